"""``screen``: the paper's hybrid. A balancing strategy cuts the display into one region per
rank (or a few, for cross-segment); a rank draws the objects touching its region, scissored
to it, and the regions travel to their tile owners."""

from __future__ import annotations

import numpy as np

from multigpu.core.work import Work, from_partition


class Screen:
    """Sort-first balancing, sort-last region exchange, around any registered strategy."""

    name = "screen"
    depth = False

    def __init__(self, strategy):
        self.strategy = strategy
        self.needs_coverage = strategy.needs_coverage

    def plan(self, frame: int, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Work:
        return from_partition(self.strategy.plan(rects, tris, coverage), tris)

    def plan_from(self, part, tris) -> Work:
        """Work from a partition planned elsewhere (``--partition broadcast``)."""
        return from_partition(part, tris)

    def observe(self, frame: int, work: Work, times: np.ndarray) -> None:
        self.strategy.observe(frame, work.partition, times)

    def report(self) -> dict:
        return {"name": self.name, "strategy": self.strategy.report()}
