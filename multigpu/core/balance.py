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

import functools
from typing import NamedTuple

import numpy as np

from multigpu.core import (  # module-level: a function-level import costs a Python call per frame
    balance_kernel as kernel,
)
from multigpu.core import jit
from multigpu.core.regions import (
    INVERTED,
    MAX_PIXELS,
    MAX_TOTAL,
    NEGATIVE,
    NOT_FINITE,
    TOO_MANY,
    overlaps,
    pixel_spans,
    tile_regions,
)
from multigpu.core.splits import SplitTask, strip_chooser
from multigpu.core.tree import VERTICAL, GpuTree, gpu_tree


class Partition(NamedTuple):
    """The result of one frame's balancing.

    regions : (K, 4) int64  ``[x0, y0, x1, y1)`` render region per rank label; they tile the
        display exactly.
    loads : (K,) weight (triangles) each rank renders: objects whose rect overlaps its region.
    visible : (K, N) bool  the T' mask of each rank.
    splits : (K-1,) float  p-pos of each internal tree node, breadth-first order (the paper's
        normalized split position within the node's region).
    split_pixels : (K-1,) int64  the same splits as absolute pixel coordinates.
    spans : (4, N) int32 or None  every object's inclusive pixel span ``[x0, y0, x1, y1]``,
        computed once per frame by the tree walk and carried here so later stages (the cost
        model's pixel counts, reports) need not recompute it; None where not known.
    pieces, piece_visible : None, or per rank the (M_k, 4) rects it renders and their (M_k, N)
        masks, for strategies that give a rank more than one rect (cross-segment); then
        ``regions`` holds each rank's bounding box and the pieces tile the display.
    features : None, or what the strategy that planned it needs to learn from its measured
        times (the cost model's per-rank triangles, pixels and prediction): a strategy's
        ``observe`` reads the partition it is given, never state a later ``plan`` changed.

    Immutable; a named tuple, not a frozen dataclass: one is made every frame, and a frozen
    dataclass sets each of its nine fields through ``object.__setattr__``.
    """

    regions: np.ndarray
    loads: np.ndarray
    visible: np.ndarray
    splits: np.ndarray
    split_pixels: np.ndarray
    spans: np.ndarray | None = None
    pieces: tuple | None = None
    piece_visible: tuple | None = None
    features: dict | None = None

    @property
    def imbalance(self) -> float:
        """max/mean of the loads (1.0 is perfect; 1.0 also when nothing is visible)."""
        mean = float(np.mean(self.loads))
        return float(np.max(self.loads)) / mean if mean > 0 else 1.0


#: the refusals of per-object inputs, made here or in the compiled walk's own pass


def validate_inputs(rects, tris, grid, size, strips, rows: bool = True
                    ) -> tuple[np.ndarray, np.ndarray, GpuTree, tuple[int, int]]:
    """Check the public arguments once; return them as arrays plus the GPU tree. ``rows``
    False leaves the per-object checks (inverted rows; weights negative or not finite; the
    triangle total) to the compiled walk (``kernel.strip_partition``), which makes them in its
    own pass over the objects, with the same refusals in the same order."""
    if not (isinstance(grid, (tuple, list)) and len(grid) == 2):
        raise ValueError(f"grid must be (rows, cols), got {grid!r}")
    n_rows, cols = int(grid[0]), int(grid[1])
    if n_rows < 1 or cols < 1:
        raise ValueError(f"grid must have at least 1 row and 1 column, got {n_rows}x{cols}")
    if not (isinstance(size, (tuple, list)) and len(size) == 2):
        raise ValueError(f"size must be (W, H), got {size!r}")
    W, H = int(size[0]), int(size[1])
    if W > MAX_PIXELS or H > MAX_PIXELS:
        raise ValueError(f"display {W}x{H} exceeds {MAX_PIXELS} pixels along an axis")
    if W < cols or H < n_rows:
        raise ValueError(f"display {W}x{H} is smaller than one pixel per rank for a {n_rows}x{cols} grid")
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
        if rows and not np.isfinite(tris).all():
            raise ValueError(NOT_FINITE)
        tris = tris.astype(np.float64, copy=False)
    else:
        raise ValueError(f"tris must be integers (triangle counts) or floats, got dtype {tris.dtype}")
    if rows:
        if tris.size and tris.min() < 0:
            raise ValueError(NEGATIVE)
        if tris.dtype.kind == "i" and tris.size and int(tris.sum(dtype=np.uint64)) >= MAX_TOTAL:
            raise ValueError(TOO_MANY)
        rt = rects.T  # coordinate-major rows (projectors return views of (4, N) arrays)
        with np.errstate(invalid="ignore"):
            if (rt[:2] > rt[2:]).any():
                raise ValueError(INVERTED)
    return rects, tris, gpu_tree(n_rows, cols), (W, H)


