"""Posing a moving scene compiled (``motion.Posed.at``, ``motion.rotations``): one pass over the
moving objects where the reference makes some forty numpy passes over (n, 3, 3) arrays. The same
arithmetic in the same order (sums left to right), so the same numbers (tests/test_motion.py)."""

from __future__ import annotations

import math

from multigpu.core.jit import compile_all


def _rotations(axis, angle, out):
    """``out[i]``: the rotation by ``angle[i]`` about unit ``axis[i]`` (Rodrigues)."""
    for i in range(axis.shape[0]):
        c, s = math.cos(angle[i]), math.sin(angle[i])
        x, y, z = axis[i, 0], axis[i, 1], axis[i, 2]
        C = 1.0 - c
        out[i, 0, 0], out[i, 0, 1], out[i, 0, 2] = c + x * x * C, x * y * C - z * s, x * z * C + y * s
        out[i, 1, 0], out[i, 1, 1], out[i, 1, 2] = y * x * C + z * s, c + y * y * C, y * z * C - x * s
        out[i, 2, 0], out[i, 2, 1], out[i, 2, 2] = z * x * C - y * s, z * y * C + x * s, c + z * z * C


def _stretch(A, k, orthogonal):
    """Body ``k``'s map's largest stretch, bounded as ``motion.stretch`` bounds it."""
    c0 = A[k, 0, 0] * A[k, 0, 0] + A[k, 1, 0] * A[k, 1, 0] + A[k, 2, 0] * A[k, 2, 0]
    c1 = A[k, 0, 1] * A[k, 0, 1] + A[k, 1, 1] * A[k, 1, 1] + A[k, 2, 1] * A[k, 2, 1]
    c2 = A[k, 0, 2] * A[k, 0, 2] + A[k, 1, 2] * A[k, 1, 2] + A[k, 2, 2] * A[k, 2, 2]
    d01 = abs(A[k, 0, 0] * A[k, 0, 1] + A[k, 1, 0] * A[k, 1, 1] + A[k, 2, 0] * A[k, 2, 1])
    d02 = abs(A[k, 0, 0] * A[k, 0, 2] + A[k, 1, 0] * A[k, 1, 2] + A[k, 2, 0] * A[k, 2, 2])
    d12 = abs(A[k, 0, 1] * A[k, 0, 2] + A[k, 1, 1] * A[k, 1, 2] + A[k, 2, 1] * A[k, 2, 2])
    off = max(max(d01, d02), d12)
    top = max(max(c0, c1), c2)
    return math.sqrt(top if off <= orthogonal * top else c0 + c1 + c2)


def _boxes(A, b, rows, body, c0, h0, origin, center, half):
    """Box ``rows[j]`` (rest ``c0[j]`` +- ``h0[j]``, local) moved by its body's map, into the
    (3, N) world ``center`` and ``half``."""
    for j in range(rows.shape[0]):
        k, o = body[j], rows[j]
        for i in range(3):
            c = A[k, i, 0] * c0[j, 0] + A[k, i, 1] * c0[j, 1] + A[k, i, 2] * c0[j, 2] + b[k, i]
            center[i, o] = c + origin[i]
            half[i, o] = abs(A[k, i, 0]) * h0[j, 0] + abs(A[k, i, 1]) * h0[j, 1] + abs(A[k, i, 2]) * h0[j, 2]


def _pose(A, b, body, objects, c0, h0, s0, r0, origin, orthogonal, spheres, center, half, centers, radii, rows,
          row0):
    """The moving objects' boxes, spheres (``spheres``) and shader rows (``motion.Posed.place``;
    object ``o``'s at ``rows[o - row0]``)."""
    _boxes(A, b, objects, body, c0, h0, origin, center, half)
    for j in range(objects.shape[0]):
        k, o = body[j], objects[j]
        for i in range(3):
            if spheres:
                centers[o, i] = (A[k, i, 0] * s0[j, 0] + A[k, i, 1] * s0[j, 1] + A[k, i, 2] * s0[j, 2] + b[k, i]
                                 + origin[i])
            rows[o - row0, 4 * i] = A[k, i, 0]
            rows[o - row0, 4 * i + 1] = A[k, i, 1]
            rows[o - row0, 4 * i + 2] = A[k, i, 2]
            rows[o - row0, 4 * i + 3] = b[k, i]
        if spheres:
            radii[o] = r0[j] * _stretch(A, k, orthogonal)


def _pose_span(A, b, lo, bmin, bmax, centers0, radii0, origin, orthogonal, spheres, center, half, centers, radii,
               rows):
    """Objects lo:lo + len(A), each its own body (``motion.Posed.place_span``): ``_pose`` with the
    rest bounds made here from the scene's (``motion.Posed._rest``'s arithmetic), rows from 0."""
    for j in range(A.shape[0]):
        o = lo + j
        cx, cy, cz = ((bmin[o, 0] + bmax[o, 0]) * 0.5 - origin[0], (bmin[o, 1] + bmax[o, 1]) * 0.5 - origin[1],
                      (bmin[o, 2] + bmax[o, 2]) * 0.5 - origin[2])
        hx, hy, hz = (bmax[o, 0] - bmin[o, 0]) * 0.5, (bmax[o, 1] - bmin[o, 1]) * 0.5, (bmax[o, 2] - bmin[o, 2]) * 0.5
        for i in range(3):
            c = A[j, i, 0] * cx + A[j, i, 1] * cy + A[j, i, 2] * cz + b[j, i]
            center[i, o] = c + origin[i]
            half[i, o] = abs(A[j, i, 0]) * hx + abs(A[j, i, 1]) * hy + abs(A[j, i, 2]) * hz
            if spheres:
                sx, sy, sz = centers0[o, 0] - origin[0], centers0[o, 1] - origin[1], centers0[o, 2] - origin[2]
                centers[o, i] = A[j, i, 0] * sx + A[j, i, 1] * sy + A[j, i, 2] * sz + b[j, i] + origin[i]
            rows[j, 4 * i] = A[j, i, 0]
            rows[j, 4 * i + 1] = A[j, i, 1]
            rows[j, 4 * i + 2] = A[j, i, 2]
            rows[j, 4 * i + 3] = b[j, i]
        if spheres:
            radii[o] = radii0[o] * _stretch(A, j, orthogonal)


compile_all(globals(), ("_rotations", "_stretch", "_boxes", "_pose", "_pose_span"))
