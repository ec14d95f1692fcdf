"""A simulation's colour bar: its colour map as a strip, the field's name and the values at the
map's ends (``scene/simulation.py``'s ``meta['simulation']['color_by']``).

Pure image work (numpy, Pillow's text): the run's annotated mosaics carry it in a corner, beside
the partition, so the exact mosaics stay what the wall showed. Images top row first.
"""

from __future__ import annotations

import numpy as np

#: the bar's size in pixels (strip height, strip width, margin)
STRIP, WIDTH, MARGIN = 10, 160, 6


def legend_of(meta: dict) -> dict | None:
    """A scene's colouring (``meta['simulation']['color_by']``), or None where nothing colours it."""
    return (meta.get("simulation") or {}).get("color_by")


def color_bar(legend: dict, table: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8: ``table`` (n, 4) as a strip, the field's name above it and its range's
    ends below, on a dark ground."""
    from PIL import Image, ImageDraw, ImageFont

    font = ImageFont.load_default()
    lo, hi = legend["range"]
    name, ends = f"{legend['field']} ({legend['colormap']})", (f"{lo:.4g}", f"{hi:.4g}")
    line = 12
    w = max(WIDTH, int(font.getlength(name))) + 2 * MARGIN
    h = 2 * line + STRIP + 3 * MARGIN
    img = Image.new("RGB", (w, h), (24, 24, 24))
    draw = ImageDraw.Draw(img)
    draw.text((MARGIN, MARGIN - 2), name, fill=(240, 240, 240), font=font)
    top = MARGIN + line
    picks = np.linspace(0, len(table) - 1, w - 2 * MARGIN).round().astype(np.int64)
    strip = np.repeat(table[picks, :3][None], STRIP, axis=0)
    img.paste(Image.fromarray(np.ascontiguousarray(strip)), (MARGIN, top))
    below = top + STRIP + 2
    draw.text((MARGIN, below), ends[0], fill=(240, 240, 240), font=font)
    draw.text((w - MARGIN - int(font.getlength(ends[1])), below), ends[1], fill=(240, 240, 240), font=font)
    return np.asarray(img)


def stamp(img: np.ndarray, patch: np.ndarray) -> np.ndarray:
    """``img`` with ``patch`` in its bottom-left corner (clipped to it), a new array."""
    out = img.copy()
    h, w = min(patch.shape[0], out.shape[0]), min(patch.shape[1], out.shape[1])
    out[out.shape[0] - h:, :w] = patch[patch.shape[0] - h:, :w]
    return out