def _task(n: int, node, reg: np.ndarray, strips: int, W: int, H: int, idx, spans, tris,
          ratio: float | None = None) -> tuple[SplitTask, int, int]:
    """What the chooser sees at internal node ``n`` over region ``reg``, and the pixels each
    child needs along the axis (every descendant tile keeps at least one pixel)."""
    axis = 0 if node.method == VERTICAL else 1
    a, b = int(reg[axis]), int(reg[axis + 2])
    length = b - a
    q = min(strips, length)
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
                     W if axis == 0 else H, tris, nl / nr if ratio is None else float(ratio))
    return task, need_lo, need_hi


def _children(reg: np.ndarray, axis: int, cut: int) -> tuple[np.ndarray, np.ndarray]:
    low, high = reg.copy(), reg.copy()
    low[axis + 2] = cut
    high[axis] = cut
    return low, high


def node_cuts(tree: GpuTree, size, strips: int, choose) -> np.ndarray:
    """(K-1,) the clamped cut of every internal node, breadth first, for a chooser that needs
    no objects (``choose.object_free``: time feedback): the compiled walk then takes them."""
    W, H = size
    none = np.zeros(0, dtype=np.int64)
    spans = np.zeros((4, 0), dtype=np.int32)
    out = np.zeros(len(tree.internal), dtype=np.int64)
    node_region = {tree.root.id: np.array([0, 0, W, H], dtype=np.int64)}
    for n, node in enumerate(tree.internal):  # K - 1 nodes, no objects
        reg = node_region.pop(node.id)
        task, need_lo, need_hi = _task(n, node, reg, int(strips), W, H, none, spans, none)
        out[n] = min(max(int(choose(task, spans)), task.a + need_lo), task.b - need_hi)
        node_region[node.low.id], node_region[node.high.id] = _children(reg, task.axis, int(out[n]))
    return out


def tree_partition(rects, tris, grid, size, strips: int, choose, compiled: bool | None = None,
                   shares=None, ratios=None) -> Partition:
    """Walk the GPU tree, asking ``choose(task, spans) -> cut pixel`` at every internal node.

    The walk (regions, T' masks, loads, split bookkeeping) is shared by every screen-space
    strategy; only the choice of the cut differs. ``spans`` is the (4, N) int32 pixel-span
    array. The returned cut is clamped to the valid range. A chooser that needs no objects
    (``object_free``) has its cuts found first and the compiled walk take them (``compiled``
    as in ``partition``). ``shares``, ``ratios``: as in ``partition``.
    """
    object_free = getattr(choose, "object_free", False) and jit.use(compiled)
    # the compiled walk makes the per-object checks in its own pass
    rects, tris, tree, (W, H) = validate_inputs(rects, tris, grid, size, strips, rows=not object_free)
    strips = int(strips)
    if object_free:
        compiled_cuts = getattr(choose, "cuts", None)  # the chooser's own compiled twin, if it has one
        cuts = (node_cuts(tree, (W, H), strips, choose) if compiled_cuts is None
                else compiled_cuts(kernel.tree_nodes(tree), (W, H), strips))
        return Partition(*kernel.strip_partition(rects, tris, tree, (W, H), strips, cuts))
    spans, onscreen = pixel_spans(rects, (W, H))
    spans = np.ascontiguousarray(spans.T)  # (4, N), a no-op: pixel_spans is coordinate-major
    K = tree.size
    if ratios is None and shares is not None:
        ratios = node_ratios(tree, shares)
    regions = np.zeros((K, 4), dtype=np.int64)
    splits = np.zeros(K - 1, dtype=np.float64)
    split_pixels = np.zeros(K - 1, dtype=np.int64)
    node_region = {tree.root.id: np.array([0, 0, W, H], dtype=np.int64)}
    node_idx = {tree.root.id: np.flatnonzero(onscreen)}

    for n, node in enumerate(tree.internal):
        reg = node_region.pop(node.id)
        idx = node_idx.pop(node.id)
        task, need_lo, need_hi = _task(n, node, reg, strips, W, H, idx, spans, tris,
                                       None if ratios is None else ratios[n])
        a, b, axis = task.a, task.b, task.axis
        cut = min(max(int(choose(task, spans)), a + need_lo), b - need_hi)
        splits[n] = (cut - a) / (b - a)
        split_pixels[n] = cut
        node_region[node.low.id], node_region[node.high.id] = _children(reg, axis, cut)
        node_idx[node.low.id] = idx[task.lo_px < cut]
        node_idx[node.high.id] = idx[task.hi_px >= cut]

    visible = np.zeros((K, rects.shape[0]), dtype=bool)
    loads = np.zeros(K, dtype=tris.dtype)
    for leaf in tree.leaves:
        idx = node_idx[leaf.id]
        regions[leaf.label] = node_region[leaf.id]
        visible[leaf.label, idx] = True
        loads[leaf.label] = tris[idx].sum()
    return Partition(regions, loads, visible, splits, split_pixels, spans)


