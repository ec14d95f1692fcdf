"""``db``: sort-last (database) decomposition with depth compositing (Equalizer DB, IceT,
Moreland et al. 2001 on tiled displays).

Objects are ordered along the renderer's own draw order (the Morton order of their centres,
the wide objects last: ``core.drawlist.scene_order``) and cut into K contiguous ranges of equal triangles: over the
objects visible this frame (``ranges="visible"``, rebalanced every frame) or over all objects
(``"static"``, fixed). A range is compact in space, so a rank's objects project to a small part
of the display; the rank renders them with depth over the bounding rect of their projections
and every tile owner keeps the nearest fragment. Ranges are ascending in draw order, so a
depth tie goes to the lower rank, which is the fragment a one-rank render keeps (GL_LESS keeps
the first drawn): the composed wall equals a one-rank render bit for bit. No geometry is drawn
twice and no screen balancing is needed; the price is colour plus depth in up to K-1 messages
per tile.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.drawlist import drawn_order
from multigpu.core.regions import pixel_spans
from multigpu.core.work import Work

RANGES = ("visible", "static")


def ranges_by_weight(order: np.ndarray, weight: np.ndarray, k: int) -> np.ndarray:
    """(N,) rank of every object: ``order`` cut into ``k`` contiguous runs of equal total
    ``weight`` (an object goes where the running total before it lands)."""
    w = np.asarray(weight, dtype=np.float64)[order]
    total = w.sum()
    before = np.cumsum(w) - w
    rank_in_order = np.minimum((before * k / total).astype(np.int64), k - 1) if total > 0 else \
        np.minimum(np.arange(order.size) * k // max(order.size, 1), k - 1)
    out = np.empty(order.size, dtype=np.int64)
    out[order] = rank_in_order
    return out


class Database:
    """Contiguous draw-order ranges of objects per rank, depth-composited onto the tiles."""

    name = "db"
    balanced = False  # whether ``--balance`` chooses how it divides a frame
    depth = True
    layers = 1
    needs_coverage = False

    def __init__(self, grid, size, order: np.ndarray, tris: np.ndarray, ranges: str = "visible"):
        if ranges not in RANGES:
            raise ValueError(f"db ranges must be one of {', '.join(RANGES)}, got '{ranges}'")
        self.k = int(grid[0]) * int(grid[1])
        self.size = tuple(size)
        self.order = np.asarray(order, dtype=np.int64)  # the draw order
        self.ranges = ranges
        self.static_owner = ranges_by_weight(self.order, tris, self.k)

    @classmethod
    def from_config(cls, cfg, scene, balance: str, rank: int | None = None) -> "Database":
        return cls(cfg.grid, cfg.size, drawn_order(scene)[0], scene.tris, cfg.db_ranges)

    def plan(self, frame: int, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Work:
        spans, onscreen = pixel_spans(rects, self.size)
        tris = np.asarray(tris, dtype=np.int64)
        owner = self.static_owner if self.ranges == "static" else \
            ranges_by_weight(self.order, np.where(onscreen, tris, 0), self.k)
        sp = spans.T  # (4, N)
        rects_out, masks, loads = [], [], np.zeros(self.k, dtype=np.int64)
        for k in range(self.k):  # ranks, not objects
            mask = onscreen & (owner == k)
            if not mask.any():
                rects_out.append(np.zeros((0, 4), dtype=np.int64))
                masks.append(np.zeros((0, len(tris)), dtype=bool))
                continue
            idx = np.flatnonzero(mask)
            box = np.array([[sp[0, idx].min(), sp[1, idx].min(), sp[2, idx].max() + 1, sp[3, idx].max() + 1]],
                           dtype=np.int64)
            rects_out.append(box)
            masks.append(mask[None, :])
            loads[k] = tris[idx].sum()
        return Work(tuple(rects_out), tuple(masks), loads, True, None)

    def observe(self, frame: int, work: Work, times: np.ndarray) -> None:
        """Ranges follow triangles; measured times are not used."""

    def report(self) -> dict:
        return {"name": self.name, "ranges": self.ranges, "order": "the draw order (morton, wide objects last)"}
