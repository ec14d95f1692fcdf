"""Passes over a scene's faces a block at a time.

Loading a model or cutting its objects into clusters visits every face several times; done
on whole arrays, each pass makes (T, 3, 3) float64 corners and friends, 72 bytes a face or
more, and a 10^7-face model costs several copies of itself. Done a block at a time, what a
pass holds is a block's temporaries, and the model costs its own arrays and the scene built
from them. Pure numpy.
"""

from __future__ import annotations

import numpy as np

#: faces per block
FACE_BLOCK = 1 << 18  # a (b, 3, 3) float64 temporary: 18 MiB


def blocks(n: int):
    """``(start, end)`` of the blocks of ``n`` faces."""
    for s in range(0, n, FACE_BLOCK):
        yield s, min(s + FACE_BLOCK, n)


def per_object(reduce, values: np.ndarray, labels: np.ndarray, out: np.ndarray) -> None:
    """``out[label] = reduce(out[label], reduce of the block's values of that label)``, for a
    block whose ``labels`` are sorted (each object's faces one run): a per-object min, max or
    sum accumulated over blocks."""
    cut = np.flatnonzero(np.r_[True, labels[1:] != labels[:-1]])
    at = labels[cut]
    out[at] = reduce(out[at], reduce.reduceat(values, cut))
