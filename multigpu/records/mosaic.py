"""The full wall as one image: tiles stitched at their grid positions (the partition drawn over
it comes from ``display.hud.overlay``)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from multigpu.errors import WriteFailed


def stitch(tiles: np.ndarray, tile_rects: np.ndarray, size, dark=()) -> np.ndarray:
    """(K, th, tw, 3) bottom-up tiles -> (H, W, 3) image, top row first (for PNG); ``dark``
    tiles (their PC gone) stay black."""
    W, H = size
    img = np.zeros((H, W, 3), dtype=np.uint8)
    for k, (x0, y0, x1, y1) in enumerate(tile_rects):  # K tiles
        if k not in dark:
            img[y0:y1, x0:x1] = tiles[k]
    return img[::-1]


def save_png(img: np.ndarray, path: Path) -> None:
    """Write a PNG atomically (temp file, then rename)."""
    from PIL import Image

    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.png")
    try:
        Image.fromarray(img).save(tmp, format="PNG")
        tmp.replace(path)
    except OSError as exc:
        raise WriteFailed.of(path, exc) from None
    finally:
        tmp.unlink(missing_ok=True)
