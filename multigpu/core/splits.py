"""Split choosers: how a cut is chosen at one node of the GPU tree, in one place.

``balance.tree_partition`` walks the tree (regions, T' masks, loads) and asks a chooser
``choose(task, spans) -> cut pixel`` at every internal node; strategies differ only in the
chooser they pass. Here: the paper's strip chooser (Alg. 2: Start/End arrays over the strips,
prefix and postfix sums, the candidate whose ratio best matches balRatio), its fill-cost
extension (``fill_prefix``), and Equalizer's time chooser (cuts follow measured times; compiled
in ``splits_kernel.py``, whose cuts the walk then takes). Pure numpy, no Python loop over
objects or strips.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multigpu.core.splits_kernel import _time_cuts

_EXACT_FLOAT = 2**53


@dataclass(frozen=True)
class SplitTask:
    """What a split chooser sees at one internal tree node.

    ``idx`` are the objects visible in the node's region ``reg``; ``lo_px``/``hi_px`` their
    inclusive pixel spans along ``axis``; the split cuts ``[a, b)`` with ``nl`` ranks on the
    low side and ``nr`` on the high side, their shares of the work in ``ratio``; ``valid``
    marks which of the candidate ``cuts`` leave every descendant tile at least one pixel;
    ``target`` is the area-proportional cut.
    """

    n: int
    node: object
    reg: np.ndarray
    axis: int
    a: int
    b: int
    q: int
    nl: int
    nr: int
    idx: np.ndarray
    lo_px: np.ndarray
    hi_px: np.ndarray
    cuts: np.ndarray
    valid: np.ndarray
    target: int
    extent: int  # display pixels along ``axis``
    weights: np.ndarray  # validated per-object weights (all objects; index with ``idx``)
    ratio: float  # balRatio: the low side's share over the high side's (``nl / nr`` for equal ranks)


def strip_sums(first: np.ndarray, last: np.ndarray, w: np.ndarray, q: int) -> tuple[np.ndarray, np.ndarray]:
    """Start and End arrays (weights added at each object's first / last strip), exact for ints."""
    if w.dtype.kind == "f":
        return np.bincount(first, w, q), np.bincount(last, w, q)
    total = int(w.sum())
    if total < _EXACT_FLOAT:  # every partial sum is an integer below 2**53: float64 is exact
        s = np.bincount(first, w, q)
        e = np.bincount(last, w, q)
        return s.astype(np.int64), e.astype(np.int64)
    # split each weight into 26-bit halves so that every float64 partial sum stays exact
    lo, hi = w & ((1 << 26) - 1), w >> 26
    out = []
    for idx in (first, last):
        h = np.bincount(idx, hi, q).astype(np.int64)
        l_ = np.bincount(idx, lo, q).astype(np.int64)
        out.append((h << 26) + l_)
    return out[0], out[1]


_TABLE_MAX = 1 << 16  # displays up to this many pixels per axis use a lookup table


def _strip_index(px: np.ndarray, a: int, length: int, q: int, extent: int) -> np.ndarray:
    """Strip of each absolute pixel ``px`` for a split of ``[a, a + length)`` into ``q`` strips.

    Offset ``o = px - a`` lies in strip ``((o + 1) * q - 1) // length``, so strip ``i`` holds
    ``[i*L//q, (i+1)*L//q)``; pixels outside the region clamp to the first / last strip. A
    table over the display axis is one gather per object; beyond ``_TABLE_MAX`` pixels the
    same formula is evaluated per object instead, so memory stays O(N) on huge walls.
    """
    if extent <= _TABLE_MAX:
        table = (np.arange(1 - a, extent + 1 - a, dtype=np.int64) * q - 1) // length
        return np.minimum(np.maximum(table, 0, out=table), q - 1, out=table).astype(np.intp).take(px)
    o = px.astype(np.int64) - (a - 1)
    o *= q
    o -= 1
    o //= length
    return np.minimum(np.maximum(o, 0, out=o), q - 1, out=o)


def choose_split(s: np.ndarray, e: np.ndarray, ratio: float, cuts: np.ndarray, valid: np.ndarray, target: int,
                 fill: tuple[np.ndarray, float] | None = None) -> int:
    """Alg. 2 lines 8-22: index into ``cuts`` of the chosen strip boundary.

    ``s``/``e`` are the Start/End arrays (length Q), ``cuts`` the Q-1 candidate pixel positions
    (boundary i sits between strips i-1 and i), ``valid`` which candidates leave each child
    enough pixels, ``target`` the area-proportional pixel. ``fill`` = (fill below each cut,
    fill of the whole region) adds the cost model's fragment term to each side. Ties, and the
    case where every Diff is infinite, go to the valid candidate nearest the target (then the
    lower one).
    """
    S = np.cumsum(s)
    E = np.cumsum(e[::-1])[::-1]
    left, right = S[:-1], E[1:]
    if fill is not None:
        below, total = fill
        left = left + below
        right = right + (total - below)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # inf: as far from balRatio as can be
        diff = np.abs(left / right - ratio)
    diff[(left <= 0) | (right <= 0) | ~valid] = np.inf
    best = diff.min()
    cand = np.flatnonzero(diff == best) if np.isfinite(best) else np.flatnonzero(valid)
    if cand.size == 0:
        return -1
    dist = np.abs(cuts[cand] - target)
    return int(cand[np.argmin(dist)])


def fill_prefix(task: SplitTask, spans: np.ndarray, density: np.ndarray) -> tuple[np.ndarray, float]:
    """Fill cost below every candidate cut, and in the whole node region.

    ``F[j] = sum_i density_i * (pixels of object i's rect inside the node region and below
    cuts[j] along the split axis)``. Each object's fill is spread evenly over its pixel
    columns (rows), so a straddling object's fill is divided between the two sides, unlike
    its triangles, which both sides process. Exact at pixel resolution up to ``_TABLE_MAX``
    pixels per axis, in equal blocks beyond.
    """
    a, b, axis, reg, idx = task.a, task.b, task.axis, task.reg, task.idx
    other = 1 - axis
    o0 = np.maximum(spans[other].take(idx), reg[other])
    o1 = np.minimum(spans[other + 2].take(idx), reg[other + 2] - 1)
    extent = np.maximum(o1 - o0 + 1, 0).astype(np.float64)  # pixels across the split axis
    lo = np.maximum(task.lo_px, a) - a
    hi = np.minimum(task.hi_px, b - 1) - a  # inclusive, offsets into [0, L)
    L = b - a
    block = max(1, -(-L // _TABLE_MAX))  # pixels per cell of the cost line
    cells = -(-L // block)
    lo_c, hi_c = lo // block, hi // block
    per_cell = density.take(idx) * extent * ((hi - lo + 1) / (hi_c - lo_c + 1))  # fill per covered cell
    diff = np.bincount(lo_c, per_cell, cells + 1) - np.bincount(hi_c + 1, per_cell, cells + 1)
    line = np.zeros(cells + 1)
    np.cumsum(np.cumsum(diff)[:cells], out=line[1:])  # fill in cells < c
    return line[np.minimum((task.cuts - a) // block, cells)], float(line[-1])


def strip_chooser(density: np.ndarray | None = None):
    """Alg. 2 as a split chooser: Start/End arrays over the strips, prefix/postfix sums, the
    candidate whose cost ratio best matches balRatio. With ``density`` (the cost model) each
    side's cost also counts the fill it renders (``fill_prefix``)."""

    def choose(t: SplitTask, spans: np.ndarray) -> int:
        length = t.b - t.a
        first = _strip_index(t.lo_px, t.a, length, t.q, t.extent)
        last = _strip_index(t.hi_px, t.a, length, t.q, t.extent)
        s, e = strip_sums(first, last, t.weights[t.idx], t.q)
        fill = None if density is None else fill_prefix(t, spans, density)
        pick = choose_split(s, e, t.ratio, t.cuts, t.valid, t.target, fill)
        return int(t.cuts[pick]) if pick >= 0 else t.target

    return choose


def time_chooser(regions: np.ndarray, times: np.ndarray, prev_cuts: np.ndarray | None, damping: float):
    """Split chooser from the last frame's measured times: each rank's time is spread evenly
    over its region (Equalizer's assumption); the cut balances the time on either side in
    the ratio of the ranks, then moves only ``damping`` of the way from the previous cut."""
    regions = np.asarray(regions, dtype=np.float64)

    def choose(t: SplitTask, spans: np.ndarray) -> int:
        density = np.asarray(times, dtype=np.float64) / np.maximum(
            (regions[:, 2] - regions[:, 0]) * (regions[:, 3] - regions[:, 1]), 1.0)
        ax, ot = t.axis, 1 - t.axis
        r0, r1 = regions[:, ax], regions[:, ax + 2]
        o = np.clip(np.minimum(regions[:, ot + 2], t.reg[ot + 2]) - np.maximum(regions[:, ot], t.reg[ot]), 0, None)
        w = density * o  # time per pixel along the axis, per old region
        c = t.cuts.astype(np.float64)[:, None]
        # sums over the ranks in rank order (cumsum; ``@`` leaves the order to BLAS), as the
        # compiled chooser (splits_kernel.py) adds them
        below = np.cumsum(np.clip(np.minimum(c, r1) - np.maximum(t.a, r0), 0, None) * w, axis=1)[:, -1]
        total = float(np.cumsum(np.clip(np.minimum(t.b, r1) - np.maximum(t.a, r0), 0, None) * w)[-1])
        if total <= 0:
            return t.target
        with np.errstate(divide="ignore", invalid="ignore"):
            diff = np.abs(below / (total - below) - t.ratio)
        diff[~t.valid | (below <= 0) | (total - below <= 0)] = np.inf
        if not np.isfinite(diff.min()):
            return t.target
        cut = int(t.cuts[int(np.argmin(diff))])
        if prev_cuts is not None:
            old = int(prev_cuts[t.n])
            cut = int(round(old + damping * (cut - old)))
        return cut

    def cuts(nodes: np.ndarray, size, strips: int) -> np.ndarray:
        """Every node's clamped cut in one compiled call (``tree_arrays``' ``nodes``)."""
        prev = _NO_CUTS if prev_cuts is None else np.ascontiguousarray(prev_cuts, dtype=np.int64)
        return _time_cuts(nodes, int(size[0]), int(size[1]), int(strips), np.ascontiguousarray(regions),
                          np.ascontiguousarray(times, dtype=np.float64), prev, float(damping))

    choose.object_free = True  # the cuts follow times and regions alone: the compiled walk takes them
    choose.cuts = cuts  # ... found by the compiled chooser (``balance.tree_partition``, where numba is)
    return choose


_NO_CUTS = np.zeros(0, dtype=np.int64)
