"""Draw commands for a subset of objects, with per-frame cost independent of object count.

A GL multi-draw still pays a setup cost per command inside the driver (llvmpipe: about a
microsecond each), so one command per visible object makes a 10^5-object frame slower than a
10^3-object frame of the same triangles. ``DrawList`` lays the scene's index buffer out once
in a spatial (Morton) order of object centres, with absolute vertex indices, and turns each
frame's visibility mask into one command per RUN of consecutive visible objects. Objects that
are near each other in space are near each other in the buffer, so a rank's screen region
selects a few long runs. Per-object colour reaches the shader through a per-vertex object id.

Pure numpy, no GL: ``render.py`` uploads ``index_blocks()`` and ``vertex_object`` once and sends
``commands(mask)`` every frame.
"""

from __future__ import annotations

import numpy as np

MORTON_BITS = 10  # per axis: 2**30 cells
#: indices per block when the buffer is built
CHUNK = 1 << 20


def morton_codes(points: np.ndarray, bits: int = MORTON_BITS, box=None) -> np.ndarray:
    """(N,) uint64 3-D Z-order codes of ``points`` (N, 3) over their bounding box, or over
    ``box`` = (lo, hi) (to code a big set a block at a time: the same codes)."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[0] == 0:
        return np.zeros(0, dtype=np.uint64)
    lo, hi = (p.min(axis=0), p.max(axis=0)) if box is None else box
    span = np.where(hi > lo, hi - lo, 1.0)
    cells = ((p - lo) / span * ((1 << bits) - 1)).astype(np.uint64)
    code = np.zeros(p.shape[0], dtype=np.uint64)
    for b in range(bits):  # bits of the code, not objects
        for axis in range(3):
            code |= ((cells[:, axis] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + axis)
    return code


def morton_order(points: np.ndarray, bits: int = MORTON_BITS) -> np.ndarray:
    """Permutation sorting ``points`` (N, 3) along a 3-D Z-order curve over their bounding box."""
    return np.argsort(morton_codes(points, bits), kind="stable")


#: the objects drawn last (``wide_objects``): the biggest in triangles times world size, holding
#: this share of the scene's triangles (chosen by ``multigpu experiment walls``' hybrid runs)
WIDE_SHARE = 0.25


def wide_objects(tris: np.ndarray, bmin: np.ndarray, bmax: np.ndarray, share: float = WIDE_SHARE) -> np.ndarray:
    """(N,) bool: the objects most likely to cross many regions of a wall, the largest by
    triangles times world diagonal (above the median), taken in that order until they hold
    ``share`` of the triangles. An object is drawn by every region its rect touches, so these
    make most of the triangles drawn twice on big walls. The hybrid decomposition draws them
    once, depth-composited; every decomposition draws them last, so depth ties resolve as in a
    one-rank render (``decompositions/hybrid.py``)."""
    tris = np.asarray(tris, dtype=np.float64)
    out = np.zeros(tris.size, dtype=bool)
    if tris.size == 0 or share <= 0:
        return out
    size = np.linalg.norm(np.asarray(bmax, dtype=np.float64) - np.asarray(bmin, dtype=np.float64), axis=1)
    weight = tris * size
    rank = np.argsort(-weight, kind="stable")
    held = np.cumsum(tris[rank])
    out[rank[:int(np.searchsorted(held, share * held[-1], side="left")) + 1]] = True
    return out & (weight > np.median(weight))  # only objects that stand out: none where all are alike


def draw_order(centers: np.ndarray, wide: np.ndarray | None = None) -> np.ndarray:
    """The renderer's object order: the Morton order of the centres, the ``wide`` objects after
    all others (each part in Morton order)."""
    codes = morton_codes(centers)
    if wide is None or not np.any(wide):
        return np.argsort(codes, kind="stable")
    return np.lexsort((codes, np.asarray(wide, dtype=bool)))


def scene_order(scene) -> tuple[np.ndarray, np.ndarray]:
    """(order, wide): a scene's draw order and its wide objects (``draw_order``, ``wide_objects``)."""
    wide = wide_objects(np.asarray(scene.index_count) // 3, scene.bmin, scene.bmax)
    return draw_order(scene.centers, wide), wide


def pass_groups(wide: np.ndarray, movers: np.ndarray | None) -> list[tuple[np.ndarray, int]] | None:
    """The groups of objects a frame draws in turn where some of a moving scene's objects stand
    still, each with its pass (0: without the maps, 1: with; ``gpu.render``): at rest, then
    moving; the wide objects after all others, at rest then moving. None where one pass draws
    every object in draw order (nothing moves, or everything)."""
    if movers is None or movers.all():
        return None
    wide = np.asarray(wide, dtype=bool)
    groups = [(~wide & ~movers, 0), (~wide & movers, 1), (wide & ~movers, 0), (wide & movers, 1)]
    return [(g, p) for g, p in groups if g.any()]


def pass_order(order: np.ndarray, wide: np.ndarray, movers: np.ndarray | None) -> np.ndarray:
    """The order objects are drawn in, ``pass_groups``' groups in turn (each in ``order``): the
    order a sort-last decomposition's ranges follow, so the lower rank's fragment wins a depth
    tie exactly where a one-rank render's earlier one does."""
    if pass_groups(wide, movers) is None:
        return order
    key = 2 * np.asarray(wide, dtype=np.int64)[order] + np.asarray(movers, dtype=np.int64)[order]
    return order[np.argsort(key, kind="stable")]


def drawn_order(scene) -> tuple[np.ndarray, np.ndarray]:
    """(order, wide): the order the renderer draws ``scene``'s objects in (``pass_order`` of its
    ``movers``, where a run set them) and its wide objects: what sort-last ranges follow."""
    order, wide = scene_order(scene)
    return pass_order(order, wide, getattr(scene, "movers", None)), wide


def owners(starts: np.ndarray, s: int, e: int) -> np.ndarray:
    """The object of every position in ``[s, e)``, objects laid out back to back from
    ``starts`` ((N+1,) cumulative, from 0)."""
    k0 = int(np.searchsorted(starts, s, side="right")) - 1
    k1 = int(np.searchsorted(starts, e, side="left"))
    span = np.minimum(starts[k0 + 1:k1 + 1], e) - np.maximum(starts[k0:k1], s)
    return np.repeat(np.arange(k0, k1, dtype=np.int64), span)


class DrawList:
    """A scene's index buffer in Morton order, and per-frame run-merged draw commands.

    Attributes
    ----------
    order : (N,) int64  object ids in buffer order (``draw_order``: Morton, the wide objects last).
    wide : (N,) bool  the objects drawn last (``wide_objects``).
    indices : (3T,) uint32  absolute vertex indices (base vertex folded in), objects in ``order``
        (made on demand from the scene; ``index_blocks`` streams it).
    vertex_object : (V,) uint32  object id of every vertex (for per-object colour; on demand).
    """

    def __init__(self, scene):
        count = scene.index_count.astype(np.int64)
        self.order, self.wide = scene_order(scene)
        lengths = count[self.order]
        self.offsets = np.zeros(scene.n_objects + 1, dtype=np.int64)  # buffer offset of each object in order
        np.cumsum(lengths, out=self.offsets[1:])
        self._scene = scene  # until uploaded: the GL buffers are made from it a block at a time
        start = getattr(scene, "part_start", None)
        self.parts = start is not None and int(start[-1]) > scene.n_objects  # objects cut into parts
        if self.parts:  # the parts in buffer order: each object's parts in its place, in their own order
            n = start[self.order + 1] - start[self.order]
            self.part_order = np.repeat(start[self.order] - np.concatenate([[0], np.cumsum(n)[:-1]]), n) + np.arange(
                int(n.sum()))
            self.part_obj = np.repeat(np.arange(scene.n_objects, dtype=np.int64), np.diff(start))
            self.part_offsets = np.zeros(self.part_order.size + 1, dtype=np.int64)
            np.cumsum(scene.part_count[self.part_order], out=self.part_offsets[1:])
            self.part_count = scene.part_count
        # coarser levels of detail (``scene/lod.py``): each level's block after the last, objects in the same order
        lod_count = getattr(scene, "lod_count", None)
        self.levels = 1 if lod_count is None else int(lod_count.shape[1])
        self.lod_offsets = []  # per level from 1: (N+1,) absolute buffer offsets of the objects in order
        at = int(self.offsets[-1])
        for lv in range(1, self.levels):  # levels, not objects
            off = np.full(scene.n_objects + 1, at, dtype=np.int64)
            np.cumsum(lod_count[self.order, lv], out=off[1:])
            off[1:] += at
            self.lod_offsets.append(off)
            at = int(off[-1])
        #: indices in the whole buffer, every level
        self.total = at

    @property
    def vertex_object(self) -> np.ndarray:
        """(V,) uint32 the object id of every vertex, made from the scene on demand (4 bytes a
        vertex; the indices pass a block of ``CHUNK`` at a time, so the temporaries stay small
        at any scale). A vertex shared by objects gets the last one's id."""
        scene = self._scene
        if scene is None:
            raise RuntimeError("the draw list was uploaded: its scene's buffers are gone")
        n, nv = scene.n_objects, scene.vertices.shape[0]
        count = scene.index_count.astype(np.int64)
        base = scene.base_vertex.astype(np.int64)
        out = np.zeros(nv, dtype=np.uint32)
        starts = np.zeros(n + 1, dtype=np.int64)  # the scene's own layout: object i's indices follow i-1's
        np.cumsum(count, out=starts[1:])
        for s in range(0, int(starts[-1]), CHUNK):
            e = min(s + CHUNK, int(starts[-1]))
            obj = owners(starts, s, e)
            absolute = scene.indices[s:e].astype(np.int64) + base[obj]
            if absolute.min() < 0 or absolute.max() >= nv:
                raise ValueError(f"{scene.name}: an index points outside the vertex buffer")
            out[absolute] = obj
        return out

    def index_blocks(self):
        """The index buffer a block of ``CHUNK`` indices at a time: ``(offset, (n,) uint32
        absolute vertex indices)``, objects in ``order``. The renderer writes each block into
        its GL buffer, so no full-size copy of the buffer is ever made on the host."""
        scene = self._scene
        base = scene.base_vertex.astype(np.int64)[self.order]
        levels = [(scene.first_index.astype(np.int64)[self.order], self.offsets)]
        levels += [(scene.lod_first[self.order, lv].astype(np.int64), off)
                   for lv, off in enumerate(self.lod_offsets, 1)]
        for first, offsets in levels:  # levels of detail, not objects
            for s in range(int(offsets[0]), int(offsets[-1]), CHUNK):
                e = min(s + CHUNK, int(offsets[-1]))
                k = owners(offsets - offsets[0], s - offsets[0], e - offsets[0])  # which object in buffer order
                src = first[k] + np.arange(s, e, dtype=np.int64) - offsets[k]
                yield s, (scene.indices[src].astype(np.int64) + base[k]).astype(np.uint32)

    @property
    def indices(self) -> np.ndarray:
        """(3T,) uint32 the whole index buffer (tests and tools; the renderer streams it)."""
        out = np.empty(self.total, dtype=np.uint32)
        for s, block in self.index_blocks():
            out[s:s + block.size] = block
        return out

    def uploaded(self) -> None:
        """Drop the scene once the GL buffers hold it (``commands`` needs only ``order`` and
        ``offsets``): a rank keeps one copy, the GL one."""
        self._scene = None

    def leveled(self, mask: np.ndarray | None, levels: np.ndarray | None, seen: np.ndarray | None = None,
                compiled: bool | None = None) -> np.ndarray:
        """The draw commands of the objects in ``mask`` at their ``levels`` of detail ((N,) int,
        0: as modelled; None: all at 0): ``commands`` (``part_commands`` where ``seen`` parts are
        given) for level 0, then one command per run of each coarser level's objects in its block
        (a coarse level is drawn whole: it has few triangles)."""
        if levels is None or not self.lod_offsets:
            return self.commands(mask, compiled) if seen is None or not self.parts else self.part_commands(
                mask, seen, compiled)
        mask = np.ones(self.order.size, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        full = mask & (levels == 0)
        out = [self.commands(full, compiled) if seen is None or not self.parts else
               self.part_commands(full, seen, compiled)]
        for lv, off in enumerate(self.lod_offsets, 1):  # levels, not objects
            out.append(self.commands(mask & (levels == lv), compiled, off))
        return np.concatenate(out)

    def commands(self, mask: np.ndarray | None, compiled: bool | None = None,
                 offsets: np.ndarray | None = None) -> np.ndarray:
        """(R, 5) uint32 ``(count, 1, first, 0, 0)`` draw commands, one per run of visible
        objects in buffer order; ``mask`` (N,) bool in scene object order (None: all).
        ``compiled``: the one-pass kernel (``drawlist_kernel.py``, the same commands) where
        numba is installed (None), or this numpy reference (False). ``offsets``: a coarser
        level's block (``lod_offsets``; None: the objects as modelled)."""
        if mask is None:
            mask = np.ones(self.order.size, dtype=bool)
        offsets = self.offsets if offsets is None else offsets
        from multigpu.core import jit

        if jit.use(compiled):
            from multigpu.core.drawlist_kernel import _commands

            return _commands(np.ascontiguousarray(mask, dtype=np.bool_), self.order, offsets)
        return _runs(np.asarray(mask, dtype=bool), self.order, offsets)

    def part_commands(self, mask: np.ndarray | None, seen: np.ndarray, compiled: bool | None = None) -> np.ndarray:
        """``commands`` over parts (a scene whose objects are cut into parts): a part is drawn
        where its object is in ``mask`` (N,) and it is ``seen`` (P,) bool in scene part order
        (``core/culling.py``: its bounds reach the region). ``compiled`` as in ``commands``."""
        if mask is None:
            mask = np.ones(self.order.size, dtype=bool)
        from multigpu.core import jit

        if jit.use(compiled):
            from multigpu.core.drawlist_kernel import _part_commands

            return _part_commands(np.ascontiguousarray(mask, dtype=np.bool_),
                                  np.ascontiguousarray(seen, dtype=np.bool_), self.part_obj, self.part_order,
                                  self.part_offsets)
        drawn = np.asarray(mask, dtype=bool)[self.part_obj] & np.asarray(seen, dtype=bool)
        return _runs(drawn, self.part_order, self.part_offsets)


def _runs(mask: np.ndarray, order: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """The numpy reference of the run merge: one command per run of ``mask``ed items (objects or
    parts, ``mask`` in scene order) consecutive in buffer ``order``, ``offsets`` their buffer offsets."""
    m = mask[order].view(np.int8)
    edges = np.diff(m, prepend=np.int8(0), append=np.int8(0))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)
    first = offsets[starts]
    count = offsets[ends] - first
    keep = count > 0  # runs of zero-triangle items draw nothing
    cmd = np.zeros((int(keep.sum()), 5), dtype=np.uint32)
    cmd[:, 0] = count[keep]
    cmd[:, 1] = 1
    cmd[:, 2] = first[keep]
    return cmd
