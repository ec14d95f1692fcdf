"""``static``: the baseline the paper argues against, a split made once and held.

The first frame this strategy plans is split by the paper's strip balancer; every later frame
keeps those cuts (each GPU-tree node's, in pixels) and only finds which objects each region
now needs. Whatever moves, the regions stay: what per-frame balancing buys is measured against
it (a run started by ``--recover`` holds the split of its own first frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multigpu.core.balance import Partition, partition, tree_partition
from multigpu.strategies.base import Configured


def _held(cuts: np.ndarray):
    """A chooser that needs no objects: every node's cut as ``cuts`` holds it (breadth first)."""
    def choose(task, spans) -> int:
        return int(cuts[task.n])

    choose.object_free = True
    return choose


@dataclass
class Static(Configured):
    """The first frame's strip split, held for the whole run."""

    name = "static"
    summary = "the first frame's strip split held for the whole run (the baseline per-frame balancing beats)"
    held: np.ndarray | None = None  # every node's cut in pixels, from the first frame planned

    def plan(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Partition:
        if self.held is None:
            first = partition(rects, tris, self.grid, self.size, self.strips, compiled=self.compiled)
            self.held = first.split_pixels.copy()
            return first
        return tree_partition(rects, tris, self.grid, self.size, self.strips, _held(self.held), self.compiled)

    def report(self) -> dict:
        return {"name": self.name, "held_split_pixels": None if self.held is None else self.held.tolist()}
