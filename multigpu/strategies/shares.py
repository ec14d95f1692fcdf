"""``shares``: the paper's strips, with each rank's share of the work learned from its render times.

The strip balancer splits every node's work in the ratio of its ranks (``nl / nr``): right for
equal GPUs and a cost that triangles predict. Where a rank is slower (another GPU, a region whose
pixels cost more than its triangles say, a core it shares), its render time stays above the
others' frame after frame. Here each rank keeps a share; after every frame's times land, a
rank that took longer than the mean loses share and a faster one gains, by ``rate`` of the log of
the ratio, so the shares settle where the times are equal; the split at each node then takes the
ratio of its two sides' shares (``core.balance.partition(shares=...)``, the paper's balRatio for
unequal ranks). The content of the frame is still balanced the moment the camera moves (the
strips count this frame's triangles); only the residual the triangles do not explain is learned,
slowly. Shares stay within ``limit`` of each other's mean.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from multigpu.core.balance import Partition, node_ratios, partition
from multigpu.core.tree import gpu_tree
from multigpu.strategies.base import Configured

#: the features a ``shares`` plan carries: the mark of its own partitions
MINE = {"planner": "shares"}


@dataclass
class Shares(Configured):
    """Strips, each split's balRatio from per-rank shares learned from the measured times."""

    rate: float = 0.25  # how far a frame's log time ratio moves a share (damped: times are noisy)
    limit: float = 4.0  # a share stays within [mean / limit, mean * limit]

    name = "shares"
    summary = "strips with each rank's share of the work learned from its measured render times"
    reproducible = False  # it follows measured times

    def __post_init__(self):
        if not (0 < self.rate <= 1 and self.limit > 1):
            raise ValueError("shares: need 0 < rate <= 1 and limit > 1")
        self.k = int(self.grid[0]) * int(self.grid[1])
        self._log = [0.0] * self.k  # each rank's log share, mean 0 (floats: K of them, a frame)
        self._ratios = None  # every node's balRatio from the shares (None: equal, the paper's)
        self._tree = gpu_tree(*self.grid)

    @property
    def shares(self) -> np.ndarray:
        return np.exp(np.array(self._log))

    def plan(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Partition:
        p = partition(rects, tris, self.grid, self.size, self.strips, compiled=self.compiled, ratios=self._ratios)
        return p._replace(features=MINE)  # ``observe`` learns only from its own plans (``auto`` shows it others)

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        """Move every rank's share by ``rate`` of log(mean time / its time), keep their mean at 1."""
        if partition is None or partition.features is not MINE:
            return  # another strategy's plan (auto's other candidate) or one planned elsewhere
        t = [float(v) for v in times]  # K ranks: plain floats cost less than numpy calls here
        if len(t) != self.k or not all(0.0 < v < math.inf for v in t):
            return  # a frame without a time for every rank says nothing about their speeds
        mean = math.log(sum(t) / self.k)
        s = [ls + self.rate * (mean - math.log(v)) for ls, v in zip(self._log, t)]
        centre, bound = sum(s) / self.k, math.log(self.limit)
        self._log = [min(max(v - centre, -bound), bound) for v in s]
        self._ratios = node_ratios(self._tree, self.shares)

    def report(self) -> dict:
        return {"name": self.name, "shares": [round(float(v), 3) for v in self.shares]}
