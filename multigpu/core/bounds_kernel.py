"""Box projection compiled: ``bounds.BoxProjector`` (frustum culling by the six planes, the 8
corners of boxes in front of the near plane in the corner dtype, near-plane clipping of the
boxes that cross it, the silhouette coverage the cost model reads) as one loop over the boxes.
The boxes are kept in a spatial (Morton) order in groups of neighbours, and a group wholly
outside a frustum plane (with a margin no rounding can cross) is culled without touching its
members: on a walkthrough most of the scene is behind or beside the camera.

Every value is formed with the same operations in the same order as the numpy reference in
``bounds.py`` (left-to-right sums, no fused multiply-add), so the rects are equal bit for bit;
the tests check it on random and extreme inputs.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.box_tables import EDGES, FACES, NEXT, SIGNS
from multigpu.core.camera import camera_into as _camera_into  # compiled here: the frame's matrices in the same call
from multigpu.core.jit import compile_all


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


def _write(out, i, x0, y0, x1, y1, c_lo, c_hi, filled):
    """``bounds._write_rects`` for one box: NDC extents to a clipped normalized rect, or NaN
    (left as it is where the caller ``filled`` every rect with NaN already)."""
    x0, y0, x1, y1 = x0 * 0.5 + c_lo, y0 * 0.5 + c_lo, x1 * 0.5 + c_hi, y1 * 0.5 + c_hi
    if x1 < 0.0 or x0 > 1.0 or y1 < 0.0 or y0 > 1.0:
        if not filled:
            out[0, i] = out[1, i] = out[2, i] = out[3, i] = np.nan
        return
    out[0, i] = min(max(x0, 0.0), 1.0)
    out[1, i] = min(max(y0, 0.0), 1.0)
    out[2, i] = min(max(x1, 0.0), 1.0)
    out[3, i] = min(max(y1, 0.0), 1.0)


def _clipped(M, cc, h, signs, edges, out, i, filled):
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
    _write(out, i, lo_x, lo_y, hi_x, hi_y, 0.5, 0.5, filled)


#: boxes per block: the corner passes run over a block's arrays (in cache), so they vectorize
BLOCK = 512
#: boxes per culling group: neighbours in the spatial order, tested against the frustum as one box
GROUP = 16
#: up to this many boxes the rects (32 bytes a box: 512 KiB) stay in cache, so writing them
#: scattered costs little and the groups pay once they cull an eighth of the boxes (ad hoc,
#: cold: the plant walk's frames with 25-40 % culled 109 us grouped against 160 us in object
#: order, the city's with 34-50 % 284-313 against 350-358 us; the 4-plant orbit, nothing
#: culled, 369 us in object order against 455 grouped); beyond, they must cull half
SCATTER_FREE = 16384


def _spread(q: np.ndarray) -> np.ndarray:
    """The 21 low bits of ``q`` (uint64) spread to every third bit (Morton interleaving)."""
    q = q & np.uint64(0x1FFFFF)
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        q = (q | (q << np.uint64(shift))) & np.uint64(mask)
    return q


def spatial_groups(center: np.ndarray, half64: np.ndarray, size: int = GROUP):
    """Boxes (``center``, ``half64``: (3, N) float64) in Morton order of their centres, cut into
    groups of ``size`` neighbours: (order, sorted centres, sorted half extents, group starts,
    group boxes (6, G): centre and half extents of each group's members' union). Once per scene."""
    n = center.shape[1]
    finite = center[:, np.isfinite(center).all(axis=0)]
    lo, hi = (finite.min(axis=1), finite.max(axis=1)) if finite.size else (np.zeros(3), np.ones(3))
    span = np.where(hi > lo, hi - lo, 1.0)
    q = np.clip(np.nan_to_num((center - lo[:, None]) / span[:, None] * (2 ** 21 - 1)), 0, 2 ** 21 - 1)
    q = q.astype(np.uint64)
    code = _spread(q[0]) | (_spread(q[1]) << np.uint64(1)) | (_spread(q[2]) << np.uint64(2))
    order = np.argsort(code, kind="stable").astype(np.int64)
    c, h = np.ascontiguousarray(center[:, order]), np.ascontiguousarray(half64[:, order])
    starts = np.unique(np.minimum(np.arange(0, n + size, size, dtype=np.int64), n))  # ends with n
    lo_g, hi_g = np.zeros((3, 0)), np.zeros((3, 0))
    if n:
        with np.errstate(invalid="ignore"):
            lo_g = np.minimum.reduceat(c - h, starts[:-1], axis=1)
            hi_g = np.maximum.reduceat(c + h, starts[:-1], axis=1)
    gbox = np.ascontiguousarray(np.concatenate([(lo_g + hi_g) * 0.5, (hi_g - lo_g) * 0.5]))
    return order, c, h, starts, gbox


def _clip_block(center, half64, M, rr, far_tol, s0, m, base, state):
    """Clip coordinates of the block's box centres (x, y, w into ``base``, cast to the corner
    dtype) and each box's state: 0 wholly in front of the near plane and inside every plane,
    1 crossing the near plane, 2 wholly outside a frustum plane. ``bounds._boxes_block``'s
    values and tests in its order (a plane's distance is x + w or -x + w, one rounding; the
    reach of the half extents along its normal, |plane @ M| . h, added left to right). The
    matrix entries are read once into locals so the loop keeps them in registers."""
    m00, m01, m02, m03 = M[0, 0], M[0, 1], M[0, 2], M[0, 3]
    m10, m11, m12, m13 = M[1, 0], M[1, 1], M[1, 2], M[1, 3]
    m20, m21, m22, m23 = M[2, 0], M[2, 1], M[2, 2], M[2, 3]
    m30, m31, m32, m33 = M[3, 0], M[3, 1], M[3, 2], M[3, 3]
    a0, a1, a2 = abs(m30), abs(m31), abs(m32)
    l0, l1, l2 = rr[0, 0], rr[0, 1], rr[0, 2]
    g0, g1, g2 = rr[1, 0], rr[1, 1], rr[1, 2]
    b0, b1, b2 = rr[2, 0], rr[2, 1], rr[2, 2]
    t0, t1, t2 = rr[3, 0], rr[3, 1], rr[3, 2]
    n0, n1, n2 = rr[4, 0], rr[4, 1], rr[4, 2]
    f0, f1, f2 = rr[5, 0], rr[5, 1], rr[5, 2]
    for j in range(m):
        i = s0 + j
        c0, c1, c2 = center[0, i], center[1, i], center[2, i]
        h0, h1, h2 = half64[0, i], half64[1, i], half64[2, i]
        x = m00 * c0 + m01 * c1 + m02 * c2 + m03
        y = m10 * c0 + m11 * c1 + m12 * c2 + m13
        z = m20 * c0 + m21 * c1 + m22 * c2 + m23
        w = m30 * c0 + m31 * c1 + m32 * c2 + m33
        out = (x + w) + (l0 * h0 + l1 * h1 + l2 * h2) < 0
        out |= (-x + w) + (g0 * h0 + g1 * h1 + g2 * h2) < 0
        out |= (y + w) + (b0 * h0 + b1 * h1 + b2 * h2) < 0
        out |= (-y + w) + (t0 * h0 + t1 * h1 + t2 * h2) < 0
        dn, rn = z + w, n0 * h0 + n1 * h1 + n2 * h2
        out |= dn + rn < 0
        out |= (-z + w) + (f0 * h0 + f1 * h1 + f2 * h2) < -far_tol * (abs(w) + (a0 * h0 + a1 * h1 + a2 * h2))
        state[j] = 2 if out else (0 if dn >= rn else 1)
        base[0, j], base[1, j], base[2, j] = x, y, w


def _eight(b, o0, o1, o2):
    """A clip row's value at a box's 8 corners (corner k: bit 2 = x, bit 1 = y, bit 0 = z;
    bit set: +): ((b +- o0) +- o1) +- o2, the reference's ((b + sx*o0) + sy*o1) + sz*o2 (a sign
    times a value is exact, b + -a is b - a), the corners sharing signs sharing the sums."""
    a0, a1 = b - o0, b + o0
    b00, b01, b10, b11 = a0 - o1, a0 + o1, a1 - o1, a1 + o1
    return (b00 - o2, b00 + o2, b01 - o2, b01 + o2, b10 - o2, b10 + o2, b11 - o2, b11 + o2)


def _grow(e, x, y):
    """Extents ``e`` (lo x, lo y, hi x, hi y) taking in the point (x, y)."""
    return min(e[0], x), min(e[1], y), max(e[2], x), max(e[3], y)


def _rows(base, half64, s0, j, Mc):
    """Clip x, y, w of box j's 8 corners (``_eight`` each), in the corner dtype: its half
    extents cast to it, times the row's entries, about its centre's clip values ``base``."""
    cast = Mc.dtype.type
    h0, h1, h2 = cast(half64[0, s0 + j]), cast(half64[1, s0 + j]), cast(half64[2, s0 + j])
    return (_eight(base[0, j], h0 * Mc[0, 0], h1 * Mc[0, 1], h2 * Mc[0, 2]),
            _eight(base[1, j], h0 * Mc[1, 0], h1 * Mc[1, 1], h2 * Mc[1, 2]),
            _eight(base[2, j], h0 * Mc[2, 0], h1 * Mc[2, 1], h2 * Mc[2, 2]))


def _corners(base, half64, s0, Mc, ext, m):
    """The NDC extents ``ext`` (4, m) of the corners of a block's boxes in the corner dtype
    (x / w, y / w in corner order, taken in as ``bounds._boxes_block`` reduces them). One
    straight pass per box with no branch and no array but the extents written: it vectorizes
    across the boxes."""
    for j in range(m):
        X, Y, W = _rows(base, half64, s0, j, Mc)
        x, y = X[0] / W[0], Y[0] / W[0]
        e = (x, y, x, y)
        e = _grow(e, X[1] / W[1], Y[1] / W[1])
        e = _grow(e, X[2] / W[2], Y[2] / W[2])
        e = _grow(e, X[3] / W[3], Y[3] / W[3])
        e = _grow(e, X[4] / W[4], Y[4] / W[4])
        e = _grow(e, X[5] / W[5], Y[5] / W[5])
        e = _grow(e, X[6] / W[6], Y[6] / W[6])
        e = _grow(e, X[7] / W[7], Y[7] / W[7])
        ext[0, j], ext[1, j], ext[2, j], ext[3, j] = e


def _box_corners(base, half64, s0, j, Mc, cx, cy):
    """NDC x, y (8,) of box j's corners into ``cx``, ``cy`` (the coverage's shoelace reads
    them): ``_corners``' values, one box at a time."""
    X, Y, W = _rows(base, half64, s0, j, Mc)
    for k in range(8):
        cx[k], cy[k] = X[k] / W[k], Y[k] / W[k]


