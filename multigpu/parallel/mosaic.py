"""The full wall as one image: tiles stitched at their grid positions, partition drawn over it."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

PALETTE = np.array([[230, 25, 75], [60, 180, 75], [255, 225, 25], [0, 130, 200], [245, 130, 48],
                    [145, 30, 180], [70, 240, 240], [240, 50, 230], [210, 245, 60], [250, 190, 212],
                    [0, 128, 128], [220, 190, 255], [170, 110, 40], [255, 250, 200], [128, 0, 0],
                    [170, 255, 195]], dtype=np.float32)


def stitch(tiles: np.ndarray, tile_rects: np.ndarray, size) -> np.ndarray:
    """(K, th, tw, 3) bottom-up tiles -> (H, W, 3) image, top row first (for PNG)."""
    W, H = size
    img = np.zeros((H, W, 3), dtype=np.uint8)
    for k, (x0, y0, x1, y1) in enumerate(tile_rects):  # K tiles
        img[y0:y1, x0:x1] = tiles[k]
    return img[::-1]


def overlay(img: np.ndarray, rects, alpha: float = 0.18) -> np.ndarray:
    """Tint each rank's pieces with its colour and draw their borders; ``rects[k]`` is rank
    k's (M_k, 4) pieces (or one (4,) region)."""
    H = img.shape[0]
    out = img.astype(np.float32)
    boxes = [(k, r) for k, rs in enumerate(rects) for r in np.asarray(rs, dtype=np.int64).reshape(-1, 4)]
    for k, (x0, y0, x1, y1) in boxes:  # pieces, not objects
        top, bot = H - y1, H - y0
        c = PALETTE[k % len(PALETTE)]
        out[top:bot, x0:x1] = out[top:bot, x0:x1] * (1 - alpha) + c * alpha
        for sl in (np.s_[top:bot, x0:min(x0 + 2, x1)], np.s_[top:bot, max(x1 - 2, x0):x1],
                   np.s_[top:min(top + 2, bot), x0:x1], np.s_[max(bot - 2, top):bot, x0:x1]):
            out[sl] = c
    return out.astype(np.uint8)


def save_png(img: np.ndarray, path: Path) -> None:
    """Write a PNG atomically (temp file, then rename)."""
    from PIL import Image

    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.png")
    try:
        Image.fromarray(img).save(tmp, format="PNG")
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
