"""Integer pixel rectangles: display tiles and object footprints (the Alg. 3 transfer plan is
``core.work.transfers``).

Rectangles are half-open ``[x0, y0, x1, y1)`` in pixels, origin bottom-left. An object's
normalized rect maps to the inclusive pixel span ``[floor(xmin*W), floor(xmax*W)]`` clipped to the
display, so a rect touching a pixel boundary counts on both sides (conservative) and a
zero-area rect still lands in exactly one pixel. Everything here is pure numpy.
"""

from __future__ import annotations

import numpy as np

# pixel coordinates of object spans: int32 halves the memory traffic of the per-frame passes;
# displays are limited to MAX_PIXELS per axis so every coordinate fits
SPAN_DTYPE = np.int32
MAX_PIXELS = 2**30
# integer weights (triangle counts) must sum below this, so every sum fits int64
MAX_TOTAL = 2**62
# the balancer's refusals of bad weights and rects (the reference and the compiled walk say the same)
NOT_FINITE = "tris (weights) must be finite"
NEGATIVE = "tris must be non-negative (a negative triangle count was given)"
TOO_MANY = "the triangle total exceeds 2**62 (sums could overflow int64)"
INVERTED = "rects has inverted rows (xmin > xmax or ymin > ymax)"


def tile_regions(rows: int, cols: int, tw: int, th: int) -> np.ndarray:
    """(K, 4) int64 display tile of every rank label (column-major, row 0 at the top)."""
    labels = np.arange(rows * cols)
    row, col = labels % rows, labels // rows
    x0 = col * tw
    y0 = (rows - 1 - row) * th
    return np.stack([x0, y0, x0 + tw, y0 + th], axis=1).astype(np.int64)


def pixel_spans(rects: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Inclusive pixel spans of normalized rects, and which rects are on screen.

    Parameters
    ----------
    rects : (N, 4) float  ``[xmin, ymin, xmax, ymax]`` normalized; NaN rows are invisible.
    size : (W, H) display size in pixels.

    Returns
    -------
    spans : (N, 4) int32  ``[cx0, cy0, cx1, cy1]`` inclusive pixel columns/rows (0 where off).
    onscreen : (N,) bool
    """
    W, H = size
    r = np.asarray(rects, dtype=np.float64)
    rt = r.T  # work coordinate-major, (4, N), so each coordinate is one contiguous row
    with np.errstate(invalid="ignore"):
        onscreen = (rt[2] >= 0.0) & (rt[0] <= 1.0) & (rt[3] >= 0.0) & (rt[1] <= 1.0)
        # (False for NaN rows: every comparison with NaN is False)
        c = np.multiply(rt, np.array([[W], [H], [W], [H]], dtype=np.float64))
        np.maximum(c, 0.0, out=c)
        np.minimum(c, np.array([[W - 1], [H - 1], [W - 1], [H - 1]], dtype=np.float64), out=c)
        np.copyto(c, 0.0, where=~onscreen)  # off-screen (and NaN) rows
        spans_t = c.astype(SPAN_DTYPE)  # truncation is floor: every value is >= 0 here
    spans = spans_t.T  # (N, 4) view of the coordinate-major array
    return spans, onscreen


def overlaps(spans: np.ndarray, region) -> np.ndarray:
    """(N,) bool: which inclusive pixel spans touch the half-open region ``[x0, y0, x1, y1)``."""
    x0, y0, x1, y1 = (int(v) for v in region)
    return (spans[:, 0] < x1) & (spans[:, 2] >= x0) & (spans[:, 1] < y1) & (spans[:, 3] >= y0)