def _block(center, half64, M, Mc, reach_rows, far_tol, c_lo, c_hi, signs, edges, faces, nxt, out, cov, with_cov,
           s0, m, idx, base, cx, cy, ext, state, cc, filled):
    """Rects of ``m`` boxes from ``s0`` of ``center``/``half64`` into ``out`` (and ``cov``) at
    the indices ``idx[:m]``: culled by the planes, corners projected block-wide (branch-free
    passes over arrays in cache), near-plane crossings clipped one by one. ``filled``: every
    rect is NaN and every coverage 1 already, so only the boxes in view are written (scattered
    writes, one cache line each)."""
    _clip_block(center, half64, M, reach_rows, far_tol, s0, m, base, state)
    _corners(base, half64, s0, Mc, ext, m)
    for j in range(m):
        i = idx[j]
        if with_cov and not filled:
            cov[i] = 1.0
        if state[j] == 2:
            if not filled:
                out[0, i] = out[1, i] = out[2, i] = out[3, i] = np.nan
        elif state[j] == 1:
            c0, c1, c2 = center[0, s0 + j], center[1, s0 + j], center[2, s0 + j]
            for r in range(4):
                cc[r] = M[r, 0] * c0 + M[r, 1] * c1 + M[r, 2] * c2 + M[r, 3]
            _clipped(M, cc, half64[:, s0 + j], signs, edges, out, i, filled)
        else:
            e0, e1, e2, e3 = np.float64(ext[0, j]), np.float64(ext[1, j]), np.float64(ext[2, j]), \
                np.float64(ext[3, j])
            if with_cov:
                _box_corners(base, half64, s0, j, Mc, cx, cy)
                cov[i] = _coverage(cx, cy, faces, nxt, e0, e1, e2, e3)
            _write(out, i, e0, e1, e2, e3, c_lo, c_hi, filled)


