"""The swarm's flight compiled (``swarm.Swarm.at``): every object's map in one pass into arrays
the swarm keeps, where the reference makes some thirty numpy passes and their temporaries (at
100k objects tens of MB a frame on every rank). The same arithmetic in the same order."""

from __future__ import annotations

import math

from multigpu.core.jit import compile_all


def _smooth(x):
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def _fly(t, gx, gy, gz, home, place, lag, axis, spin, gather_s, scatter_s, cycle_s, A, b):
    """Object ``i``: its place between home and its place in the flock about (gx, gy, gz), and
    its spin (``swarm.Swarm.at``), as the map ``A[i]``, ``b[i]``."""
    g = (gx, gy, gz)
    for i in range(home.shape[0]):
        u = t - lag[i]
        s = 0.0
        if u > 0:
            cycle = u % cycle_s
            s = _smooth(cycle / gather_s) * (1 - _smooth((cycle - scatter_s) / gather_s))
        c, sn = math.cos(spin[i] * t), math.sin(spin[i] * t)
        x, y, z = axis[i, 0], axis[i, 1], axis[i, 2]
        C = 1.0 - c
        A[i, 0, 0], A[i, 0, 1], A[i, 0, 2] = c + x * x * C, x * y * C - z * sn, x * z * C + y * sn
        A[i, 1, 0], A[i, 1, 1], A[i, 1, 2] = y * x * C + z * sn, c + y * y * C, y * z * C - x * sn
        A[i, 2, 0], A[i, 2, 1], A[i, 2, 2] = z * x * C - y * sn, z * y * C + x * sn, c + z * z * C
        for k in range(3):
            where = home[i, k] + s * ((g[k] + place[i, k]) - home[i, k])
            b[i, k] = where - (A[i, k, 0] * home[i, 0] + A[i, k, 1] * home[i, 1] + A[i, k, 2] * home[i, 2])


compile_all(globals(), ("_smooth", "_fly"))
