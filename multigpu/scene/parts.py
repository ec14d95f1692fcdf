"""Parts: every object of many triangles cut, inside itself, into spatially compact runs of
triangles with their own bounds, so a rank draws only the parts of an object its region needs.

The balancer sees whole objects (its cost does not grow with the part count); the renderer
culls an object's parts against the region it draws (``core/culling.py``). An object's triangles
are reordered along a Z-order curve of their centroids and every run of about
``PART_TRIS`` of them is a part, its bounding box kept beside it in the scene cache. Objects of at
most ``PART_TRIS`` triangles are one part each, their own bounds. Images do not change with the
part size: a part is culled only where none of its triangles reaches the region (conservative
bounds, as the objects'), and the reordering is the scene's, the same for every rank and for a
one-rank render. Built once at load, cached; pure numpy.
"""

from __future__ import annotations

import numpy as np

from multigpu.core import jit
from multigpu.scene.layout import Scene
from multigpu.scene.parts_kernel import _apply, _keys

#: triangles per part (objects above it are cut; measured in docs/BENCHMARKS.md, `bench parts`)
PART_TRIS = 64


def with_parts(scene: Scene, size: int = PART_TRIS, compiled: bool | None = None) -> Scene:
    """``scene`` with its parts: objects above ``size`` triangles reordered inside their own
    index range and cut into near-equal parts of at most ``size`` triangles, the others one
    part each (their own bounds). ``compiled`` as in ``_cut_in_place``."""
    big = np.flatnonzero(scene.tris > size)
    n_parts = np.ones(scene.n_objects, dtype=np.int64)
    indices = scene.indices
    if big.size:
        indices = np.array(scene.indices, dtype=np.uint32)  # a copy: the scene's may be a read-only map
        n_parts[big], counts, bmin, bmax = _cut_in_place(scene, big, size, indices, compiled)
    part_start = np.zeros(scene.n_objects + 1, dtype=np.int64)
    np.cumsum(n_parts, out=part_start[1:])
    total = int(part_start[-1])
    part_count = np.empty(total, dtype=np.int64)
    part_bmin, part_bmax = np.empty((total, 3)), np.empty((total, 3))
    whole = np.ones(scene.n_objects, dtype=bool)
    whole[big] = False
    at = part_start[:-1][whole]  # an object kept whole: its own range and bounds
    part_count[at] = scene.index_count[whole]
    part_bmin[at], part_bmax[at] = scene.bmin[whole], scene.bmax[whole]
    if big.size:  # the cut objects' parts, in (object, part) order, into their objects' part rows
        n = n_parts[big]
        rows = _ranges(part_start[big], n)
        part_count[rows], part_bmin[rows], part_bmax[rows] = counts, bmin, bmax
    meta = {**scene.meta, "parts": {"size": int(size), "parts": total, "objects_cut": int(big.size)}}
    return Scene(**{**scene._arrays(parts=False), "indices": indices}, name=scene.name, meta=meta,
                 part_start=part_start, part_count=part_count, part_bmin=part_bmin, part_bmax=part_bmax)


def _ranges(first: np.ndarray, n: np.ndarray) -> np.ndarray:
    """``first[k], first[k] + 1, ..., first[k] + n[k] - 1`` for every k, back to back."""
    return np.repeat(first - np.concatenate([[0], np.cumsum(n)[:-1]]), n) + np.arange(int(n.sum()))


#: triangles of cut objects handled at a time (an object larger than this alone): the temporaries
#: (keys, order, and for the numpy reference the corners) stay bounded at any scale
BLOCK_TRIS = 1 << 22