def _groups_out(M, rr, gbox, gout):
    """Whether each group's box (``gbox`` (6, G): centre, half extents) lies outside the left,
    right, bottom, top or near plane by more than any rounding of its members' own tests could
    make up (1e-9 of the magnitudes, ~1e7 ulps), into ``gout``: then every member box is culled
    by that plane in ``_clip_block`` too, because a member's box lies inside its group's. The
    far plane (with its tolerance) is left to the members, and so are groups whose bounds are
    not finite. One branch-free pass over the groups (it vectorizes)."""
    m00, m01, m02, m03 = M[0, 0], M[0, 1], M[0, 2], M[0, 3]
    m10, m11, m12, m13 = M[1, 0], M[1, 1], M[1, 2], M[1, 3]
    m20, m21, m22, m23 = M[2, 0], M[2, 1], M[2, 2], M[2, 3]
    m30, m31, m32, m33 = M[3, 0], M[3, 1], M[3, 2], M[3, 3]
    # the magnitudes' column sums: sum over rows of |M[r, a]|
    s0 = abs(m00) + abs(m10) + abs(m20) + abs(m30)
    s1 = abs(m01) + abs(m11) + abs(m21) + abs(m31)
    s2 = abs(m02) + abs(m12) + abs(m22) + abs(m32)
    s3 = abs(m03) + abs(m13) + abs(m23) + abs(m33)
    for g in range(gbox.shape[1]):
        c0, c1, c2, h0, h1, h2 = gbox[0, g], gbox[1, g], gbox[2, g], gbox[3, g], gbox[4, g], gbox[5, g]
        x = m00 * c0 + m01 * c1 + m02 * c2 + m03
        y = m10 * c0 + m11 * c1 + m12 * c2 + m13
        z = m20 * c0 + m21 * c1 + m22 * c2 + m23
        w = m30 * c0 + m31 * c1 + m32 * c2 + m33
        margin = 1e-9 * (s0 * (abs(c0) + 2.0 * h0) + s1 * (abs(c1) + 2.0 * h1) + s2 * (abs(c2) + 2.0 * h2) + s3)
        out = (x + w) + (rr[0, 0] * h0 + rr[0, 1] * h1 + rr[0, 2] * h2) < -margin
        out |= (-x + w) + (rr[1, 0] * h0 + rr[1, 1] * h1 + rr[1, 2] * h2) < -margin
        out |= (y + w) + (rr[2, 0] * h0 + rr[2, 1] * h1 + rr[2, 2] * h2) < -margin
        out |= (-y + w) + (rr[3, 0] * h0 + rr[3, 1] * h1 + rr[3, 2] * h2) < -margin
        out |= (z + w) + (rr[4, 0] * h0 + rr[4, 1] * h1 + rr[4, 2] * h2) < -margin
        gout[g] = out & (margin < np.inf)  # non-finite bounds: the members' own tests


