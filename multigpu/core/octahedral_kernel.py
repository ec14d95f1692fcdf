"""Octahedral normal codes, compiled (``octahedral.encode``): the reference's arithmetic a
vertex at a time, in its order: the sum of the three magnitudes left to right, the division (by 1
where that sum is not positive), a zero sum's +z, the fold of the lower half, the rounding half
to even; a normal with a coordinate that is not finite coded as a zero one (+z).
"""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all


def _code(x):
    """``np.rint((x * 0.5 + 0.5) * 65535)`` as uint32 (x in [-1, 1])."""
    return np.uint64(np.rint((x * 0.5 + 0.5) * 65535.0))


def _normal(a, b, c):
    """The code of normal (a, b, c) (float64)."""
    if not (np.isfinite(a) and np.isfinite(b) and np.isfinite(c)):
        a, b, c = 0.0, 0.0, 0.0
    s = (abs(a) + abs(b)) + abs(c)
    d = s if s > 0 else 1.0
    x, y, z = a / d, b / d, c / d
    if s == 0:
        z = 1.0
    sx = 1.0 if x >= 0 else -1.0
    sy = 1.0 if y >= 0 else -1.0
    if z < 0:
        x, y = (1 - abs(y)) * sx, (1 - abs(x)) * sy
    return np.uint32((_code(x) | (_code(y) << np.uint64(16))) & np.uint64(0xFFFFFFFF))


def _encode(n, out):
    """``out[v]``: the code of normal ``n[v]`` ((V, 3) float64)."""
    for v in range(n.shape[0]):
        out[v] = _normal(n[v, 0], n[v, 1], n[v, 2])


def _pack(vertices, bits, out):
    """``out[v]``: vertex ``v``'s position bits (``bits``: ``vertices`` (V, 6) float32 seen as
    uint32) and its normal's code, its float32 coordinates widened to float64 as the reference's."""
    for v in range(vertices.shape[0]):
        out[v, 0], out[v, 1], out[v, 2] = bits[v, 0], bits[v, 1], bits[v, 2]
        out[v, 3] = _normal(np.float64(vertices[v, 3]), np.float64(vertices[v, 4]), np.float64(vertices[v, 5]))


compile_all(globals(), ("_code", "_normal", "_encode", "_pack"))
