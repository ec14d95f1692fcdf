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
    balanced = False  # whether ``--balance`` chooses how it divides a frame
    depth = False
    layers = 1
    needs_coverage = False

    def __init__(self, grid, size, bin_size: int = 64, pattern: str = "diagonal", rank: int | None = None):
        self.k = int(grid[0]) * int(grid[1])
        self.size = tuple(size)
        self.bin_size, self.pattern = int(bin_size), pattern
        self.rank = rank  # whose masks to compute (None: every rank's, for tests and reports)
        rects, bx, by = bin_rects(self.size, self.bin_size)
        self.nx, self.ny = int(bx.max()) + 1, int(by.max()) + 1
        self.who = owner(pattern, bx, by, self.k)
        self.rects = tuple(rects[self.who == k] for k in range(self.k))
        self.bins = tuple((bx[self.who == k], by[self.who == k]) for k in range(self.k))

    @classmethod
    def from_config(cls, cfg, scene, balance: str, rank: int | None = None) -> "Bins":
        return cls(cfg.grid, cfg.size, cfg.bin_size, cfg.bin_pattern, rank)

    def plan(self, frame: int, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Work:
        spans, onscreen = pixel_spans(rects, self.size)
        idx = np.flatnonzero(onscreen)
        b = self.bin_size
        bx0, by0, bx1, by1 = (spans.T[i, onscreen].astype(np.int64) // b for i in range(4))
        tris = np.asarray(tris, dtype=np.int64)
        t = tris[idx]
        # triangles per bin (an object counts in every bin it touches) from one 2-D difference
        # array over the bin grid: four bincounts and two prefix sums, whatever the bin count
        w = self.nx + 1
        diff = np.zeros((self.ny + 1) * w)
        for yy, xx, sign in ((by0, bx0, 1), (by0, bx1 + 1, -1), (by1 + 1, bx0, -1), (by1 + 1, bx1 + 1, 1)):
            diff += sign * np.bincount(yy * w + xx, weights=t, minlength=diff.size)
        per_bin = diff.reshape(self.ny + 1, w).cumsum(0).cumsum(1)[:self.ny, :self.nx].ravel()
        loads = np.bincount(self.who, weights=per_bin, minlength=self.k).round().astype(np.int64)
        masks = []
        for k, (kx, ky) in enumerate(self.bins):  # ranks, not objects
            m = np.zeros((len(kx) if self.rank in (None, k) else 0, len(tris)), dtype=bool)
            if len(m):  # this rank's bins x visible objects: which object touches which bin
                m[:, idx] = ((bx0 <= kx[:, None]) & (bx1 >= kx[:, None]) & (by0 <= ky[:, None]) & (by1 >= ky[:, None]))
            masks.append(m)
        return Work(self.rects, tuple(masks), loads, False, None)

    def observe(self, frame: int, work: Work, times: np.ndarray) -> None:
        """Static: measured times are not used."""

    def report(self) -> dict:
        return {"name": self.name, "pattern": self.pattern, "bin_size": self.bin_size,
                "bins_per_rank": [int(len(r)) for r in self.rects]}