def _frame_rows(M, dtype_of):
    """What every box's tests read from ``M`` (4, 4): the clip rows x, y, w of M[:, :3] in the
    corner dtype (``dtype_of``: an array of it), and the six planes' reach |plane @ M[:, :3]|
    (plane i: +-row i // 2 plus row 3; ``bounds.reach_rows``' values: one rounding each)."""
    Mc = np.empty((3, 3), dtype=dtype_of.dtype)
    for a in range(3):
        Mc[0, a], Mc[1, a], Mc[2, a] = M[0, a], M[1, a], M[3, a]
    rr = np.empty((6, 3))
    for i in range(6):
        sign = 1.0 if i % 2 == 0 else -1.0
        for a in range(3):
            rr[i, a] = abs(sign * M[i // 2, a] + M[3, a])
    return Mc, rr


def _finite(a):
    """Whether every entry of the 2-D ``a`` is finite."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            if not np.isfinite(a[i, j]):
                return False
    return True


def _clip_matrix(proj, view):
    """``proj @ view``, each entry's four products added left to right (``box_tables.clip_matrix``)."""
    M = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            M[i, j] = (proj[i, 0] * view[0, j] + proj[i, 1] * view[1, j] + proj[i, 2] * view[2, j]
                       + proj[i, 3] * view[3, j])
    return M


def _project(center, half, half64, order, groups, gbox, pcenter, phalf64, plain, view, proj, widen, far_tol, out, cov,
             with_cov):
    """Rects (4, N) into ``out`` (NaN: culled or off screen) and, ``with_cov``, silhouette
    coverage into ``cov``. The boxes come in a spatial order (``order[j]``: the object at sorted
    position j; ``center``/``half64`` sorted), in groups of neighbours (``groups``: G+1 starts,
    ``gbox`` (6, G): each group's centre and half extents): a group outside a frustum plane is
    culled whole, the boxes of the others gathered into blocks. Where the groups cull fewer
    than half of the boxes (fewer than an eighth up to ``SCATTER_FREE`` boxes; ``plain`` -1;
    1 always, 0 never), the boxes go in their own order instead (``pcenter``/``phalf64``:
    unsorted): no gathering, and the rects written in sequence rather than scattered at random
    (at 10^6 boxes the scatter alone costs ~8 ms).
    The rects are the same either way: a group's test only culls boxes their own tests cull.
    The box tables (``box_tables``) are compile-time constants, not arguments. False, with
    nothing written, when ``view`` or ``proj`` is not finite (the caller refuses them), else
    True."""
    if not (_finite(view) and _finite(proj)):
        return False
    M = _clip_matrix(proj, view)
    signs, edges, faces, nxt = SIGNS, EDGES, FACES, NEXT
    Mc, reach_rows = _frame_rows(M, half)
    c_lo, c_hi = 0.5 + widen * -0.5, 0.5 + widen * 0.5
    cc = np.empty(4)
    bc = np.empty((3, BLOCK))  # a block of gathered boxes: centres, half extents, object ids
    bh = np.empty((3, BLOCK))
    idx = np.empty(BLOCK, dtype=np.int64)
    base = np.empty((3, BLOCK), dtype=half.dtype)  # the centres' clip x, y, w cast to the corner dtype
    cx = np.empty(8, dtype=half.dtype)  # one box's corners, for its coverage
    cy = np.empty(8, dtype=half.dtype)
    ext = np.empty((4, BLOCK), dtype=half.dtype)
    state = np.empty(BLOCK, dtype=np.int8)
    n_groups = groups.size - 1
    gout = np.zeros(n_groups, dtype=np.bool_)
    culled = 0
    if plain != 1:
        _groups_out(M, reach_rows, gbox, gout)
        for g in range(n_groups):
            if gout[g]:
                culled += groups[g + 1] - groups[g]
    n = pcenter.shape[1]
    if plain == 1 or (plain == -1 and (2 * culled < n if n > SCATTER_FREE else 8 * culled < n)):
        for s0 in range(0, n, BLOCK):
            m = min(BLOCK, n - s0)
            for j in range(m):
                idx[j] = s0 + j
            _block(pcenter, phalf64, M, Mc, reach_rows, far_tol, c_lo, c_hi, signs, edges, faces, nxt, out, cov,
                   with_cov, s0, m, idx, base, cx, cy, ext, state, cc, False)
        return True
    # culled boxes' rects: NaN written in sequence over every row first (a write per culled box
    # scattered by ``order`` would touch every cache line of ``out`` at random), the others
    # overwritten below
    out[:] = np.nan
    if with_cov:
        cov[:] = 1.0
    m = 0
    for g in range(n_groups):
        g0, g1 = groups[g], groups[g + 1]
        if gout[g]:
            continue
        if m + (g1 - g0) > BLOCK:
            _block(bc, bh, M, Mc, reach_rows, far_tol, c_lo, c_hi, signs, edges, faces, nxt, out, cov, with_cov,
                   0, m, idx, base, cx, cy, ext, state, cc, True)
            m = 0
        for a in range(3):
            for j in range(g1 - g0):
                bc[a, m + j] = center[a, g0 + j]
                bh[a, m + j] = half64[a, g0 + j]
        for j in range(g1 - g0):
            idx[m + j] = order[g0 + j]
        m += g1 - g0
    if m:
        _block(bc, bh, M, Mc, reach_rows, far_tol, c_lo, c_hi, signs, edges, faces, nxt, out, cov, with_cov,
               0, m, idx, base, cx, cy, ext, state, cc, True)
    return True


def _project_camera(center, half, half64, order, groups, gbox, pcenter, phalf64, plain, ex, ey, ez, tx, ty, tz, ux,
                    uy, uz, fov, near, far, aspect, widen, far_tol, out, cov, with_cov, frame):
    """A frame's matrices from its camera (``camera.camera_into`` into ``frame`` (3, 4, 4): view,
    projection, light) and then ``_project`` with them, in one call: 0, or 1 where the camera's
    position and target coincide, 2 where the matrices are not finite (nothing projected)."""
    if not _camera_into(ex, ey, ez, tx, ty, tz, ux, uy, uz, fov, near, far, aspect, frame):
        return 1
    ok = _project(center, half, half64, order, groups, gbox, pcenter, phalf64, plain, frame[0], frame[1], widen,
                  far_tol, out, cov, with_cov)
    return 0 if ok else 2


def _seen_frames(center, half, half64, order, groups, gbox, pcenter, phalf64, plain, pos, tgt, up, fov, near, far,
                 aspect, widen, far_tol, out, cov, frame, seen):
    """``seen[f]`` for camera ``f`` (rows of ``pos``, ``tgt``, ``up``, ``fov``, ``near``, ``far``):
    1 where ``_project_camera`` puts some box's rect on the display ([0, 1]^2), 0 where none, -1
    where it refused the camera: a generated path's check of every frame in one call."""
    for f in range(pos.shape[0]):
        status = _project_camera(center, half, half64, order, groups, gbox, pcenter, phalf64, plain, pos[f, 0],
                                 pos[f, 1], pos[f, 2], tgt[f, 0], tgt[f, 1], tgt[f, 2], up[f, 0], up[f, 1], up[f, 2],
                                 fov[f], near[f], far[f], aspect, widen, far_tol, out, cov, False, frame)
        if status != 0:
            seen[f] = -1
            continue
        seen[f] = 0
        for i in range(out.shape[1]):
            if out[2, i] >= 0 and out[0, i] <= 1 and out[3, i] >= 0 and out[1, i] <= 1:
                seen[f] = 1
                break


compile_all(globals(), ("_finite", "_clip_matrix", "_clip_block", "_eight", "_grow", "_rows", "_corners",
                         "_box_corners", "_face", "_coverage", "_write", "_clipped", "_block", "_groups_out",
                         "_frame_rows", "_project", "_camera_into", "_project_camera", "_seen_frames"))


def project_boxes(grouped, plain_boxes, half, view, proj, widen, far_tol, out, coverage=None, plain: int = -1) -> bool:
    """``bounds.BoxProjector``'s rects (4, N) into ``out`` and, when given, silhouette coverage;
    ``grouped``: ``project.spatial_groups`` of the boxes (culled a group at a time);
    ``plain_boxes``: (centres, half extents) in object order, used where the groups cull
    fewer than half the boxes (an eighth up to ``project.SCATTER_FREE`` boxes; ``plain`` -1;
    1: always, 0: never; the same rects). False
    (nothing written) when ``view`` or ``proj`` has an entry that is not finite."""
    order, center, half64, starts, gbox = grouped
    cov = _NO_COVERAGE if coverage is None else coverage
    return _project(center, half, half64, order, starts, gbox, plain_boxes[0], plain_boxes[1], plain, view, proj,
                    widen, far_tol, out, cov, coverage is not None)


_NO_COVERAGE = np.empty(0)
