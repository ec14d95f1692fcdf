"""``screen``: the paper's hybrid. A balancing strategy cuts the display into one region per
rank (or a few, for cross-segment); a rank draws the objects touching its region, scissored
to it, and the regions travel to their tile owners."""

from __future__ import annotations

import numpy as np

from multigpu.core.work import Work, from_partition


class Screen:
    """Sort-first balancing, sort-last region exchange, around any registered strategy."""

    name = "screen"
    balanced = True  # whether ``--balance`` chooses how it divides a frame
    depth = False
    layers = 1

    def __init__(self, strategy):
        self.strategy = strategy
        self.needs_coverage = strategy.needs_coverage

    @classmethod
    def from_config(cls, cfg, scene, balance: str, rank: int | None = None, grid=None) -> "Screen":
        """``grid``: the GPU tree's shape where it is not the wall's (half the ranks, for a stereo
        wall split by eye: ``core/stereo.halved``)."""
        from multigpu.strategies import make_strategy

        return cls(make_strategy(balance, cfg.grid if grid is None else grid, cfg.size, cfg.strips))

    def plan(self, frame: int, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Work:
        return from_partition(self.strategy.plan(rects, tris, coverage), tris)

    def partition(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None):
        """The strategy's partition alone (``--partition broadcast``: rank 0 plans it, every
        rank turns it into work with ``from_partition``)."""
        return self.strategy.plan(rects, tris, coverage)

    @staticmethod
    def from_partition(part, tris) -> Work:
        """Work from a partition planned elsewhere."""
        return from_partition(part, tris)

    def observe(self, frame: int, work: Work, times: np.ndarray) -> None:
        self.strategy.observe(frame, work.partition, times)

    def report(self) -> dict:
        return {"name": self.name, "strategy": self.strategy.report()}