def partition(rects, tris, grid, size, strips: int = 2048, fill=None, compiled: bool | None = None,
              shares=None, ratios=None) -> Partition:
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
    compiled : Alg. 2 (with or without ``fill``) as one compiled call (``balance_kernel.py``: the
        same partition, bit for bit); None uses it where numba is installed, False runs this
        module's numpy reference.
    shares : optional (K,) positive float: each rank's share of the work by rank label (a
        faster GPU a larger one); a split's balRatio is then its two sides' shares summed, one
        over the other. None: equal ranks, the paper's ``nl / nr``.
    ratios : optional (K-1,) float64, instead of ``shares``: every node's balRatio as
        ``node_ratios`` gives it (a strategy whose shares change once a frame makes them then).
    """
    density = None
    if fill is not None:
        density = np.broadcast_to(np.asarray(fill, dtype=np.float64), np.shape(rects)[:1])
        if density.size and (not np.isfinite(density).all() or density.min() < 0):
            raise ValueError("fill must be finite and non-negative")
        density = np.ascontiguousarray(density)
    if jit.use(compiled):
        rects, tris, tree, size = validate_inputs(rects, tris, grid, size, strips, rows=False)
        if ratios is None and shares is not None:
            ratios = node_ratios(tree, shares)
        return Partition(*kernel.strip_partition(rects, tris, tree, size, int(strips), density=density,
                                                 ratios=ratios))
    return tree_partition(rects, tris, grid, size, strips, strip_chooser(density), compiled, shares, ratios)


def partition_tiles(rects, tris, grid, size, compiled: bool | None = None) -> Partition:
    """The ``--balance none`` baseline: every rank renders exactly its own display tile.

    Same outputs as ``partition`` (loads, T' masks) so the two compare one to one; ``splits``
    are the tile boundaries in p-pos form. Compiled (``compiled`` as in ``partition``): the
    tree walk with the tile boundaries as its cuts, the same partition.
    """
    compiled = jit.use(compiled)  # compiled, the walk makes the per-object checks in its own pass
    rects, tris, tree, (W, H) = validate_inputs(rects, tris, grid, size, 2, rows=not compiled)
    rows, cols = tree.rows, tree.cols
    if W % cols or H % rows:
        raise ValueError(f"display {W}x{H} does not divide into {rows}x{cols} equal tiles")
    if compiled:
        return Partition(*kernel.strip_partition(rects, tris, tree, (W, H), 2, _tile_splits(rows, cols, W, H)[1]))
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
    splits, split_pixels = _tile_splits(rows, cols, W, H)
    return Partition(regions, loads, visible, splits, split_pixels, np.ascontiguousarray(spans.T))


@functools.lru_cache(maxsize=64)
def _tile_splits(rows: int, cols: int, W: int, H: int) -> tuple[np.ndarray, np.ndarray]:
    """The tile boundaries as every node's split (p-pos) and cut pixel: read-only, built once
    per wall (asked for every frame)."""
    tree = gpu_tree(rows, cols)
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
    splits.setflags(write=False)
    pixels.setflags(write=False)
    return splits, pixels


def node_ratios(tree, shares) -> np.ndarray:
    """(K-1,) float64 balRatio of every internal node, breadth first: the shares of the ranks on
    its low side summed, over those on its high side (``shares`` (K,) positive, by rank label)."""
    shares = np.asarray(shares, dtype=np.float64)
    if shares.shape != (tree.size,) or not np.isfinite(shares).all() or shares.min() <= 0:
        raise ValueError(f"shares must be {tree.size} positive finite numbers, one per rank")
    low, high = _sides(tree.rows, tree.cols)
    return (low @ shares) / (high @ shares)


@functools.lru_cache(maxsize=16)
def _sides(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """(K-1, K) 0/1: the ranks on each internal node's low and high side (made once per wall)."""
    tree = gpu_tree(rows, cols)
    out = np.zeros((2, len(tree.internal), tree.size))
    for n, node in enumerate(tree.internal):  # K - 1 nodes, once per wall
        for side, child in enumerate((node.low, node.high)):
            for c in range(child.c0, child.c1):
                out[side, n, c * rows + child.r0:c * rows + child.r1] = 1.0
    return out[0], out[1]
