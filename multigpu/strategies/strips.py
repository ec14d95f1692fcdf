"""``strips``: Dong & Peng's GPU-tree strip balancer on triangle counts (the paper's method)."""

from __future__ import annotations

import numpy as np

from multigpu.core.balance import Partition, partition
from multigpu.strategies.base import Configured


class Strips(Configured):
    """Dong & Peng's GPU-tree strip balancer on triangle counts."""

    name = "strips"
    summary = "Dong & Peng's GPU-tree strip balancer on triangle counts"

    def plan(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Partition:
        return partition(rects, tris, self.grid, self.size, self.strips, compiled=self.compiled)
