"""The cost model's per-rank pixel feature (``strategies.base.rank_pixels``) in one compiled call:
each rank's visible objects' pixel spans clipped to its region, their areas weighted by one or
more per-object coverages and summed in object order, as the reference sums them."""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all


def rank_pixels(spans, visible, regions, cov, out):
    """``out`` (K, M) = per rank k and weighting m, the sum over its visible objects (in object
    order) of ``cov[m, o]`` times the area of object o's inclusive span ``spans[:, o]`` clipped
    to ``regions[k]`` (half-open)."""
    K, n, M = visible.shape[0], visible.shape[1], cov.shape[0]
    for k in range(K):
        x0, y0, x1, y1 = regions[k, 0], regions[k, 1], regions[k, 2], regions[k, 3]
        for m in range(M):
            out[k, m] = 0.0
        for o in range(n):
            if not visible[k, o]:
                continue
            w = min(np.int64(spans[2, o]), x1 - 1) - max(np.int64(spans[0, o]), x0) + 1
            h = min(np.int64(spans[3, o]), y1 - 1) - max(np.int64(spans[1, o]), y0) + 1
            area = np.float64(max(w, 0)) * max(h, 0)
            for m in range(M):
                out[k, m] += cov[m, o] * area


compile_all(globals(), ("rank_pixels",))
