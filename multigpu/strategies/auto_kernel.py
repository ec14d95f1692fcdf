"""The triangles of every object in view (``auto``'s trial load) in one compiled pass over the
objects: numpy's masked sum (``np.sum(tris, where=...)``) takes ~75 us for the city's 6,690
objects even with the caches warm; this loop a few."""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all


def _seen(x0, tris):
    """The sum of ``tris`` over the objects whose ``x0`` (a rect's first coordinate) is not NaN,
    added in object order."""
    s = tris.dtype.type(0)
    for i in range(x0.shape[0]):
        if x0[i] == x0[i]:
            s += tris[i]
    return s


compile_all(globals(), ("_seen",))


def seen_triangles(rects: np.ndarray, tris: np.ndarray) -> float:
    """The triangles of the objects in view: ``tris`` summed over the (N, 4) ``rects`` that
    are not NaN, in one compiled pass (the projector's rects give a contiguous first column)."""
    return float(_seen(np.ascontiguousarray(rects[:, 0]), np.asarray(tris)))

