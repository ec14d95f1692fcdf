"""``time``: Equalizer's load equalizer as the baseline: no scene knowledge, the splits follow
the previous frame's measured render times, damped."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multigpu.core.balance import Partition, partition, tree_partition
from multigpu.core.splits import time_chooser
from multigpu.strategies.base import Configured


@dataclass
class TimeFeedback(Configured):
    """Equalizer's load equalizer, as the state-of-the-art baseline: no scene knowledge, the
    splits follow the previous frame's measured render times with ``damping``."""

    damping: float = 0.5

    name = "time"
    summary = "Equalizer's load equalizer: splits follow the last frame's render times, no scene knowledge"
    reproducible = False  # it follows measured times

    def __post_init__(self):
        self._last: Partition | None = None
        self._times: np.ndarray | None = None

    def plan(self, rects, tris, coverage=None):
        if self._last is None:
            return partition(rects, tris, self.grid, self.size, self.strips, compiled=self.compiled)
        choose = time_chooser(self._last.regions, self._times, self._last.split_pixels, self.damping)
        return tree_partition(rects, tris, self.grid, self.size, self.strips, choose, self.compiled)

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        self._last, self._times = partition, np.asarray(times, dtype=np.float64).copy()
