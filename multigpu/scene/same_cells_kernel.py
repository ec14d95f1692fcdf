"""A step in its first step's layout, compiled (``same_cells.changes``): its vertices placed, their
smooth normals and every object's and part's box and sphere in four passes over the points and
triangles, where the reference makes some forty numpy passes and their (T, 3, 3) temporaries (a
96x96 plate: ~8 ms of a live stream's keeper, taken from rank 0's frame loop while it holds
Python's lock; compiled ``nogil``, it runs beside it). The same arithmetic in the same order:
each normal summed over its triangles in their order (``np.bincount``'s), each sum of three
squares left to right, a NaN (a float32 overflow) kept by a minimum or maximum as numpy keeps it.
"""

from __future__ import annotations

import math

import numpy as np

from multigpu.core.jit import compile_all


def _lo(a, b):
    """``np.minimum``'s: a NaN either side wins."""
    return a if (a <= b or a != a) else b


def _hi(a, b):
    """``np.maximum``'s."""
    return a if (a >= b or a != a) else b


def _place(points, point, tri, obj, part, origin, vertices, bmin, bmax, far, pbmin, pbmax, acc):
    """Vertex ``v`` at ``points[point[v]]`` relative to ``origin`` (the centre of their bounds, set
    here) into ``vertices`` (float32 position, normal); each object's (``obj``) and part's
    (``part``, empty: none) box of its triangles ``tri`` as drawn, each object's farthest corner's
    squared distance from its box's centre (``far``); ``acc`` (V, 3) float64 zeros: the normals'
    sums."""
    V = point.shape[0]
    for k in range(3):
        lo, hi = np.inf, -np.inf
        for v in range(V):
            x = points[point[v], k]
            lo = _lo(lo, x)
            hi = _hi(hi, x)
        origin[k] = (lo + hi) / 2
    for v in range(V):
        for k in range(3):
            vertices[v, k] = np.float32(points[point[v], k] - origin[k])
    c = np.empty((3, 3))
    for t in range(tri.shape[0]):
        for j in range(3):
            for k in range(3):
                c[j, k] = np.float64(vertices[tri[t, j], k]) + origin[k]
        e1x, e1y, e1z = c[1, 0] - c[0, 0], c[1, 1] - c[0, 1], c[1, 2] - c[0, 2]
        e2x, e2y, e2z = c[2, 0] - c[0, 0], c[2, 1] - c[0, 1], c[2, 2] - c[0, 2]
        nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        for j in range(3):
            v = tri[t, j]
            acc[v, 0] += nx
            acc[v, 1] += ny
            acc[v, 2] += nz
        o = obj[t]
        for k in range(3):
            lo = _lo(_lo(c[0, k], c[1, k]), c[2, k])
            hi = _hi(_hi(c[0, k], c[1, k]), c[2, k])
            bmin[o, k] = _lo(bmin[o, k], lo)
            bmax[o, k] = _hi(bmax[o, k], hi)
            if part.shape[0]:
                p = part[t]
                pbmin[p, k] = _lo(pbmin[p, k], lo)
                pbmax[p, k] = _hi(pbmax[p, k], hi)
    for t in range(tri.shape[0]):
        o = obj[t]
        cx, cy, cz = (bmin[o, 0] + bmax[o, 0]) / 2, (bmin[o, 1] + bmax[o, 1]) / 2, (bmin[o, 2] + bmax[o, 2]) / 2
        for j in range(3):
            v = tri[t, j]
            dx = (np.float64(vertices[v, 0]) + origin[0]) - cx
            dy = (np.float64(vertices[v, 1]) + origin[1]) - cy
            dz = (np.float64(vertices[v, 2]) + origin[2]) - cz
            far[o] = _hi(far[o], (dx * dx + dy * dy) + dz * dz)
    for v in range(V):
        length = math.sqrt((acc[v, 0] * acc[v, 0] + acc[v, 1] * acc[v, 1]) + acc[v, 2] * acc[v, 2])
        for k in range(3):
            if length > 0:
                vertices[v, 3 + k] = np.float32(acc[v, k] / length)
            else:
                vertices[v, 3 + k] = np.float32(1.0 if k == 2 else 0.0)


compile_all(globals(), ("_lo", "_hi", "_place"))
