"""Cross-segment balancing compiled (``strategies/cross.py``): the segments' time profiles from
the last frame's pieces, their weights and times and this frame's rects (the time model), the
view equalizer's damped shares, the cuts that give each helper its share of a segment, each
rank's pieces joined where they share an edge, and then every piece's object mask and weight,
the ranks' T' masks, loads and bounding regions: one compiled call where the reference makes
some 600 numpy calls.

Same operations in the same order as the reference (sequential sums), so pieces, masks, weights
and loads are identical (tests/test_kernel.py).
"""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all, entry

#: the most objects on screen the time profiles weigh one by one (more: every k-th stands for k,
#: in ``strategies.cross`` too); a profile places a few cuts, and each object costs ~15 ns
SAMPLE = 8192


def _model(rt, tris, W, H, pixel_weight, object_weight, cover_weight, uniform, spans, d, on):
    """``strategies.cross._density``: the on-screen objects (their indices, M), their inclusive
    pixel spans (M, 4) int64 and weights per pixel of span (M,), and a pixel's own weight
    (``uniform``: 1, the objects' 0), written into the caller's ``spans`` (N, 4), ``d``, ``on``
    (N,) and returned as their first M rows: fresh arrays of 10^5 rows would be page-faulted
    every frame."""
    n = rt.shape[1]
    m, total, covered = 0, 0, 0
    w1, h1 = W - 1.0, H - 1.0
    for o in range(n):  # the spans as ``regions.pixel_spans`` forms them, for the on-screen objects
        a0, a1, a2, a3 = rt[0, o], rt[1, o], rt[2, o], rt[3, o]
        if not (a2 >= 0.0 and a0 <= 1.0 and a3 >= 0.0 and a1 <= 1.0):  # off screen, or NaN
            continue
        s0, s1 = np.int64(np.int32(min(max(a0 * W, 0.0), w1))), np.int64(np.int32(min(max(a1 * H, 0.0), h1)))
        s2, s3 = np.int64(np.int32(min(max(a2 * W, 0.0), w1))), np.int64(np.int32(min(max(a3 * H, 0.0), h1)))
        spans[m, 0], spans[m, 1], spans[m, 2], spans[m, 3] = s0, s1, s2, s3
        covered += (s2 - s0 + 1) * (s3 - s1 + 1)
        total += tris[o]
        on[m] = o
        m += 1
    if uniform or m == 0:
        d[:m] = 0.0
        return on[:m], spans[:m], d[:m], 1.0 if uniform else pixel_weight * np.float64(total) / (W * H)
    per_object = object_weight * np.float64(total) / m
    per_pixel = cover_weight * np.float64(total) / np.float64(covered)
    for i in range(m):  # the frame's means known: each object's weight spread over its span
        area = (spans[i, 2] - spans[i, 0] + 1) * (spans[i, 3] - spans[i, 1] + 1)
        d[i] = (tris[on[i]] + per_object) / area + per_pixel
    return on[:m], spans[:m], d[:m], pixel_weight * np.float64(total) / (W * H)


def _mass(on, spans, d, beta, x0, y0, x1, y1):
    """``strategies.cross._mass``: the weight of the rect ``[x0, y0, x1, y1)``."""
    acc = 0.0
    for i in range(on.shape[0]):
        ox = min(spans[i, 2] + 1, x1) - max(spans[i, 0], x0)
        oy = min(spans[i, 3] + 1, y1) - max(spans[i, 1], y0)
        if ox > 0 and oy > 0:
            acc += d[i] * ox * oy
    return beta * ((x1 - x0) * (y1 - y0)) + acc


def _axes(tiles):
    """Per segment: the axis it is cut across (0: x, its longer), its start and length on it."""
    T = tiles.shape[0]
    ints = np.zeros((3, T), dtype=np.int64)
    for t in range(T):
        x0, y0, x1, y1 = tiles[t, 0], tiles[t, 1], tiles[t, 2], tiles[t, 3]
        ax = 0 if x1 - x0 >= y1 - y0 else 1
        ints[0, t], ints[1, t], ints[2, t] = ax, (x0, y0)[ax], (x1 - x0, y1 - y0)[ax]
    return ints[0], ints[1], ints[2]


