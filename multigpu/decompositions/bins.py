"""``bins``: static bin patterns, sort-middle emulated (Kerbl et al. 2017; Equalizer's tile and
pixel compounds). The display is cut into B x B pixel bins owned by ranks in a fixed pattern
(``core.bins``); a rank draws, bin by bin, the objects touching each of its bins, scissored
to it, and the bins travel to their tile owners. No balancer: this is the static baseline the
dynamic methods must beat; ``Work.load_cv`` (std/mean of per-rank triangles, the paper's
c_v) says how even the pattern is in each frame."""

from __future__ import annotations

import numpy as np

from multigpu.core.bins import bin_rects, owner
from multigpu.core.regions import pixel_spans
from multigpu.core.work import Work


class Bins:
    name = "bins"
    depth = False
    needs_coverage = False

    def __init__(self, grid, size, bin_size: int = 64, pattern: str = "diagonal"):
        self.k = int(grid[0]) * int(grid[1])
        self.size = tuple(size)
        self.bin_size, self.pattern = int(bin_size), pattern
        rects, bx, by = bin_rects(self.size, self.bin_size)
        who = owner(pattern, bx, by, self.k)
        self.rects = tuple(rects[who == k] for k in range(self.k))

    def plan(self, frame: int, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Work:
        spans, onscreen = pixel_spans(rects, self.size)
        sp = spans.T[:, onscreen]  # (4, n) visible objects only
        idx = np.flatnonzero(onscreen)
        tris = np.asarray(tris, dtype=np.int64)
        masks, loads = [], np.zeros(self.k, dtype=np.int64)
        for k, r in enumerate(self.rects):  # ranks, not objects: one (bins x objects) test each
            touch = ((sp[0] < r[:, 2:3]) & (sp[2] >= r[:, 0:1]) & (sp[1] < r[:, 3:4]) & (sp[3] >= r[:, 1:2]))
            m = np.zeros((len(r), len(tris)), dtype=bool)
            m[:, idx] = touch
            masks.append(m)
            loads[k] = int((touch.astype(np.int64) @ tris[idx]).sum()) if len(r) and idx.size else 0
        return Work(self.rects, tuple(masks), loads, False, None)

    def observe(self, frame: int, work: Work, times: np.ndarray) -> None:
        """Static: measured times are not used."""

    def report(self) -> dict:
        return {"name": self.name, "pattern": self.pattern, "bin_size": self.bin_size,
                "bins_per_rank": [int(len(r)) for r in self.rects]}
