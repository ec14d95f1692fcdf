"""The machinery's maps compiled (``moves.Machinery.at``): each moving body's turn and slide in
one pass, where the reference makes a dozen numpy passes (a fixed cost of some 0.2 ms a frame on
a plant of a few hundred machines). The same arithmetic in the same order."""

from __future__ import annotations

import math

from multigpu.core.jit import compile_all


def _machine(t, which, up, rate, pivot, slide, pace, phase, A, b):
    """Body ``which[j]``: a turn by ``rate[j] * t`` about ``up[j]`` through ``pivot[j]``, then
    ``slide[j]`` times its to-and-fro, into ``A``, ``b``."""
    for j in range(which.shape[0]):
        k = which[j]
        angle = rate[j] * t
        c, s = math.cos(angle), math.sin(angle)
        x, y, z = up[j, 0], up[j, 1], up[j, 2]
        C = 1.0 - c
        A[k, 0, 0], A[k, 0, 1], A[k, 0, 2] = c + x * x * C, x * y * C - z * s, x * z * C + y * s
        A[k, 1, 0], A[k, 1, 1], A[k, 1, 2] = y * x * C + z * s, c + y * y * C, y * z * C - x * s
        A[k, 2, 0], A[k, 2, 1], A[k, 2, 2] = z * x * C - y * s, z * y * C + x * s, c + z * z * C
        fro = math.sin(2 * math.pi * pace[j] * t + phase[j]) - math.sin(phase[j])
        for i in range(3):
            turned = A[k, i, 0] * pivot[j, 0] + A[k, i, 1] * pivot[j, 1] + A[k, i, 2] * pivot[j, 2]
            b[k, i] = pivot[j, i] - turned + fro * slide[j, i]


compile_all(globals(), ("_machine",))
