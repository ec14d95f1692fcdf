"""The paper's balancer compiled: pixel spans, the GPU-tree walk with the strip chooser (Start/End
arrays, prefix and postfix sums, the split closest to balRatio), T' masks and loads in ONE numba
call per frame, where the numpy reference (``balance.partition``) makes hundreds of C-level calls.

Same rules, same order of every sum as the reference (sequential, as ``np.bincount`` and
``np.cumsum`` add), so partitions, masks, loads and splits are identical, which the tests check
on random and extreme inputs. Compiled once per machine (``cache=True``: numba keeps the machine
code beside this file) and loaded afterwards; ``warm()`` compiles at setup, never in a frame.
Without numba the reference runs (``available()`` says which).
"""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all
from multigpu.core.regions import INVERTED, MAX_TOTAL, NEGATIVE, NOT_FINITE, TOO_MANY

#: displays up to this many pixels along an axis look strips up in a table (as splits.py does)
TABLE_MAX = 1 << 16


def tree_arrays(tree) -> tuple[np.ndarray, np.ndarray]:
    """The GPU tree as arrays. One row per internal node in breadth-first order: split axis,
    ranks low and high, pixels each child needs along the axis, the node's slot and its
    children's slots (slot 0 is the root); then each leaf's slot by rank label."""
    slot = {tree.root.id: 0}
    for node in tree.internal:
        slot[node.low.id], slot[node.high.id] = len(slot), len(slot) + 1
    rows = []
    for node in tree.internal:
        axis = 0 if node.method == "vertical" else 1
        need = (node.low.ncols, node.high.ncols) if axis == 0 else (node.low.nrows, node.high.nrows)
        rows.append((axis, node.low.count, node.high.count, *need, slot[node.id], slot[node.low.id],
                     slot[node.high.id]))
    nodes = np.array(rows, dtype=np.int64).reshape(-1, 8)
    leaves = np.array([slot[leaf.id] for leaf in tree.leaves], dtype=np.int64)
    return nodes, leaves


def _spans(rt, W, H, tris, axis, table, s, e):
    """``regions.pixel_spans`` of coordinate-major rects ``rt`` (4, N): inclusive pixel spans
    (4, N), which rects are on screen, the on-screen objects in order, and what
    ``balance.validate_inputs`` checks per object, made in this pass instead of numpy ones:
    whether any row is inverted (xmin > xmax or ymin > ymax), any weight is not finite or
    negative, and the weights' total (uint64, wrapping as numpy's sum does); an empty ``tris``
    (no weights: cross-segment masks) skips the weight checks and needs an empty ``table``. Where ``table`` is
    not empty, the same pass also adds each on-screen object's ``tris`` to the Start/End
    arrays ``s``/``e`` at the strips ``table`` gives its first and last pixel along ``axis``
    (the root node's, in the walk's order: the same sums), so the root's objects are not read
    a second time."""
    n = rt.shape[1]
    spans = np.zeros((4, n), dtype=np.int32)
    on = np.zeros(n, dtype=np.bool_)
    members = np.empty(n, dtype=np.int64)
    count = 0
    inverted = False
    not_finite = negative = False
    total = np.uint64(0)
    fused = table.shape[0] > 0
    weighed = tris.shape[0] > 0
    for i in range(n):
        if weighed:
            w = tris[i]
            if w != w or w == np.inf or w == -np.inf:  # float weights only
                not_finite = True
            elif w < 0:
                negative = True
            if w >= 0 and w < 1.8e19:  # every int64 weight; the total is read for integer weights only
                total += np.uint64(w)
        if rt[0, i] > rt[2, i] or rt[1, i] > rt[3, i]:  # False for NaN rows
            inverted = True
        if rt[2, i] >= 0.0 and rt[0, i] <= 1.0 and rt[3, i] >= 0.0 and rt[1, i] <= 1.0:  # False for NaN rows
            on[i] = True
            members[count] = i
            count += 1
            for c in range(4):
                size = W if c % 2 == 0 else H
                v = min(max(rt[c, i] * size, 0.0), size - 1.0)
                spans[c, i] = np.int32(v)  # truncation is floor: v >= 0
            if fused:
                s[table[spans[axis, i]]] += tris[i]
                e[table[spans[axis + 2, i]]] += tris[i]
    return spans, on, (inverted, not_finite, negative, total), members[:count]


