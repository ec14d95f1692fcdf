"""Cross-segment balancing compiled (``strategies/cross.py``): the segments' time profiles from
the last frame's pieces and times, the view equalizer's damped shares, the cuts that give each
helper its share of a segment, and then every piece's object mask, the ranks' T' masks, loads
and bounding regions: two compiled calls where the reference makes some 600 numpy calls.

Same operations in the same order as the reference (sequential sums), so pieces, masks and
loads are identical (tests/test_kernel.py).
"""

from __future__ import annotations

import numpy as np

from multigpu.core.kernel.jit import compile_all


def _profiles(allp, owner, k, times, tiles):
    """Per segment: axis (0: x), start, length, time profile along its longer axis (rows of
    ``prof``), and its total time (``loads``)."""
    P, T = allp.shape[0], tiles.shape[0]
    floats = np.zeros(k + P + T)  # one allocation where three were: each costs ~0.4 us with the caches cold
    rank_area, density, loads = floats[:k], floats[k:k + P], floats[k + P:]
    for p in range(P):
        rank_area[owner[p]] += np.float64((allp[p, 2] - allp[p, 0]) * (allp[p, 3] - allp[p, 1]))
    for p in range(P):
        density[p] = times[owner[p]] / max(rank_area[owner[p]], 1.0)
    ints = np.zeros((3 + P, T), dtype=np.int64)  # axes, starts, lengths, then the (P, T) overlaps
    axes, a0s, lens, inter = ints[0], ints[1], ints[2], ints[3:]
    for p in range(P):
        for t in range(T):
            w = min(allp[p, 2], tiles[t, 2]) - max(allp[p, 0], tiles[t, 0])
            h = min(allp[p, 3], tiles[t, 3]) - max(allp[p, 1], tiles[t, 1])
            inter[p, t] = max(w, 0) * max(h, 0)
    longest = 0
    for t in range(T):
        loads[t] = density[0] * inter[0, t] if P else 0.0
        for p in range(1, P):
            loads[t] += density[p] * inter[p, t]
        longest = max(longest, tiles[t, 2] - tiles[t, 0], tiles[t, 3] - tiles[t, 1])
    prof = np.zeros((T, longest))
    for t in range(T):
        x0, y0, x1, y1 = tiles[t, 0], tiles[t, 1], tiles[t, 2], tiles[t, 3]
        ax = 0 if x1 - x0 >= y1 - y0 else 1
        a0, a1 = (x0, x1) if ax == 0 else (y0, y1)
        axes[t], a0s[t], lens[t] = ax, a0, a1 - a0
        for j in range(P):
            if inter[j, t] == 0:
                continue
            px0, py0, px1, py1 = allp[j, 0], allp[j, 1], allp[j, 2], allp[j, 3]
            if ax == 0:
                lo, hi, across = max(px0, x0), min(px1, x1), min(py1, y1) - max(py0, y0)
            else:
                lo, hi, across = max(py0, y0), min(py1, y1), min(px1, x1) - max(px0, x0)
            v = density[j] * across
            for i in range(lo - a0, hi - a0):
                prof[t, i] += v
    return axes, a0s, lens, prof, loads


def _seqsum(x):
    s = x[0]
    for i in range(1, x.shape[0]):
        s += x[i]
    return s


