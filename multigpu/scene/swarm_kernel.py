"""The swarm's flight compiled (``swarm.Swarm.at_span``): a span of objects' maps in one pass,
where the reference makes some thirty numpy passes and their temporaries. The same arithmetic
in the same order."""

from __future__ import annotations

import math

import numpy as np

from multigpu.core.jit import compile_all


def _smooth(x):
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def _fly(t, gx, gy, gz, lo, bmin, bmax, origin, params, gather_s, scatter_s, cycle_s, A, b):
    """Body ``o = lo + i``: its place between home (the centre of its rest box ``bmin``/``bmax``,
    less ``origin``) and its place in the flock about (gx, gy, gz), and its spin
    (``swarm.Swarm.at_span``; ``params[o]``: place, lag, axis, spin), as ``A[i]``, ``b[i]``."""
    g = (gx, gy, gz)
    for i in range(A.shape[0]):
        o = lo + i
        u = t - np.float64(params[o, 3])
        s = 0.0
        if u > 0:
            cycle = u % cycle_s
            s = _smooth(cycle / gather_s) * (1 - _smooth((cycle - scatter_s) / gather_s))
        ax, ay, az = np.float64(params[o, 4]), np.float64(params[o, 5]), np.float64(params[o, 6])
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        x, y, z = ax / norm, ay / norm, az / norm
        angle = np.float64(params[o, 7]) * t
        c, sn = math.cos(angle), math.sin(angle)
        C = 1.0 - c
        A[i, 0, 0], A[i, 0, 1], A[i, 0, 2] = c + x * x * C, x * y * C - z * sn, x * z * C + y * sn
        A[i, 1, 0], A[i, 1, 1], A[i, 1, 2] = y * x * C + z * sn, c + y * y * C, y * z * C - x * sn
        A[i, 2, 0], A[i, 2, 1], A[i, 2, 2] = z * x * C - y * sn, z * y * C + x * sn, c + z * z * C
        hx, hy, hz = ((bmin[o, 0] + bmax[o, 0]) / 2 - origin[0], (bmin[o, 1] + bmax[o, 1]) / 2 - origin[1],
                      (bmin[o, 2] + bmax[o, 2]) / 2 - origin[2])
        home = (hx, hy, hz)
        for k in range(3):
            where = home[k] + s * ((g[k] + np.float64(params[o, k])) - home[k])
            b[i, k] = where - (A[i, k, 0] * hx + A[i, k, 1] * hy + A[i, k, 2] * hz)


compile_all(globals(), ("_smooth", "_fly"))
