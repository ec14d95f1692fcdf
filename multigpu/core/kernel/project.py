"""Box projection compiled: ``bounds.BoxProjector`` (frustum culling by the six planes, the 8
corners of boxes in front of the near plane in the corner dtype, near-plane clipping of the
boxes that cross it, the silhouette coverage the cost model reads) as one loop over the boxes.

Every value is formed with the same operations in the same order as the numpy reference in
``bounds.py`` (left-to-right sums, no fused multiply-add), so the rects are equal bit for bit;
the tests check it on random and extreme inputs.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.kernel.jit import compile_all


def _corner(b, hx, hy, hz, m, k):
    """One clip row at corner ``k`` (bit 2: x, bit 1: y, bit 0: z), in the corner dtype:
    ((b +- hx*m0) +- hy*m1) +- hz*m2, as ``bounds._corners`` adds them."""
    ax, ay, az = hx * m[0], hy * m[1], hz * m[2]
    t = b + ax if k & 4 else b - ax
    t = t + ay if k & 2 else t - ay
    return t + az if k & 1 else t - az


def _corner_xy(base, hx, hy, hz, Mc, cx, cy):
    """NDC x and y of a box's 8 corners into ``cx``/``cy`` (corner dtype)."""
    for k in range(8):
        w = _corner(base[2], hx, hy, hz, Mc[2], k)
        cx[k] = _corner(base[0], hx, hy, hz, Mc[0], k) / w
        cy[k] = _corner(base[1], hx, hy, hz, Mc[1], k) / w


def _face(cx, cy, faces, nxt, f):
    """Twice the signed area of face ``f`` (shoelace, its 4 terms added in order)."""
    s = cx[faces[f, 0]] * cy[nxt[f, 0]] - cx[nxt[f, 0]] * cy[faces[f, 0]]
    for j in range(1, 4):
        s += cx[faces[f, j]] * cy[nxt[f, j]] - cx[nxt[f, j]] * cy[faces[f, j]]
    return s


def _coverage(cx, cy, faces, nxt, x0, y0, x1, y1):
    """``bounds._silhouette_fraction`` of one box: half its faces' summed |shoelace area|
    (summed in the corner dtype) over its rect's area."""
    area = abs(_face(cx, cy, faces, nxt, 0))
    for f in range(1, 6):
        area += abs(_face(cx, cy, faces, nxt, f))
    quarter = np.float64(area * np.float32(0.25))  # as the reference's in-place *= 0.25
    rect = (x1 - x0) * (y1 - y0)
    if not rect > 0:
        return 1.0
    return min(max(quarter / rect, 0.0), 1.0)


def _write(out, i, x0, y0, x1, y1, c_lo, c_hi):
    """``bounds._write_rects`` for one box: NDC extents to a clipped normalized rect, or NaN."""
    x0, y0, x1, y1 = x0 * 0.5 + c_lo, y0 * 0.5 + c_lo, x1 * 0.5 + c_hi, y1 * 0.5 + c_hi
    if x1 < 0.0 or x0 > 1.0 or y1 < 0.0 or y0 > 1.0:
        out[0, i] = out[1, i] = out[2, i] = out[3, i] = np.nan
        return
    out[0, i] = min(max(x0, 0.0), 1.0)
    out[1, i] = min(max(y0, 0.0), 1.0)
    out[2, i] = min(max(x1, 0.0), 1.0)
    out[3, i] = min(max(y1, 0.0), 1.0)