def _profiles(allp, owner, k, times, tiles, mass, on, spans, d, beta):
    """Per segment: axis (0: x), start, length, time profile along its longer axis (rows of
    ``prof``), and its total time (``loads``): this frame's weight along the axis (``on``,
    ``spans``, ``d``, ``beta``: ``_model``) times the rate of the last frame's pieces
    (``allp``, rank-major) over each position, each piece's rank's time per unit of ``mass``
    (their weights when planned; empty: weighed now), averaged across the axis. One pass over
    the objects, each adding to the segments its span meets (found in lookup tables: the segments
    are a grid of equal tiles) without a test per segment (unpredictable, so slow)."""
    P, T = allp.shape[0], tiles.shape[0]
    floats = np.zeros(2 * k + T)  # one allocation where three were: each costs ~0.4 us with the caches cold
    rank_w, rate, loads = floats[:k], floats[k:2 * k], floats[2 * k:]
    for p in range(P):
        x0, y0, x1, y1 = allp[p, 0], allp[p, 1], allp[p, 2], allp[p, 3]
        rank_w[owner[p]] += mass[p] if mass.shape[0] == P else _mass(on, spans, d, beta, x0, y0, x1, y1)
    for r in range(k):
        rate[r] = times[r] / rank_w[r] if rank_w[r] > 0 else 0.0
    axes, a0s, lens = _axes(tiles)
    longest = 0
    for t in range(T):
        longest = max(longest, lens[t])
    diffs = np.zeros((2, T, longest + 1))  # the weight's and the rate's differences along each axis
    g, rr = diffs[0], diffs[1]
    for t in range(T):  # the pieces' rates over each segment, in piece order
        x0, y0, x1, y1 = tiles[t, 0], tiles[t, 1], tiles[t, 2], tiles[t, 3]
        for j in range(P):
            q0, q1 = max(allp[j, 0], x0), max(allp[j, 1], y0)
            q2, q3 = min(allp[j, 2], x1), min(allp[j, 3], y1)
            if q2 > q0 and q3 > q1:
                lo, hi, across = (q0, q2, q3 - q1) if axes[t] == 0 else (q1, q3, q2 - q0)
                rr[t, lo - a0s[t]] += rate[owner[j]] * across
                rr[t, hi - a0s[t]] -= rate[owner[j]] * across
    tw, th = tiles[0, 2] - tiles[0, 0], tiles[0, 3] - tiles[0, 1]  # a grid of equal tiles from (0, 0)
    cols, rows = tiles[:, 2].max() // tw, tiles[:, 3].max() // th
    label = np.empty((rows, cols), dtype=np.int64)
    for t in range(T):
        label[tiles[t, 1] // th, tiles[t, 0] // tw] = t
    span_x, span_y = spans[:, 2].max() + 2 if on.shape[0] else 1, spans[:, 3].max() + 2 if on.shape[0] else 1
    col_of, row_of = np.empty(span_x, dtype=np.int64), np.empty(span_y, dtype=np.int64)  # no division per object
    for x in range(span_x):
        col_of[x] = min(x // tw, cols - 1)
    for y in range(span_y):
        row_of[y] = min(y // th, rows - 1)
    step = max(on.shape[0] // SAMPLE, 1)  # past SAMPLE objects on screen, every step-th stands for step
    for i in range(0, on.shape[0], step):  # each object's start and end along the segments it meets, in order
        s0, s1, s2, s3, dd = spans[i, 0], spans[i, 1], spans[i, 2] + 1, spans[i, 3] + 1, d[i] * step
        for cy in range(row_of[s1], row_of[s3 - 1] + 1):
            for cx in range(col_of[s0], col_of[s2 - 1] + 1):
                t = label[cy, cx]
                x0, y0, x1, y1 = tiles[t, 0], tiles[t, 1], tiles[t, 2], tiles[t, 3]
                if axes[t] == 0:
                    oc, a, b = max(min(s3, y1) - max(s1, y0), 0), min(max(s0, x0), x1), max(min(s2, x1), x0)
                else:
                    oc, a, b = max(min(s2, x1) - max(s0, x0), 0), min(max(s1, y0), y1), max(min(s3, y1), y0)
                x = dd * oc * (b > a)  # nothing met (a span past the last tile) adds 0.0
                g[t, a - a0s[t]] += x
                g[t, b - a0s[t]] -= x
    prof = np.zeros((T, longest))
    for t in range(T):
        across = (tiles[t, 3] - tiles[t, 1]) if axes[t] == 0 else (tiles[t, 2] - tiles[t, 0])
        w, r = 0.0, 0.0
        for i in range(lens[t]):
            w += g[t, i]
            r += rr[t, i]
            prof[t, i] = r / across * (w + beta * across)
        loads[t] = _seqsum(prof[t, :lens[t]])
    return axes, a0s, lens, prof, loads


def _reverse(tiles, order, p, ax, helpers, used, m):
    """``strategies.cross``'s ``_reverse``: whether segment ``order[p]``'s helpers (positions
    on the resource axis) run from the high end of its cut axis ``ax``."""
    t, k = order[p], order.shape[0]
    before, after = 0.0, 0.0
    for j in range(m):
        if helpers[j] < p:
            before += used[j]
        elif helpers[j] > p:
            after += used[j]
    prev = p > 0 and _side(tiles, order[p - 1], t) == ax
    nxt = p + 1 < k and _side(tiles, order[p + 1], t) == ax
    if prev and (before >= after or not nxt):
        return tiles[order[p - 1], ax] > tiles[t, ax]
    if nxt:
        return tiles[order[p + 1], ax] < tiles[t, ax]
    return False


def _side(tiles, q, t):
    """The axis that separates neighbouring tiles ``q`` and ``t`` (0: x, same row)."""
    return 0 if tiles[q, 1] == tiles[t, 1] and tiles[q, 3] == tiles[t, 3] else 1


def _join(rects, lo, hi):
    """``strategies.cross``'s ``_join`` on one rank's pieces, rows ``lo:hi`` of ``rects`` (in
    segment order): any two that share a whole edge joined, in place; returns the new end."""
    i = lo
    while i < hi:
        joined = False
        for j in range(i + 1, hi):
            a0, a1, a2, a3 = rects[i, 0], rects[i, 1], rects[i, 2], rects[i, 3]
            b0, b1, b2, b3 = rects[j, 0], rects[j, 1], rects[j, 2], rects[j, 3]
            if a1 == b1 and a3 == b3 and (a2 == b0 or b2 == a0):
                rects[i, 0], rects[i, 2] = min(a0, b0), max(a2, b2)
            elif a0 == b0 and a2 == b2 and (a3 == b1 or b3 == a1):
                rects[i, 1], rects[i, 3] = min(a1, b1), max(a3, b3)
            else:
                continue
            for r in range(j, hi - 1):  # the pieces after j move up
                for c in range(4):
                    rects[r, c] = rects[r + 1, c]
            hi -= 1
            joined = True
            break
        i = lo if joined else i + 1
    return hi


def _seqsum(x):
    s = x[0]
    for i in range(1, x.shape[0]):
        s += x[i]
    return s


def _helpers(lo_r, hi_r, k, min_help, helpers, used):
    """The units (positions on the resource axis) helping the segment at ``[lo_r, hi_r)`` and
    how much, into ``helpers`` and ``used``: those with at least ``min_help`` of their unit,
    else the one with the most; returns how many."""
    m, best, most = 0, 0, -1.0
    for r in range(k):
        u = min(r + 1.0, hi_r) - max(r * 1.0, lo_r)
        if u > most:
            best, most = r, u
        if u > 1e-12 and u >= min_help:
            helpers[m], used[m] = r, u
            m += 1
    if m == 0:
        helpers[0], used[0], m = best, most, 1
    return m


def _pack(rects, who, seg, q, k, join, packed):
    """The ``q`` pieces (``rects``, owners ``who``, segments ``seg``) rank-major, each rank's in
    segment order and joined (``_join``) where ``join``, into ``packed`` (``_cross``'s layout);
    returns how many are left."""
    # rank-major, segments in order: a stable insertion sort of the few pieces (numpy's
    # mergesort and the gathers after it allocated five arrays)
    order_q = np.empty(q, dtype=np.int64)
    for i in range(q):
        key, j = who[i] * k + seg[i], i
        while j > 0 and who[order_q[j - 1]] * k + seg[order_q[j - 1]] > key:
            order_q[j] = order_q[j - 1]
            j -= 1
        order_q[j] = i
    ranked = rects[k * k:k * k + q]  # the sorted pieces (at most K per segment: q <= K * K)
    for i in range(q):
        for c in range(4):
            ranked[i, c] = rects[order_q[i], c]
    at, n_out, i = 6 * k + 1, 0, 0
    while i < q:  # each rank's pieces joined, then packed; the owners into ``seg`` (read no more)
        r, e = who[order_q[i]], i
        while e < q and who[order_q[e]] == r:
            e += 1
        end = _join(ranked, i, e) if join else e
        for j in range(i, end):
            for c in range(4):
                packed[at + 4 * n_out + c] = ranked[j, c]
            seg[n_out] = r
            n_out += 1
        i = e
    for j in range(n_out):
        packed[at + 4 * n_out + j] = seg[j]
    return n_out


def _cut(allp, owner, times, tiles, order, shares, out, damping, min_share, min_help, join, packed, mass, model):
    """The view equalizer's new shares (into ``out``) and every rank's pieces, rank-major, each
    rank's pieces in segment order and joined where they share an edge, written into
    ``packed`` (``_cross``'s layout: rects (Q, 4) from 6K + 1, owners (Q,) after them); returns
    Q. ``order``: the segments along the resource axis; ``mass``, ``model``: ``_profiles``'.
    Few allocations: each costs ~0.4 us of CPU with the caches cold (ad hoc), and a frame's
    plan made some forty."""
    k = tiles.shape[0]
    on, spans, d, beta = model
    axes, a0s, lens, prof, loads = _profiles(allp, owner, k, times, tiles, mass, on, spans, d, beta)
    total = _seqsum(loads)
    floats = np.zeros((3, k))
    new, start, used = floats[0], floats[1], floats[2]
    for t in range(k):
        new[t] = k * loads[t] / total if total > 0 else 1.0
    for t in range(k):
        out[t] = max((1 - damping) * new[t] + damping * shares[t], min_share)
    scale = k / _seqsum(out)
    for t in range(k):
        out[t] = out[t] * scale
    for p in range(1, k):
        start[order[p]] = start[order[p - 1]] + out[order[p - 1]]
    rects = np.zeros((2 * k * k, 4), dtype=np.int64)
    ids = np.zeros((3, 2 * k * k), dtype=np.int64)
    who, seg, helpers = ids[0], ids[1], ids[2]
    cum_at = np.empty(prof.shape[1])  # every segment's cumulative profile and cuts, in turn
    cuts_at = np.empty(k + 1, dtype=np.int64)
    q = 0
    for p in range(k):  # segments along the resource axis
        t = order[p]
        lo_r, hi_r = start[t], start[t] + out[t]
        m = _helpers(lo_r, hi_r, k, min_help, helpers, used)
        ax, a0, n = axes[t], a0s[t], lens[t]
        rev = join and _reverse(tiles, order, p, ax, helpers, used, m)
        cum = cum_at[:n]
        positive = False
        for i in range(n):
            positive |= prof[t, i] > 0
        for i in range(n):
            v = prof[t, n - 1 - i] if rev else prof[t, i]
            cum[i] = (cum[i - 1] if i else 0.0) + v if positive else i + 1.0
        usum = _seqsum(used[:m])
        cuts = cuts_at[:m + 1]
        cuts[0], cuts[m] = 0, n
        acc = 0.0
        for j in range(m - 1):
            acc += used[j]
            target = acc / usum * cum[n - 1]
            cuts[j + 1] = np.searchsorted(cum, target) + 1
        for j in range(1, m + 1):
            cuts[j] = max(cuts[j - 1], min(cuts[j], n))
        x0, y0, x1, y1 = tiles[t, 0], tiles[t, 1], tiles[t, 2], tiles[t, 3]
        for j in range(m):
            c0, c1 = cuts[j], cuts[j + 1]
            if c1 <= c0:
                continue
            if rev:
                c0, c1 = n - c1, n - c0
            if ax == 0:
                rects[q, 0], rects[q, 1], rects[q, 2], rects[q, 3] = a0 + c0, y0, a0 + c1, y1
            else:
                rects[q, 0], rects[q, 1], rects[q, 2], rects[q, 3] = x0, a0 + c0, x1, a0 + c1
            who[q], seg[q] = order[helpers[j]], t
            q += 1
    return _pack(rects, who, seg, q, k, join, packed)


def _masks(tris, n, prects, powner, k, packed, model, mass):
    """Every piece's object mask (its rect overlaps the object's pixel span) and the ranks' T'
    masks, in one (P + K, N) array (pieces first, returned); loads (an object drawn in two
    pieces counts twice) and bounding regions into ``packed`` (``_cross``'s layout, the pieces'
    starts per rank already there); every piece's weight (``_mass``, with ``d``, ``beta``:
    ``_model``'s) into ``mass``. One pass over the objects on screen, their spans
    ``model``'s (cross-segment partitions carry no spans: only the cost model reads them, from
    its own partitions)."""
    on, spans, d, beta = model
    P = prects.shape[0]
    both = np.zeros((P + k, n), dtype=np.bool_)
    masks, visible = both[:P], both[P:]
    regions, loads = packed[k + 1:5 * k + 1], packed[5 * k + 1:6 * k + 1]
    for p in range(P):
        r = powner[p]
        x0, y0, x1, y1 = prects[p, 0], prects[p, 1], prects[p, 2], prects[p, 3]
        if p > packed[r]:  # not the rank's first piece (the pieces are rank-major)
            regions[4 * r], regions[4 * r + 1] = min(regions[4 * r], x0), min(regions[4 * r + 1], y0)
            regions[4 * r + 2], regions[4 * r + 3] = max(regions[4 * r + 2], x1), max(regions[4 * r + 3], y1)
        else:
            regions[4 * r], regions[4 * r + 1], regions[4 * r + 2], regions[4 * r + 3] = x0, y0, x1, y1
    for i in range(on.shape[0]):  # one sequential pass over the objects on screen, the pieces tested
        o = on[i]
        s0, s1, s2, s3 = spans[i, 0], spans[i, 1], spans[i, 2], spans[i, 3]
        for p in range(P):  # integer loads: the same sums in any order
            if s0 < prects[p, 2] and s2 >= prects[p, 0] and s1 < prects[p, 3] and s3 >= prects[p, 1]:
                masks[p, o] = True
                visible[powner[p], o] = True
                loads[powner[p]] += tris[o]
                ox = min(s2 + 1, prects[p, 2]) - max(s0, prects[p, 0])
                oy = min(s3 + 1, prects[p, 3]) - max(s1, prects[p, 1])
                mass[p] += d[i] * ox * oy
    for p in range(P):
        mass[p] = beta * ((prects[p, 2] - prects[p, 0]) * (prects[p, 3] - prects[p, 1])) + mass[p]
    return both


def _cross(allp, owner, times, tiles, order, shares, new, damping, min_share, min_help, join, rt, tris, W, H,
           mass, pixel_weight, object_weight, cover_weight, uniform, spans, d, on):
    """``_cut`` then ``_masks`` in one call (a frame's cross-segment plan): the new shares into
    ``new`` and the rest packed in two arrays (every returned array costs a Python call to box
    it, paid again with the caches cold): the integers ``[at (K+1) | regions (K, 4) | loads (K) | pieces (Q, 4) | owner
    (Q)]``, ``at`` where each rank's pieces start in the rank-major pieces; the masks ``[pieces'
    (Q, N) | ranks' T' (K, N)]``; and the pieces' weights (Q,) under this frame's model, which
    the next frame's ``mass`` reads. ``tris``: int64; ``mass``: the last frame's pieces' weights
    when they were planned (empty: weighed with this frame's rects)."""
    k = tiles.shape[0]
    packed = np.zeros(6 * k + 1 + 5 * 2 * k * k, dtype=np.int64)  # room for the most pieces ``_cut`` makes
    model = _model(rt, tris, W, H, pixel_weight, object_weight, cover_weight, uniform, spans, d, on)
    q = _cut(allp, owner, times, tiles, order, shares, new, damping, min_share, min_help, join, packed, mass, model)
    at = 6 * k + 1
    prects, powner = packed[at:at + 4 * q].reshape((q, 4)), packed[at + 4 * q:at + 5 * q]
    for p in range(q):
        packed[powner[p] + 1] += 1
    for r in range(k):
        packed[r + 1] += packed[r]
    weights = np.zeros(q)
    both = _masks(tris, rt.shape[1], prects, powner, k, packed, model, weights)
    return packed[:at + 5 * q], both, weights


compile_all(globals(), ("_model", "_mass", "_axes", "_profiles", "_reverse", "_side", "_join", "_helpers", "_pack",
                        "_seqsum", "_cut", "_masks", "_cross"))


def scratch_for(n: int) -> tuple:
    """``cross_partition``'s per-object scratch for ``n`` objects (the time model's spans, weights
    and on-screen objects), kept by the caller between frames."""
    return np.empty((n, 4), dtype=np.int64), np.empty(n), np.empty(n, dtype=np.int64)


def cross_partition(pieces, mass, times, tiles, order, shares, damping: float, min_share: float, min_help: float,
                    join: bool, pixel_weight: float, object_weight: float, cover_weight: float, uniform: bool,
                    rects, tris, size,
                    out: np.ndarray | None = None, bound: dict | None = None, scratch: tuple | None = None):
    """``strategies.cross``: the new segment shares (into ``out`` where given, a (K,) float64
    array other than ``shares``), and the partition's fields (regions, loads, T' masks, splits,
    split pixels, no spans, pieces and their masks per rank, and the pieces flat for the next
    frame: ``{"pieces": (Q, 4), "owner": (Q,), "mass": (Q,)}``, their weights in the time model)
    from the last frame's pieces (that flat form, or per rank), their weights ``mass`` (None:
    weighed now; ignored where the flat form carries them) and measured ``times``; ``order``:
    the segments along the resource axis; ``join``: helpers cut from their own side and a rank's
    pieces joined; ``pixel_weight``, ``object_weight``, ``cover_weight``, ``uniform``: the time
    model's. One compiled call.
    ``bound``: a dict the caller keeps between calls that passes the same types every call
    (``times``, ``tiles``, ``order``, ``shares``, ``out``: C-contiguous float64, int64, int64,
    float64, float64 arrays; ``damping``, ``min_share``, ``min_help`` and the model's weights floats;
    ``join``, ``uniform`` bools; ``size`` ints): the kernel's entry point is kept there and
    called directly where the pieces are flat (``jit.entry``). ``scratch``: the time model's
    per-object arrays, ``scratch_for(len(tris))``, kept by the caller (None: made here)."""
    k = len(tiles)
    flat = isinstance(pieces, dict)
    if flat:  # the last frame's flat pieces, as this function returned them
        allp, owner, mass = pieces["pieces"], pieces["owner"], pieces["mass"]
    else:
        allp = np.concatenate([np.asarray(p, dtype=np.int64).reshape(-1, 4) for p in pieces])  # ranks, not objects
        owner = np.repeat(np.arange(k), [len(p) for p in pieces])
        mass = np.zeros(0) if mass is None else np.ascontiguousarray(mass, dtype=np.float64)
    new = np.empty(k) if out is None else out
    # (4, N) float64 rects (the projector's own array, transposed back: no copy) and int64 weights
    args = (allp, owner, times, tiles, order, shares, new, damping, min_share, min_help, join,
            np.ascontiguousarray(rects.T, dtype=np.float64),
            np.ascontiguousarray(tris, dtype=np.int64), size[0], size[1], mass, pixel_weight, object_weight,
            cover_weight, uniform,
            *(scratch if scratch is not None else scratch_for(len(tris))))
    call = _cross
    if flat and bound is not None:  # the entry point, bound at the first flat call
        call = bound.get("cross")
        if call is None:
            call = bound["cross"] = entry(_cross, args)
    ints, both, weights = call(*args)
    # views of the packed arrays (their layout: _cross) in few Python steps (each costs us, cold)
    at = ints[:k + 1].tolist()
    q = at[k]
    prects = ints[6 * k + 1:6 * k + 1 + 4 * q].reshape(q, 4)
    cuts = list(zip(at[:-1], at[1:]))
    none, none_px = _no_splits(k)
    return new, (ints[k + 1:5 * k + 1].reshape(k, 4), ints[5 * k + 1:6 * k + 1], both[q:], none, none_px, None,
                 tuple([prects[a:b] for a, b in cuts]), tuple([both[a:b] for a, b in cuts]),
                 {"pieces": prects, "owner": ints[6 * k + 1 + 4 * q:], "mass": weights})


_NO_SPLITS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _no_splits(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Read-only (K-1,) zero splits and split pixels of a partition with no tree (one pair per K)."""
    if k not in _NO_SPLITS:
        pair = np.zeros(max(k - 1, 0)), np.zeros(max(k - 1, 0), dtype=np.int64)
        for a in pair:
            a.setflags(write=False)
        _NO_SPLITS[k] = pair
    return _NO_SPLITS[k]
