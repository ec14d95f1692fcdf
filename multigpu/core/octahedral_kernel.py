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


def _encode(n, out):
    """``out[v]``: the code of normal ``n[v]`` ((V, 3) float64)."""
    for v in range(n.shape[0]):
        a, b, c = n[v, 0], n[v, 1], n[v, 2]
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
        u, w = _code(x), _code(y)
        out[v] = np.uint32((u | (w << np.uint64(16))) & np.uint64(0xFFFFFFFF))


compile_all(globals(), ("_code", "_encode"))
