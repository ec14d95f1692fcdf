"""The GPU-tree strip load balancer (Dong & Peng 2019, Alg. 1 and 2) in pure numpy.

``partition`` walks the GPU tree breadth first. At each split of a node's region ``[a, b)``
along one axis it lays ``Q = min(strips, b - a)`` strips of (near) equal width over the region,
adds every visible object's weight to the Start array at its first strip and to the End array
at its last strip, takes the prefix sum of Start and the postfix sum of End, and picks the strip
boundary ``i`` minimising ``Diff_i = |S[i-1] / E[i] - balRatio|``. Objects straddling the line
stay visible on both sides. No Python loop runs over objects or strips; the only loop is over
the K - 1 tree nodes.

Integer weights (triangle counts) are summed exactly in int64 up to a total of 2**62.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .regions import MAX_PIXELS, overlaps, pixel_spans, tile_regions
from .tree import VERTICAL, GpuTree

MAX_TOTAL = 2**62
_EXACT_FLOAT = 2**53


@dataclass(frozen=True)
class Partition:
    """The result of one frame's balancing.

    regions : (K, 4) int64  ``[x0, y0, x1, y1)`` render region per rank label; they tile the
        display exactly.
    loads : (K,) weight (triangles) each rank renders: objects whose rect overlaps its region.
    visible : (K, N) bool  the T' mask of each rank.
    splits : (K-1,) float  p-pos of each internal tree node, breadth-first order (the paper's
        normalized split position within the node's region).
    split_pixels : (K-1,) int64  the same splits as absolute pixel coordinates.
    """

    regions: np.ndarray
    loads: np.ndarray
    visible: np.ndarray
    splits: np.ndarray
    split_pixels: np.ndarray

    @property
    def imbalance(self) -> float:
        """max/mean of the loads (1.0 is perfect; 1.0 also when nothing is visible)."""
        mean = float(np.mean(self.loads))
        return float(np.max(self.loads)) / mean if mean > 0 else 1.0


def validate_inputs(rects, tris, grid, size, strips) -> tuple[np.ndarray, np.ndarray, GpuTree, tuple[int, int]]:
    """Check the public arguments once; return them as arrays plus the GPU tree."""
    if not (isinstance(grid, (tuple, list)) and len(grid) == 2):
        raise ValueError(f"grid must be (rows, cols), got {grid!r}")
    rows, cols = (int(g) for g in grid)
    if rows < 1 or cols < 1:
        raise ValueError(f"grid must have at least 1 row and 1 column, got {rows}x{cols}")
    if not (isinstance(size, (tuple, list)) and len(size) == 2):
        raise ValueError(f"size must be (W, H), got {size!r}")
    W, H = (int(s) for s in size)
    if W > MAX_PIXELS or H > MAX_PIXELS:
        raise ValueError(f"display {W}x{H} exceeds {MAX_PIXELS} pixels along an axis")
    if W < cols or H < rows:
        raise ValueError(f"display {W}x{H} is smaller than one pixel per rank for a {rows}x{cols} grid")
    if int(strips) != strips or strips < 2:
        raise ValueError(f"strips must be an integer >= 2, got {strips!r}")
    rects = np.asarray(rects, dtype=np.float64)
    if rects.ndim != 2 or rects.shape[1] != 4:
        raise ValueError(f"rects must have shape (N, 4), got {rects.shape}")
    tris = np.asarray(tris)
    if tris.ndim != 1 or tris.shape[0] != rects.shape[0]:
        raise ValueError(f"tris must have shape ({rects.shape[0]},) to match rects, got {tris.shape}")
    if tris.dtype.kind in "iub":
        tris = tris.astype(np.int64, copy=False)
    elif tris.dtype.kind == "f":
        if not np.isfinite(tris).all():
            raise ValueError("tris (weights) must be finite")
        tris = tris.astype(np.float64, copy=False)
    else:
        raise ValueError(f"tris must be integers (triangle counts) or floats, got dtype {tris.dtype}")
    if tris.size and tris.min() < 0:
        raise ValueError("tris must be non-negative (a negative triangle count was given)")
    if tris.dtype.kind == "i" and tris.size and int(tris.sum(dtype=np.uint64)) >= MAX_TOTAL:
        raise ValueError(f"the triangle total exceeds 2**62 (sums could overflow int64)")
    with np.errstate(invalid="ignore"):
        if np.any(rects[:, 0] > rects[:, 2]) or np.any(rects[:, 1] > rects[:, 3]):
            raise ValueError("rects has inverted rows (xmin > xmax or ymin > ymax)")
    return rects, tris, GpuTree(rows, cols), (W, H)


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
        return np.clip(table, 0, q - 1).astype(np.intp).take(px)
    o = px.astype(np.int64) - (a - 1)
    o *= q
    o -= 1
    o //= length
    return np.clip(o, 0, q - 1, out=o)


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
    with np.errstate(divide="ignore", invalid="ignore"):
        diff = np.abs(left / right - ratio)
    diff[(left <= 0) | (right <= 0) | ~valid] = np.inf
    best = diff.min()
    cand = np.flatnonzero(diff == best) if np.isfinite(best) else np.flatnonzero(valid)
    if cand.size == 0:
        return -1
    dist = np.abs(cuts[cand] - target)
    return int(cand[np.argmin(dist)])


@dataclass(frozen=True)
class SplitTask:
    """What a split chooser sees at one internal tree node.

    ``idx`` are the objects visible in the node's region ``reg``; ``lo_px``/``hi_px`` their
    inclusive pixel spans along ``axis``; the split cuts ``[a, b)`` with ``nl`` ranks on the
    low side and ``nr`` on the high side; ``valid`` marks which of the candidate ``cuts``
    leave every descendant tile at least one pixel; ``target`` is the area-proportional cut.
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


def tree_partition(rects, tris, grid, size, strips: int, choose) -> Partition:
    """Walk the GPU tree, asking ``choose(task, spans) -> cut pixel`` at every internal node.

    The walk (regions, T' masks, loads, split bookkeeping) is shared by every screen-space
    strategy; only the choice of the cut differs. ``spans`` is the (4, N) int32 pixel-span
    array. The returned cut is clamped to the valid range.
    """
    rects, tris, tree, (W, H) = validate_inputs(rects, tris, grid, size, strips)
    strips = int(strips)
    spans, onscreen = pixel_spans(rects, (W, H))
    spans = np.ascontiguousarray(spans.T)  # (4, N), a no-op: pixel_spans is coordinate-major
    K = tree.size
    regions = np.zeros((K, 4), dtype=np.int64)
    splits = np.zeros(K - 1, dtype=np.float64)
    split_pixels = np.zeros(K - 1, dtype=np.int64)
    node_region = {tree.root.id: np.array([0, 0, W, H], dtype=np.int64)}
    node_idx = {tree.root.id: np.flatnonzero(onscreen)}

    for n, node in enumerate(tree.internal):
        reg = node_region.pop(node.id)
        idx = node_idx.pop(node.id)
        axis = 0 if node.method == VERTICAL else 1
        a, b = int(reg[axis]), int(reg[axis + 2])
        length = b - a
        q = min(strips, length)
        # child extents along the axis must leave every descendant tile at least one pixel
        if axis == 0:
            need_lo, need_hi = node.low.ncols, node.high.ncols
        else:
            need_lo, need_hi = node.low.nrows, node.high.nrows
        nl, nr = node.low.count, node.high.count
        cuts = a + (np.arange(1, q, dtype=np.int64) * length) // q
        valid = (cuts - a >= need_lo) & (b - cuts >= need_hi)
        target = a + (length * nl) // (nl + nr)
        lo_px = spans[axis].take(idx)
        hi_px = spans[axis + 2].take(idx)
        task = SplitTask(n, node, reg, axis, a, b, q, nl, nr, idx, lo_px, hi_px, cuts, valid, target,
                         W if axis == 0 else H, tris)
        cut = int(np.clip(int(choose(task, spans)), a + need_lo, b - need_hi))
        splits[n] = (cut - a) / length
        split_pixels[n] = cut

        low_reg, high_reg = reg.copy(), reg.copy()
        low_reg[axis + 2] = cut
        high_reg[axis] = cut
        node_region[node.low.id], node_region[node.high.id] = low_reg, high_reg
        node_idx[node.low.id] = idx[lo_px < cut]
        node_idx[node.high.id] = idx[hi_px >= cut]

    visible = np.zeros((K, rects.shape[0]), dtype=bool)
    loads = np.zeros(K, dtype=tris.dtype)
    for leaf in tree.leaves:
        idx = node_idx[leaf.id]
        regions[leaf.label] = node_region[leaf.id]
        visible[leaf.label, idx] = True
        loads[leaf.label] = tris[idx].sum()
    return Partition(regions, loads, visible, splits, split_pixels)


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
        pick = choose_split(s, e, t.nl / t.nr, t.cuts, t.valid, t.target, fill)
        return int(t.cuts[pick]) if pick >= 0 else t.target

    return choose


def partition(rects, tris, grid, size, strips: int = 2048, fill=None) -> Partition:
    """Balance ``tris`` over a ``rows x cols`` wall by splitting the screen along the GPU tree.

    Parameters
    ----------
    rects : (N, 4) float  normalized ``[xmin, ymin, xmax, ymax]`` (may reach outside [0, 1];
        NaN rows are invisible).
    tris : (N,) non-negative int  triangles per object (or non-negative float weights).
    grid : (rows, cols)
    size : (W, H) full display in pixels.
    strips : strips per split axis (>= 2); a region narrower than ``strips`` pixels uses one
        strip per pixel.
    fill : optional (N,) non-negative float, or a scalar: cost per covered pixel of each
        object's rect (the cost model's fragment term). None balances ``tris`` alone, exactly
        the paper's Alg. 2.
    """
    rects_a = np.asarray(rects)
    density = None
    if fill is not None:
        density = np.broadcast_to(np.asarray(fill, dtype=np.float64), rects_a.shape[:1])
        if density.size and (not np.isfinite(density).all() or density.min() < 0):
            raise ValueError("fill must be finite and non-negative")
        density = np.ascontiguousarray(density)
    return tree_partition(rects, tris, grid, size, strips, strip_chooser(density))


def partition_tiles(rects, tris, grid, size) -> Partition:
    """The ``--balance none`` baseline: every rank renders exactly its own display tile.

    Same outputs as ``partition`` (loads, T' masks) so the two compare one to one; ``splits``
    are the tile boundaries in p-pos form.
    """
    rects, tris, tree, (W, H) = validate_inputs(rects, tris, grid, size, 2)
    rows, cols = tree.rows, tree.cols
    if W % cols or H % rows:
        raise ValueError(f"display {W}x{H} does not divide into {rows}x{cols} equal tiles")
    regions = tile_regions(rows, cols, W // cols, H // rows)
    spans, onscreen = pixel_spans(rects, (W, H))
    K = tree.size
    visible = np.zeros((K, rects.shape[0]), dtype=bool)
    loads = np.zeros(K, dtype=tris.dtype)
    on = np.flatnonzero(onscreen)
    for k in range(K):  # K ranks, not objects
        idx = on[overlaps(spans[on], regions[k])]
        visible[k, idx] = True
        loads[k] = tris[idx].sum()
    splits, split_pixels = _tile_splits(tree, W, H)
    return Partition(regions, loads, visible, splits, split_pixels)


def _tile_splits(tree: GpuTree, W: int, H: int) -> tuple[np.ndarray, np.ndarray]:
    tw, th = W // tree.cols, H // tree.rows
    splits = np.zeros(len(tree.internal))
    pixels = np.zeros(len(tree.internal), dtype=np.int64)
    for n, node in enumerate(tree.internal):
        if node.method == VERTICAL:
            a, b, cut = node.c0 * tw, node.c1 * tw, node.high.c0 * tw
        else:  # rows counted from the top; pixel y from the bottom
            a, b = (tree.rows - node.r1) * th, (tree.rows - node.r0) * th
            cut = (tree.rows - node.high.r1) * th
        splits[n], pixels[n] = (cut - a) / (b - a), cut
    return splits, pixels
