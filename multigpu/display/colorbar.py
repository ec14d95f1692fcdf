"""A simulation's colour bar: its colour map as a strip, the field's name and the values at the
map's ends (``scene/simulation.py``'s ``meta['simulation']['color_by']``).

Pure image work (numpy, Pillow's text): the run's annotated mosaics carry it in a corner, beside
the partition, so the exact mosaics stay what the wall showed; with ``--color-bar`` the wall shows
it too, in the canvas's bottom-left corner, each rank stamping the part on its tile
(``TileKey``). Images top row first, tiles bottom row first (as composed).
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


class TileKey:
    """The part of the colour bar ``bar`` (top row first) that falls on a tile ``rect`` (x0, y0,
    x1, y1 of the canvas, y up), the bar's bottom-left corner ``MARGIN`` pixels from the canvas's."""

    def __init__(self, bar: np.ndarray, rect):
        x0, y0, x1, y1 = (int(v) for v in rect)
        h, w = bar.shape[:2]
        up = bar[::-1]  # bottom row first, as tiles are
        cx0, cx1, cy0, cy1 = max(x0, MARGIN), min(x1, MARGIN + w), max(y0, MARGIN), min(y1, MARGIN + h)
        self.part = None
        if cx0 < cx1 and cy0 < cy1:
            self.part = (np.s_[cy0 - y0:cy1 - y0, cx0 - x0:cx1 - x0],
                         np.ascontiguousarray(up[cy0 - MARGIN:cy1 - MARGIN, cx0 - MARGIN:cx1 - MARGIN]))

    @classmethod
    def of(cls, meta: dict, rect) -> "TileKey | None":
        """The tile's part of a scene's colour bar (None: nothing colours the scene)."""
        legend = legend_of(meta)
        if legend is None:
            return None
        from multigpu.scene.simulation import lookup

        return cls(color_bar(legend, lookup(legend["colormap"])), rect)

    def stamp(self, tile: np.ndarray) -> None:
        """The bar's part over the composed ``tile`` (in place; nothing where none falls on it)."""
        if self.part is not None:
            where, pixels = self.part
            tile[where] = pixels