def _cut_in_place(scene: Scene, big: np.ndarray, size: int, indices: np.ndarray, compiled: bool | None = None):
    """Reorder the triangles of objects ``big`` inside their ranges of ``indices`` along a
    Z-order curve of their centroids in each object's own box, and cut each into near-equal
    parts of at most ``size``: (parts per object, (P,) index counts, (P, 3) bounds min and max).
    ``compiled``: the two passes of ``parts_kernel.py`` (None: where numba is installed) or this
    module's numpy reference (the same indices and bounds)."""
    tris = scene.tris[big]
    n = -(-tris // size)
    per = -(-tris // n)  # near-equal part sizes: every part but an object's last holds ``per``
    part_first = np.zeros(big.size + 1, dtype=np.int64)
    np.cumsum(n, out=part_first[1:])
    counts = np.zeros(int(part_first[-1]), dtype=np.int64)
    bmin, bmax = np.full((counts.size, 3), np.inf), np.full((counts.size, 3), -np.inf)
    ends = np.cumsum(tris)
    cut_at = np.searchsorted(ends, np.arange(BLOCK_TRIS, int(ends[-1]), BLOCK_TRIS), side="left")
    edges = np.unique(np.r_[0, cut_at + 1, big.size].clip(0, big.size))
    fn = _block if jit.use(compiled) else _block_reference
    for a, b in zip(edges[:-1], edges[1:]):  # blocks of objects, not objects
        fn(scene, big[a:b], per[a:b], part_first[a:b] , indices, counts, bmin, bmax)
    return n, counts, bmin, bmax


def _within_parts(order: np.ndarray, tris: np.ndarray, starts: np.ndarray, per: np.ndarray) -> np.ndarray:
    """``order`` (each object's triangles along the curve) with every part's triangles back in
    their modelled order: the curve decides which triangles share a part, the modeller's order
    how they are drawn (ordered along the curve, a one-rank render ran 16 % slower: vertex reuse)."""
    obj = np.repeat(np.arange(tris.size, dtype=np.int64), tris)
    part = obj * (int(tris.max()) + 1) + (np.arange(order.size, dtype=np.int64) - starts[obj]) // np.repeat(per, tris)
    return order[np.lexsort((order, part))]


def _block_args(scene: Scene, big: np.ndarray):
    tris = scene.tris[big]
    starts = np.zeros(big.size + 1, dtype=np.int64)  # each object's triangles, back to back
    np.cumsum(tris, out=starts[1:])
    lo = scene.bmin[big] - scene.origin
    span = np.maximum(scene.bmax[big] - scene.bmin[big], 1e-300)
    return (tris, starts, scene.first_index[big].astype(np.int64), scene.base_vertex[big].astype(np.int64),
            lo, span)


def _block(scene, big, per, part_first, indices, counts, bmin, bmax) -> None:
    """The compiled passes over one block of cut objects."""
    tris, starts, first, base, lo, span = _block_args(scene, big)
    src = np.ascontiguousarray(scene.indices)
    pos = np.ascontiguousarray(scene.vertices[:, :3])
    key = np.empty(int(starts[-1]), dtype=np.uint64)
    _keys(src, first, base, tris, starts, pos, lo, span, key)
    order = _within_parts(np.argsort(key, kind="stable"), tris, starts, per)
    _apply(order, src, indices, first, base, starts, per, part_first, pos, np.asarray(scene.origin, np.float64),
           counts, bmin, bmax)


def _block_reference(scene, big, per, part_first, indices, counts, bmin, bmax) -> None:
    """The numpy reference of ``_block``."""
    tris, starts, first, base, lo, span = _block_args(scene, big)
    total = int(starts[-1])
    obj = np.repeat(np.arange(big.size, dtype=np.int64), tris)  # which object of the block a triangle is of
    src = np.repeat(first, tris * 3) + np.arange(3 * total) - np.repeat(3 * starts[:-1], tris * 3)
    tri = scene.indices[src].astype(np.int64).reshape(total, 3)
    corners = scene.vertices[:, :3][tri + base[obj][:, None]]  # (T, 3, 3) float32
    m = (corners[:, 0].astype(np.float64) + corners[:, 1]) + corners[:, 2]
    cells = ((m / 3.0 - lo[obj]) / span[obj] * 1023.0).clip(0.0, 1023.0).astype(np.uint64)
    key = np.zeros(total, dtype=np.uint64)
    for b in range(10):  # bits of the code, not triangles
        for axis in range(3):
            key |= ((cells[:, axis] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + axis)
    key |= obj.astype(np.uint64) << np.uint64(30)
    order = _within_parts(np.argsort(key, kind="stable"), tris, starts, per)
    del key, cells
    indices[src] = tri[order].ravel().astype(np.uint32)
    corners = corners[order]
    part = np.repeat(part_first, tris) + (np.arange(total) - starts[obj]) // np.repeat(per, tris)
    cut = np.flatnonzero(np.r_[True, part[1:] != part[:-1]])
    lo_w = corners.min(axis=1).astype(np.float64) + scene.origin
    hi_w = corners.max(axis=1).astype(np.float64) + scene.origin
    rows = part[cut]
    bmin[rows] = np.minimum.reduceat(lo_w, cut)
    bmax[rows] = np.maximum.reduceat(hi_w, cut)
    counts[rows] = 3 * np.diff(np.r_[cut, total])