def _clipped(M, cc, h, signs, edges, out, i):
    """``bounds._clipped_rects`` for one box crossing the near plane: the extents of its corners
    in front of the plane and of its edges' crossings with it, projected."""
    P = np.empty((4, 8))
    for k in range(8):
        sx, sy, sz = h[0] * signs[k, 0], h[1] * signs[k, 1], h[2] * signs[k, 2]
        for r in range(4):
            P[r, k] = sx * M[r, 0] + sy * M[r, 1] + sz * M[r, 2] + cc[r]
    lo_x = lo_y = np.inf
    hi_x = hi_y = -np.inf
    kept = False
    for j in range(20):  # 8 corners, then 12 edges
        if j < 8:
            x, y, w, keep = P[0, j], P[1, j], P[3, j], P[2, j] + P[3, j] >= 0
        else:
            a, b = edges[j - 8, 0], edges[j - 8, 1]
            d0, d1 = P[2, a] + P[3, a], P[2, b] + P[3, b]
            keep = (d0 >= 0) != (d1 >= 0)
            t = d0 / (d0 - d1) if keep else 0.0
            x = P[0, a] + t * (P[0, b] - P[0, a])
            y = P[1, a] + t * (P[1, b] - P[1, a])
            w = P[3, a] + t * (P[3, b] - P[3, a])
        if keep and w > 0:
            kept = True
            x, y = min(max(x / w, -4.0), 4.0), min(max(y / w, -4.0), 4.0)
            lo_x, lo_y, hi_x, hi_y = min(lo_x, x), min(lo_y, y), max(hi_x, x), max(hi_y, y)
    if not kept:  # nothing in front: off screen
        lo_x, lo_y, hi_x, hi_y = 2.0, 2.0, 3.0, 3.0
    _write(out, i, lo_x, lo_y, hi_x, hi_y, 0.5, 0.5)


def _project(center, half, half64, M, Mc, reach_rows, widen, far_tol, signs, edges, faces, nxt, out, cov, with_cov):
    """Rects (4, N) into ``out`` (NaN: culled or off screen) and, ``with_cov``, silhouette
    coverage into ``cov``. ``Mc``: clip rows x, y, w of M[:, :3] in the corner dtype;
    ``reach_rows``: |plane @ M[:, :3]| of the six frustum planes."""
    n = center.shape[1]
    c_lo, c_hi = 0.5 + widen * -0.5, 0.5 + widen * 0.5
    cc = np.empty(4)
    base = np.empty(3, dtype=half.dtype)  # the centre's clip x, y, w cast to the corner dtype
    cx = np.empty(8, dtype=half.dtype)
    cy = np.empty(8, dtype=half.dtype)
    aw0, aw1, aw2 = abs(M[3, 0]), abs(M[3, 1]), abs(M[3, 2])
    for i in range(n):
        c0, c1, c2 = center[0, i], center[1, i], center[2, i]
        h0, h1, h2 = half64[0, i], half64[1, i], half64[2, i]
        for r in range(4):
            cc[r] = M[r, 0] * c0 + M[r, 1] * c1 + M[r, 2] * c2 + M[r, 3]
        w_r = aw0 * h0 + aw1 * h1 + aw2 * h2
        outside = front = False
        for p in range(6):  # left, right, bottom, top, near, far: inside means >= 0
            axis, sign = p // 2, 1.0 if p % 2 == 0 else -1.0
            d = cc[axis] + cc[3] if sign > 0 else -cc[axis] + cc[3]
            reach = reach_rows[p, 0] * h0 + reach_rows[p, 1] * h1 + reach_rows[p, 2] * h2
            if p == 4:
                front = d >= reach
            d += reach
            if p == 5:
                outside |= d < -far_tol * (abs(cc[3]) + w_r)
            else:
                outside |= d < 0
        if with_cov:
            cov[i] = 1.0
        if outside:
            out[0, i] = out[1, i] = out[2, i] = out[3, i] = np.nan
            continue
        if not front:
            _clipped(M, cc, half64[:, i], signs, edges, out, i)
            continue
        base[0], base[1], base[2] = cc[0], cc[1], cc[3]
        _corner_xy(base, half[0, i], half[1, i], half[2, i], Mc, cx, cy)
        x0, y0, x1, y1 = cx[0], cy[0], cx[0], cy[0]
        for k in range(1, 8):
            x0, y0, x1, y1 = min(x0, cx[k]), min(y0, cy[k]), max(x1, cx[k]), max(y1, cy[k])
        e0, e1, e2, e3 = np.float64(x0), np.float64(y0), np.float64(x1), np.float64(y1)
        if with_cov:
            cov[i] = _coverage(cx, cy, faces, nxt, e0, e1, e2, e3)
        _write(out, i, e0, e1, e2, e3, c_lo, c_hi)


compile_all(globals(), ("_corner", "_corner_xy", "_face", "_coverage", "_write", "_clipped", "_project"))
