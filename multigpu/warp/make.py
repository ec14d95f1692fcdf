"""``multigpu warp make``: the outputs of a described rig (``rig.py``), as an MPCDI file.

Each projector becomes a region of the buffer (the wall's canvas): the box of the content it
shows, its warp (a grid of samples, ``GRID`` output pixels apart, in the region's normalized
coordinates; beyond the screen's edges they run on outside 0..1 and the content there is black,
NaN where they lie far off it),
and its alpha and beta maps at its own size. A wall can be aligned by hand from such a file, and
the tests read it back (``mpcdi.read``) to simulate the projection the wall would give.
"""

from __future__ import annotations

import numpy as np

from multigpu.warp.mpcdi import REACH, Output
from multigpu.warp.rig import Rig

#: output pixels between a warp grid's samples
GRID = 8


def grid_shape(size: tuple[int, int], step: int = GRID) -> tuple[int, int]:
    """(rows, cols) of a warp grid a sample every ``step`` pixels over an output of ``size``."""
    return max(2, -(-size[1] // step) + 1), max(2, -(-size[0] // step) + 1)


def outputs(rig: Rig, buffer: tuple[int, int], step: int = GRID) -> list[Output]:
    """Every projector of ``rig`` as an MPCDI output on a ``buffer`` (w, h) that is the whole
    content: its region, its warp, alpha and beta. The regions are the tiles of a wall
    (``layout.py``): equal, a whole number of buffer pixels apart, each holding all the content
    its projector shows (a little more where it stands askew), so the ranks that drive them
    compose exactly the pixels their projector needs."""
    exact = [rig.warp(i) for i in range(len(rig.projectors))]
    boxes = []
    for p, st in zip(rig.projectors, exact):
        on = ((st >= 0) & (st <= 1)).all(axis=-1)
        if not on.any():
            raise ValueError(f"projector {p.name} does not reach the screen")
        boxes.append((st[on].min(axis=0), st[on].max(axis=0)))
    areas = regions(boxes, buffer)
    out = []
    for i, p in enumerate(rig.projectors):
        x, y, w, h = areas[i]
        grid = rig.warp(i, grid_shape(p.size, step))
        warp = (grid - (x, y)) / (w, h)  # in the region's own coordinates
        far = ((warp < -REACH) | (warp > 1 + REACH)).any(axis=-1)  # far off the screen: shows nothing
        warp[far] = np.nan
        alpha, beta = rig.blend_maps(i)
        out.append(Output(p.name, p.size, areas[i], warp, alpha, beta))
    return out


def regions(boxes: list, buffer: tuple[int, int]) -> list[tuple[float, float, float, float]]:
    """(x, y, w, h) normalized: the regions of a row of projectors whose content ``boxes`` (lo, hi
    normalized (x, y) pairs, left to right) cover the buffer's width: equal tiles of whole pixels,
    the first at the left edge and the last at the right, ``step`` pixels apart, the largest step
    at which every tile holds its box; each the buffer's height (the images overfill it)."""
    W, H = buffer
    n = len(boxes)
    lo = np.array([b[0][0] for b in boxes]) * W
    hi = np.array([b[1][0] for b in boxes]) * W
    if n == 1:
        return [(0.0, 0.0, 1.0, 1.0)]
    i = np.arange(n)
    # tile i is [i*step, i*step + tw) with (n-1)*step + tw = W: it holds lo_i (i*step <= lo_i) and hi_i
    bound = [lo[k] / k for k in range(1, n)] + [(W - hi[k]) / (n - 1 - k) for k in range(n - 1)]
    step = int(np.floor(min(bound) + 1e-9))
    tw = W - (n - 1) * step
    if step < 1 or tw > W:
        raise ValueError("the projectors' images do not lie side by side across the screen")
    return [(float(k * step / W), 0.0, float(tw / W), 1.0) for k in i]


def buffer_size(rig: Rig) -> tuple[int, int]:
    """(w, h) of a buffer (the wall's canvas) that holds the screen's content at about the
    projectors' own pixel density."""
    exact = rig.warp(0)
    on = ((exact >= 0) & (exact <= 1)).all(axis=-1)
    st = exact[on]
    share = st.max(axis=0) - st.min(axis=0)  # of the screen's content one projector shows
    cols, rows = int(on.any(axis=0).sum()), int(on.any(axis=1).sum())  # its pixels on the screen
    return int(round(cols / share[0])), int(round(rows / share[1]))
