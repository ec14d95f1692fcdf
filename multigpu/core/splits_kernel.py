"""Equalizer's time chooser compiled (``splits.time_chooser`` at every node of the GPU tree, as
``balance.node_cuts`` walks it): each rank's last measured time spread evenly over its last
region, and at each node the candidate cut whose time below and above best matches the ranks
on either side, moved only ``damping`` of the way from the last cut. One call for the tree's
K - 1 cuts where the reference makes some 120 numpy calls (~0.5 ms of CPU a frame); the
compiled walk then takes the cuts.

Same operations in the same order as the reference (its sums over ranks sequential), so the cuts
are equal (tests/test_kernel.py).
"""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all


def _choose(regions, density, ax, reg, a, b, q, nl, nr, need_lo, need_hi, w, x):
    """``time_chooser``'s candidate cut at one node (``[a, b)`` along ``ax`` of region ``reg``),
    before the damping; -1 where none has time on both sides (the reference's target, undamped).
    ``w``, ``x``: scratch of K."""
    k, ot = regions.shape[0], 1 - ax
    length = b - a
    for r in range(k):  # time per pixel along the axis, per old region
        o = min(regions[r, ot + 2], np.float64(reg[ot + 2])) - max(regions[r, ot], np.float64(reg[ot]))
        w[r] = density[r] * max(o, 0.0)
    for r in range(k):
        x[r] = max(min(np.float64(b), regions[r, ax + 2]) - max(np.float64(a), regions[r, ax]), 0.0)
    total = x[0] * w[0]
    for r in range(1, k):
        total += x[r] * w[r]
    if total <= 0:
        return -1
    ratio = nl / nr
    best, at = np.inf, -1
    for j in range(q - 1):
        c = a + ((j + 1) * length) // q
        s = max(min(np.float64(c), regions[0, ax + 2]) - max(np.float64(a), regions[0, ax]), 0.0) * w[0]
        for r in range(1, k):
            s += max(min(np.float64(c), regions[r, ax + 2]) - max(np.float64(a), regions[r, ax]), 0.0) * w[r]
        d = abs(s / (total - s) - ratio)
        if not (c - a >= need_lo and b - c >= need_hi) or s <= 0 or total - s <= 0:
            d = np.inf
        if d < best:  # a NaN never is: a time that is not finite makes every candidate's NaN (the reference: target)
            best, at = d, c
    return at


def _time_cuts(nodes, W, H, strips, regions, times, prev, damping):
    """(K-1,) every internal node's clamped cut, breadth first (``tree_arrays``' ``nodes``), from
    the last frame's ``regions`` (K, 4) float64 and ``times`` (K,); ``prev`` (K-1,) the last
    cuts (empty: no damping)."""
    k, m = regions.shape[0], nodes.shape[0]
    density = np.empty(k)
    for r in range(k):
        density[r] = times[r] / max((regions[r, 2] - regions[r, 0]) * (regions[r, 3] - regions[r, 1]), 1.0)
    slots = np.zeros((2 * m + 1, 4), dtype=np.int64)  # regions by slot, the root's first
    slots[0, 2], slots[0, 3] = W, H
    out = np.zeros(m, dtype=np.int64)
    w, x = np.empty(k), np.empty(k)
    for n in range(m):
        ax, nl, nr, need_lo, need_hi, me, lo, hi = (nodes[n, 0], nodes[n, 1], nodes[n, 2], nodes[n, 3], nodes[n, 4],
                                                    nodes[n, 5], nodes[n, 6], nodes[n, 7])
        reg = slots[me]
        a, b = reg[ax], reg[ax + 2]
        length = b - a
        q = min(strips, length)
        target = a + (length * nl) // (nl + nr)
        cut = _choose(regions, density, ax, reg, a, b, q, nl, nr, need_lo, need_hi, w, x)
        if cut < 0:
            cut = target
        elif prev.shape[0]:  # damped: only a fraction of the way from the last cut
            old = prev[n]
            cut = int(round(old + damping * (cut - old)))
        cut = min(max(cut, a + need_lo), b - need_hi)
        out[n] = cut
        for c in range(4):
            slots[lo, c], slots[hi, c] = reg[c], reg[c]
        slots[lo, ax + 2], slots[hi, ax] = cut, cut
    return out


compile_all(globals(), ("_choose", "_time_cuts"))