def _cut(allp, owner, times, tiles, shares, out, damping, min_share, packed):
    """The view equalizer's new shares (into ``out``) and every rank's pieces, rank-major, each
    rank's pieces in segment order, written into ``packed`` (``_cross``'s layout: rects (Q, 4)
    from 6K + 1, owners (Q,) after them); returns Q. Few allocations: each costs ~0.4 us of
    CPU with the caches cold (ad hoc), and a frame's plan made some forty."""
    k = tiles.shape[0]
    axes, a0s, lens, prof, loads = _profiles(allp, owner, k, times, tiles)
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
    for t in range(1, k):
        start[t] = start[t - 1] + out[t - 1]
    rects = np.zeros((2 * k * k, 4), dtype=np.int64)
    ids = np.zeros((3, 2 * k * k), dtype=np.int64)
    who, seg, helpers = ids[0], ids[1], ids[2]
    cum_at = np.empty(prof.shape[1])  # every segment's cumulative profile and cuts, in turn
    cuts_at = np.empty(k + 1, dtype=np.int64)
    q = 0
    for t in range(k):  # segments
        lo_r, hi_r = start[t], start[t] + out[t]
        m = 0
        for r in range(k):
            u = min(r + 1.0, hi_r) - max(r * 1.0, lo_r)
            if u > 1e-12:
                helpers[m], used[m] = r, u
                m += 1
        n = lens[t]
        cum = cum_at[:n]
        positive = False
        for i in range(n):
            positive |= prof[t, i] > 0
        for i in range(n):
            cum[i] = (cum[i - 1] if i else 0.0) + prof[t, i] if positive else i + 1.0
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
            if axes[t] == 0:
                rects[q, 0], rects[q, 1], rects[q, 2], rects[q, 3] = a0s[t] + c0, y0, a0s[t] + c1, y1
            else:
                rects[q, 0], rects[q, 1], rects[q, 2], rects[q, 3] = x0, a0s[t] + c0, x1, a0s[t] + c1
            who[q], seg[q] = helpers[j], t
            q += 1
    # rank-major, segments in order: a stable insertion sort of the few pieces (numpy's
    # mergesort and the gathers after it allocated five arrays)
    order = np.empty(q, dtype=np.int64)
    for i in range(q):
        key, j = who[i] * k + seg[i], i
        while j > 0 and who[order[j - 1]] * k + seg[order[j - 1]] > key:
            order[j] = order[j - 1]
            j -= 1
        order[j] = i
    at = 6 * k + 1
    for i in range(q):
        o = order[i]
        for c in range(4):
            packed[at + 4 * i + c] = rects[o, c]
        packed[at + 4 * q + i] = who[o]
    return q


def _masks(rt, tris, W, H, prects, powner, k, packed):
    """Every piece's object mask (its rect overlaps the object's pixel span) and the ranks' T'
    masks, in one (P + K, N) array (pieces first, returned); loads (an object drawn in two
    pieces counts twice) and bounding regions into ``packed`` (``_cross``'s layout, the pieces'
    starts per rank already there). One pass over the rects: an object's span is formed where
    it is tested, as ``walk._spans`` forms it, and not kept (cross-segment partitions carry no
    spans: only the cost model reads them, from its own partitions)."""
    n = rt.shape[1]
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
    w1, h1 = W - 1.0, H - 1.0
    for o in range(n):  # one sequential pass over the objects, the pieces tested for those on screen
        a0, a1, a2, a3 = rt[0, o], rt[1, o], rt[2, o], rt[3, o]
        if not (a2 >= 0.0 and a0 <= 1.0 and a3 >= 0.0 and a1 <= 1.0):  # off screen, or NaN
            continue
        s0, s1 = np.int32(min(max(a0 * W, 0.0), w1)), np.int32(min(max(a1 * H, 0.0), h1))
        s2, s3 = np.int32(min(max(a2 * W, 0.0), w1)), np.int32(min(max(a3 * H, 0.0), h1))
        for p in range(P):  # integer loads: the same sums in any order
            if s0 < prects[p, 2] and s2 >= prects[p, 0] and s1 < prects[p, 3] and s3 >= prects[p, 1]:
                masks[p, o] = True
                visible[powner[p], o] = True
                loads[powner[p]] += tris[o]
    return both


def _cross(allp, owner, times, tiles, shares, new, damping, min_share, rt, tris, W, H):
    """``_cut`` then ``_masks`` in one call (a frame's cross-segment plan): the new shares into
    ``new`` and the rest packed in two arrays (every returned array costs a Python call to box
    it, paid again with the caches cold): the integers ``[at (K+1) | regions (K, 4) | loads (K) | pieces (Q, 4) | owner
    (Q)]``, ``at`` where each rank's pieces start in the rank-major pieces; the masks ``[pieces'
    (Q, N) | ranks' T' (K, N)]``. ``tris``: int64."""
    k = tiles.shape[0]
    packed = np.zeros(6 * k + 1 + 5 * 2 * k * k, dtype=np.int64)  # room for the most pieces ``_cut`` makes
    q = _cut(allp, owner, times, tiles, shares, new, damping, min_share, packed)
    at = 6 * k + 1
    prects, powner = packed[at:at + 4 * q].reshape((q, 4)), packed[at + 4 * q:at + 5 * q]
    for p in range(q):
        packed[powner[p] + 1] += 1
    for r in range(k):
        packed[r + 1] += packed[r]
    both = _masks(rt, tris, W, H, prects, powner, k, packed)
    return packed[:at + 5 * q], both


compile_all(globals(), ("_profiles", "_seqsum", "_cut", "_masks", "_cross"))
