"""A frame's transfers compiled (``core.work.transfers``) for many pieces (bins, big walls):
every (piece, tile) overlap in (sender, receiver, piece index) order in one pass. A screen
partition's few pairs take ``transfers``' plain loop, the reference these parts equal
(tests/test_kernel.py); the numpy version both replace made some thirty calls on a handful of
rects, ~0.15 ms of CPU per frame with the caches cold after rendering."""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all


def _parts(R, counts, T):
    """(M, 7) int64 rows ``[sender, receiver, index, x0, y0, x1, y1]``: rank-major pieces
    ``R`` (P, 4) (``counts[k]`` of them rank k's) against tiles ``T`` (K, 4)."""
    out = np.empty((R.shape[0] * T.shape[0], 7), dtype=np.int64)
    m = 0
    first = 0
    for s in range(counts.shape[0]):  # ranks, then tiles, then the sender's pieces: the sorted order
        for t in range(T.shape[0]):
            for i in range(counts[s]):
                p = first + i
                x0, y0 = max(R[p, 0], T[t, 0]), max(R[p, 1], T[t, 1])
                x1, y1 = min(R[p, 2], T[t, 2]), min(R[p, 3], T[t, 3])
                if x1 > x0 and y1 > y0:
                    out[m, 0], out[m, 1], out[m, 2] = s, t, i
                    out[m, 3], out[m, 4], out[m, 5], out[m, 6] = x0, y0, x1, y1
                    m += 1
        first += counts[s]
    return out[:m].copy()


compile_all(globals(), ("_parts",))
