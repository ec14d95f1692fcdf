"""``none``: the paper's baseline, every rank renders exactly its own display tile."""

from __future__ import annotations

import numpy as np

from multigpu.core.balance import Partition, partition_tiles
from multigpu.strategies.base import Configured


class NoBalance(Configured):
    """The paper's baseline: each rank renders exactly its own display tile."""

    name = "none"
    summary = "the paper's baseline: each rank renders exactly its own display tile"

    def plan(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Partition:
        return partition_tiles(rects, tris, self.grid, self.size, self.compiled)
