"""``hybrid``: the screen partition for most objects, the wide ones drawn once and depth-composited.

On a wall of many tiles an object is drawn by every region its rect touches, and a few objects
(big in triangles and in the world: ``core.drawlist.wide_objects``) make most of what is drawn
twice. Here those are taken out of the screen partition: a balancing strategy (``--balance``)
cuts the display for the others, and the visible wide objects, in draw order, are cut into K
contiguous ranges that fill each rank up to the mean load (a rank the partition left light takes
more); each rank renders its range with depth over the bounding rect of its objects' pixels, as
``db`` does, and every tile owner keeps the nearest fragment (Molnar et al.'s sort-last for the
objects that make sort-first's overlap; the sort-first/sort-last hybrids of Samanta et al. 2000).

Exact: every rank's region carries depth too. The wide objects are drawn after all others
(``core.drawlist.draw_order``), so at a depth tie a one-rank render keeps the region's fragment,
and a region's parts win ties (``Piece.ties``); among the depth pieces the lower rank wins, as it
holds the earlier range. The composed wall equals a one-rank render bit for bit. The price:
every piece's depth is read back and travels, and a rank sends up to two pieces' parts.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.drawlist import drawn_order
from multigpu.core.regions import pixel_spans
from multigpu.core.work import Work, from_partition


def fill_ranges(weight: np.ndarray, loads: np.ndarray) -> np.ndarray:
    """(M,) rank of each of M items in order: contiguous ascending ranges whose ``weight``s
    bring the ranks' ``loads`` (K,) toward their common mean (each rank's room is what its load
    lacks of the mean of all the work, split by the items' running total)."""
    w = np.asarray(weight, dtype=np.float64)
    loads = np.asarray(loads, dtype=np.float64)
    k, total = loads.size, float(w.sum())
    if w.size == 0:
        return np.zeros(0, dtype=np.int64)
    room = np.maximum((loads.sum() + total) / k - loads, 0.0)
    if room.sum() <= 0 or total <= 0:
        room = np.ones(k)
    ends = np.cumsum(room) / room.sum() * total  # where each rank's range ends along the items' total
    middle = np.cumsum(w) - w / 2  # an item goes where its middle lands
    return np.minimum(np.searchsorted(ends, middle, side="right"), k - 1).astype(np.int64)


class Hybrid:
    """Sort-first regions for most objects, the wide objects in depth-composited ranges."""

    name = "hybrid"
    balanced = True  # whether ``--balance`` chooses how it divides a frame
    depth = True
    layers = 2  # a rank's pieces may cover the display twice: its region and its depth piece

    def __init__(self, strategy, grid, size, order: np.ndarray, wide: np.ndarray):
        self.strategy = strategy
        self.needs_coverage = strategy.needs_coverage
        self.k = int(grid[0]) * int(grid[1])
        self.size = tuple(size)
        self.wide = np.asarray(wide, dtype=bool)
        self.order = np.asarray(order, dtype=np.int64)[self.wide[order]]  # the wide objects in draw order

    @classmethod
    def from_config(cls, cfg, scene, balance: str, rank: int | None = None) -> "Hybrid":
        from multigpu.strategies import make_strategy

        order, wide = drawn_order(scene)
        return cls(make_strategy(balance, cfg.grid, cfg.size, cfg.strips), cfg.grid, cfg.size, order, wide)

    def plan(self, frame: int, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Work:
        rects = np.asarray(rects)
        tris = np.asarray(tris, dtype=np.int64)
        narrow = rects.copy()
        narrow[self.wide] = np.nan  # the wide objects are no region's
        base = from_partition(self.strategy.plan(narrow, tris, coverage), tris)
        spans, onscreen = pixel_spans(rects[self.order], self.size)
        idx = self.order[onscreen]  # the visible wide objects, in draw order
        spans = spans[onscreen]
        owner = fill_ranges(tris[idx], base.loads)
        n = tris.size
        masks = np.zeros((self.k, n), dtype=bool)
        masks[owner, idx] = True
        cuts = np.searchsorted(owner, np.arange(self.k + 1))  # rank k's range: idx[cuts[k]:cuts[k + 1]]
        ranks = np.flatnonzero(cuts[1:] > cuts[:-1])  # the ranks with wide objects to draw
        at = cuts[ranks]
        boxes = np.stack([np.minimum.reduceat(spans[:, 0], at), np.minimum.reduceat(spans[:, 1], at),
                          np.maximum.reduceat(spans[:, 2], at) + 1, np.maximum.reduceat(spans[:, 3], at) + 1],
                         axis=1).astype(np.int64) if ranks.size else np.zeros((0, 4), dtype=np.int64)
        loads = np.asarray(base.loads, dtype=np.int64).copy()
        if ranks.size:
            loads[ranks] += np.add.reduceat(tris[idx], at)
        out_rects, out_masks = list(base.rects), list(base.masks)
        for j, k in enumerate(ranks.tolist()):  # ranks, not objects
            out_rects[k] = np.concatenate([np.asarray(out_rects[k], dtype=np.int64).reshape(-1, 4), boxes[j:j + 1]])
            out_masks[k] = np.concatenate([np.asarray(out_masks[k]).reshape(-1, n), masks[k:k + 1]])
        front = tuple(len(r) for r in base.rects)
        return Work(tuple(out_rects), tuple(out_masks), loads, True, base.partition, front)

    def observe(self, frame: int, work: Work, times: np.ndarray) -> None:
        """The strategy learns from the ranks' whole render times (its regions and their ranges)."""
        self.strategy.observe(frame, work.partition, times)

    def report(self) -> dict:
        return {"name": self.name, "strategy": self.strategy.report(), "wide_objects": int(self.wide.sum()),
                "order": "the draw order (morton, wide objects last)"}