def _strip_table(extent, a, length, q):
    """The strip of every display pixel along an axis, for a node over ``[a, a + length)``
    cut into ``q`` strips (pixels outside clamp to the end strips)."""
    table = np.empty(extent, dtype=np.int64)
    for px in range(extent):
        table[px] = min(max(((px - a + 1) * q - 1) // length, 0), q - 1)
    return table


def _fill_line(idx, spans, density, reg, axis, a, b, cuts_of):
    """``splits.fill_prefix`` at one node: the fill cost below every candidate cut (``cuts_of``
    gives them: cut i at ``a + ((i + 1) * (b - a)) // q``, as a (q - 1,) array) and in the whole
    region. Each object's fill (density x its pixels across the axis) spread evenly over the
    cells it covers along the axis; the cells' differences summed in the objects' order, then
    two running sums: the reference's ``bincount`` and ``cumsum`` values."""
    other = 1 - axis
    L = b - a
    block = max(1, -(-L // TABLE_MAX))
    cells = -(-L // block)
    up = np.zeros(cells + 1)
    down = np.zeros(cells + 1)
    for t in range(idx.shape[0]):
        o = idx[t]
        o0 = max(spans[other, o], reg[other])
        o1 = min(spans[other + 2, o], reg[other + 2] - 1)
        extent = np.float64(max(o1 - o0 + 1, 0))
        lo = max(spans[axis, o], a) - a
        hi = min(spans[axis + 2, o], b - 1) - a
        lo_c, hi_c = lo // block, hi // block
        per_cell = density[o] * extent * ((hi - lo + 1) / (hi_c - lo_c + 1))
        up[lo_c] += per_cell
        down[hi_c + 1] += per_cell
    line = np.zeros(cells + 1)
    run = 0.0
    acc = 0.0
    for c in range(cells):
        run += up[c] - down[c]  # the reference's cumsum of (bincount - bincount), up to cell c
        acc = run if c == 0 else acc + run
        line[c + 1] = acc
    below = np.empty(cuts_of.shape[0])
    for i in range(cuts_of.shape[0]):
        below[i] = line[min((cuts_of[i] - a) // block, cells)]
    return below, line[cells]


def _choose(s, e, below, total, ratio, a, length, q, need_lo, need_hi, target):
    """``splits.choose_split`` on Start/End arrays ``s``/``e`` (turned into prefix/postfix sums
    in place): the valid cut with the least Diff, ties and the all-infinite case nearest
    ``target`` (then the lower cut); ``target`` itself when no cut is valid. A non-empty
    ``below`` (``_fill_line``, with the region's ``total``) adds the cost model's fill to each
    side. Each side's cost is a float either way, as the reference's ratio of two int64 sums."""
    fill = below.shape[0] > 0
    for i in range(1, q):
        s[i] += s[i - 1]
    for i in range(q - 2, -1, -1):
        e[i] += e[i + 1]
    best = np.inf
    per_pixel = q == length  # a strip per pixel: cut i is a + i + 1 (no division)
    diffs = np.empty(q - 1)  # each cut's Diff (inf: not a candidate), read again by the second pass
    for i in range(q - 1):
        cut = a + i + 1 if per_pixel else a + ((i + 1) * length) // q
        left = s[i] + below[i] if fill else s[i] + 0.0
        right = e[i + 1] + (total - below[i]) if fill else e[i + 1] + 0.0
        d = np.inf
        if cut - a >= need_lo and a + length - cut >= need_hi and left > 0 and right > 0:
            d = abs(left / right - ratio)
            best = min(best, d)
        diffs[i] = d
    pick, pick_dist = -1, 0
    for i in range(q - 1):
        cut = a + i + 1 if per_pixel else a + ((i + 1) * length) // q
        if cut - a < need_lo or a + length - cut < need_hi:
            continue
        if best < np.inf and not diffs[i] == best:
            continue
        dist = abs(cut - target)
        if pick < 0 or dist < pick_dist:
            pick, pick_dist = cut, dist
    return pick if pick >= 0 else target


def _split(idx, spans, axis, cut):
    """The objects of ``idx`` that touch the low side of ``cut``, and those touching the high
    side, in order (branch-free: every object is written to both and kept where it belongs)."""
    lo = np.empty(idx.shape[0], dtype=np.int64)
    hi = np.empty(idx.shape[0], dtype=np.int64)
    first, last = spans[axis], spans[axis + 2]
    p = r = 0
    for t in range(idx.shape[0]):
        o = idx[t]
        lo[p] = o
        hi[r] = o
        p += first[o] < cut
        r += last[o] >= cut
    return lo[:p], hi[:r]


def _starts_ends(idx, spans, tris, axis, a, length, q, extent):
    """A node's Start/End arrays: the ``tris`` of each object of ``idx`` added at the strip of its
    first and of its last pixel along ``axis``, the node's ``[a, a + length)`` cut into ``q``
    strips (pixels outside clamp to the end strips)."""
    s = np.zeros(q, dtype=tris.dtype)
    e = np.zeros(q, dtype=tris.dtype)
    if q == length:  # a strip per pixel (strips >= the region's pixels, the usual): no table
        top = q - 1
        for t in range(idx.shape[0]):
            o = idx[t]
            s[min(max(spans[axis, o] - a, 0), top)] += tris[o]
            e[min(max(spans[axis + 2, o] - a, 0), top)] += tris[o]
    elif extent <= TABLE_MAX:  # the strip of every display pixel, once: no division per object
        table = _strip_table(extent, a, length, q)
        for t in range(idx.shape[0]):
            o = idx[t]
            s[table[spans[axis, o]]] += tris[o]
            e[table[spans[axis + 2, o]]] += tris[o]
    else:
        for t in range(idx.shape[0]):
            o = idx[t]
            f = ((spans[axis, o] - a + 1) * q - 1) // length
            g = ((spans[axis + 2, o] - a + 1) * q - 1) // length
            s[min(max(f, 0), q - 1)] += tris[o]
            e[min(max(g, 0), q - 1)] += tris[o]
    return s, e


def _walk(rt, tris, W, H, strips, nodes, leaves, fixed, density, ratios):
    """``balance.tree_partition`` with the strip chooser, in one call (``rt``: (4, N) rects);
    a node whose ``fixed`` cut is >= 0 takes that cut instead (choosers that need no objects:
    time feedback, the static tiles). A non-empty ``density`` (N,) adds the cost model's fill
    term to every chosen cut (``splits.strip_chooser(density)``); ``ratios`` (K-1,) every node's
    balRatio."""
    n = rt.shape[1]
    K = leaves.shape[0]
    # the root's Start/End arrays are filled in the spans' own pass (its region is the display)
    root_axis = nodes[0, 0] if nodes.shape[0] > 0 else 0
    root_len = W if root_axis == 0 else H
    root_q = min(strips, root_len)
    fuse = nodes.shape[0] > 0 and fixed[0] < 0 and root_len <= TABLE_MAX
    table0 = _strip_table(root_len, 0, root_len, root_q) if fuse else np.empty(0, dtype=np.int64)
    s0 = np.zeros(root_q if fuse else 0, dtype=tris.dtype)
    e0 = np.zeros(root_q if fuse else 0, dtype=tris.dtype)
    spans, on, checks, first_members = _spans(rt, W, H, tris, root_axis, table0, s0, e0)
    regs = np.zeros((2 * K - 1, 4), dtype=np.int64)
    regs[0, 2], regs[0, 3] = W, H
    members = [first_members]
    for _ in range(2 * K - 2):
        members.append(members[0][:0])
    splits = np.zeros(K - 1, dtype=np.float64)
    split_pixels = np.zeros(K - 1, dtype=np.int64)
    for m in range(nodes.shape[0]):
        axis, nl, nr, need_lo, need_hi = nodes[m, 0], nodes[m, 1], nodes[m, 2], nodes[m, 3], nodes[m, 4]
        me, low, high = nodes[m, 5], nodes[m, 6], nodes[m, 7]
        idx = members[me]
        a, b = regs[me, axis], regs[me, axis + 2]
        length = b - a
        if fixed[m] >= 0:
            cut = fixed[m]
        else:
            q = min(strips, length)
            if m == 0 and fuse:  # filled with the spans
                s, e = s0, e0
            else:
                s, e = _starts_ends(idx, spans, tris, axis, a, length, q, W if axis == 0 else H)
            target = a + (length * nl) // (nl + nr)
            below, total = density[:0], 0.0  # no fill term
            if density.shape[0] > 0:
                below, total = _fill_line(idx, spans, density, regs[me], axis, a, b,
                                          a + (np.arange(1, q) * length) // q)
            cut = _choose(s, e, below, total, ratios[m], a, length, q, need_lo, need_hi, target)
        cut = min(max(cut, a + need_lo), b - need_hi)
        splits[m] = (cut - a) / length
        split_pixels[m] = cut
        regs[low] = regs[me]
        regs[high] = regs[me]
        regs[low, axis + 2] = cut
        regs[high, axis] = cut
        members[low], members[high] = _split(idx, spans, axis, cut)
    regions = np.zeros((K, 4), dtype=np.int64)
    visible = np.zeros((K, n), dtype=np.bool_)
    loads = np.zeros(K, dtype=tris.dtype)
    for label in range(K):
        regions[label] = regs[leaves[label]]
        idx = members[leaves[label]]
        total = loads[label]
        for t in range(idx.shape[0]):
            visible[label, idx[t]] = True
            total += tris[idx[t]]
        loads[label] = total
    return regions, loads, visible, splits, split_pixels, spans, checks


compile_all(globals(), ("_spans", "_strip_table", "_starts_ends", "_fill_line", "_choose", "_split", "_walk"))


def strip_partition(rects: np.ndarray, tris: np.ndarray, tree, size, strips: int, cuts: np.ndarray | None = None,
                    density: np.ndarray | None = None, ratios: np.ndarray | None = None):
    """The compiled walk on validated inputs (``balance.validate_inputs``; the per-object
    checks are made here, in the walk's own pass over the objects): regions, loads,
    T' masks, splits in p-pos and pixels, spans (4, N). ``cuts`` (K-1,) fixes every node's cut
    (-1: the strip chooser's); ``density`` (N,) float64, validated: the cost model's fill per
    covered pixel of each object; ``ratios`` (K-1,) float64 each node's balRatio (None: its ranks
    ``nl / nr``). Integer loads are exact sums; float loads are summed again by numpy as the
    reference sums them (pairwise)."""
    nodes, leaves, free = _tree(tree)
    if cuts is None:
        cuts = free
    if ratios is None:
        ratios = nodes[:, 1] / nodes[:, 2]
    rt = np.ascontiguousarray(rects.T, dtype=np.float64)  # the projectors' own layout: no copy
    regions, loads, visible, splits, split_pixels, spans, (inverted, not_finite, negative, total) = _walk(
        rt, tris, int(size[0]), int(size[1]), int(strips), nodes, leaves, cuts,
        _NO_FILL if density is None else density, np.ascontiguousarray(ratios, dtype=np.float64))
    if not_finite or negative or inverted or (tris.dtype.kind == "i" and int(total) >= MAX_TOTAL):
        if not_finite:  # the reference's order: weights, their total, then the rects
            raise ValueError(NOT_FINITE)
        if negative:
            raise ValueError(NEGATIVE)
        if tris.dtype.kind == "i" and int(total) >= MAX_TOTAL:
            raise ValueError(TOO_MANY)
        raise ValueError(INVERTED)
    if tris.dtype.kind == "f":
        loads = np.array([tris[v].sum() for v in visible], dtype=tris.dtype)  # K ranks, not objects
    return regions, loads, visible, splits, split_pixels, spans


_TREES: dict = {}


def _tree(tree) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``tree_arrays`` of ``tree`` and the chooser's cuts (-1) for every node, made once per wall
    shape (the kernels only read them)."""
    shape = (tree.rows, tree.cols)
    if shape not in _TREES:
        nodes, leaves = tree_arrays(tree)
        _TREES[shape] = (nodes, leaves, np.full(len(nodes), -1, dtype=np.int64))
    return _TREES[shape]


def tree_nodes(tree) -> np.ndarray:
    """The internal nodes' rows of ``tree_arrays`` (breadth first), made once per wall shape."""
    return _tree(tree)[0]


_NO_FILL = np.empty(0)
