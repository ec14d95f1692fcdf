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


def outputs(rig: Rig, step: int = GRID) -> list[Output]:
    """Every projector of ``rig`` as an MPCDI output: its region (the content it shows, on a
    buffer that is the whole content), warp, alpha and beta."""
    out = []
    for i, p in enumerate(rig.projectors):
        exact = rig.warp(i)
        on = ((exact >= 0) & (exact <= 1)).all(axis=-1)
        if not on.any():
            raise ValueError(f"projector {p.name} does not reach the screen")
        lo, hi = exact[on].min(axis=0), exact[on].max(axis=0)
        area = (float(lo[0]), float(lo[1]), float(hi[0] - lo[0]), float(hi[1] - lo[1]))
        grid = rig.warp(i, grid_shape(p.size, step))
        warp = (grid - lo) / (hi - lo)  # in the region's own coordinates
        far = ((warp < -REACH) | (warp > 1 + REACH)).any(axis=-1)  # far off the screen: shows nothing
        warp[far] = np.nan
        alpha, beta = rig.blend_maps(i)
        out.append(Output(p.name, p.size, area, warp, alpha, beta))
    return out


def content_coords(o: Output, warp: np.ndarray) -> np.ndarray:
    """A region's warp coordinates (..., 2) as coordinates across the whole buffer."""
    x, y, w, h = o.area
    return np.stack([x + warp[..., 0] * w, y + warp[..., 1] * h], axis=-1)


def buffer_size(rig: Rig) -> tuple[int, int]:
    """(w, h) of a buffer (the wall's canvas) that holds the screen's content at about the
    projectors' own pixel density."""
    exact = rig.warp(0)
    on = ((exact >= 0) & (exact <= 1)).all(axis=-1)
    st = exact[on]
    share = st.max(axis=0) - st.min(axis=0)  # of the screen's content one projector shows
    cols, rows = int(on.any(axis=0).sum()), int(on.any(axis=1).sum())  # its pixels on the screen
    return int(round(cols / share[0])), int(round(rows / share[1]))
