"""``cross``: cross-segment load balancing (Erol, Eilemann, Pajarola 2011; Equalizer's view
equalizer over per-segment load equalizers).

Each display tile is a segment. From the last frame's measured times (each rank's time spread
evenly over the pixels it rendered), every segment's load is known. The view equalizer gives
segment t a share ``r_t = K * L_t / sum(L)`` of the K ranks (damped, and never zero), and lays
the shares out along one resource axis in tile order: rank k is the unit ``[k, k+1)`` of that
axis, so it helps the segments its unit overlaps, usually its own and a neighbour. Each
segment is then split among its helpers by its own load equalizer: cuts across the segment's
longer axis where the measured time profile reaches each helper's share. A rank may thus
render pieces of two segments; the pieces tile the display and travel to their tiles' owners.
Follows measured times, so not bit-reproducible between runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multigpu.core import kernel
from multigpu.core.balance import Partition, partition
from multigpu.core.regions import pixel_spans, tile_regions
from multigpu.strategies.base import Configured


def _seqsum(x: np.ndarray) -> float:
    """Sum in index order (numpy's ``sum`` pairs terms; the compiled kernel adds in order)."""
    return float(np.cumsum(x)[-1])


def _overlap_area(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(P, T) pixel areas of every rect of ``a`` (P, 4) within every rect of ``b`` (T, 4)."""
    lo = np.maximum(a[:, None, :2], b[None, :, :2])
    hi = np.minimum(a[:, None, 2:], b[None, :, 2:])
    return np.clip(hi - lo, 0, None).prod(axis=-1)


@dataclass
class CrossSegment(Configured):
    """Resources move between display segments by load, then each segment is split by time."""

    damping: float = 0.5
    min_share: float = 0.02  # a segment keeps at least this share of a rank

    name = "cross"
    reproducible = False  # it follows measured times

    def __post_init__(self):
        rows, cols = self.grid
        W, H = self.size
        self.tiles = tile_regions(rows, cols, W // cols, H // rows)
        self._pieces: tuple | None = None
        self._flat: dict | None = None  # the same pieces flat, where the kernel planned them
        self._times: np.ndarray | None = None
        self.shares = np.ones(len(self.tiles))
        self._spare = np.empty(len(self.tiles))  # the compiled kernel's new shares go here (no array to box)
        self._compiled = kernel.use(self.compiled)  # once, not per frame
        self._integer = None  # the integer weights array last seen (checked once, not per frame)
        self._bound: dict = {}  # the kernel's entry point for this strategy's own argument types
        self.size = (int(W), int(H))  # the kernel's argument types, fixed here once
        self.damping, self.min_share = float(self.damping), float(self.min_share)

    def plan(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Partition:
        if self._pieces is None:
            return partition(rects, tris, self.grid, self.size, self.strips, compiled=self.compiled)
        if self._compiled and (tris is self._integer or self._integers(tris)):
            old = self.shares  # the new shares go into the spare array; the old one is the next spare
            self.shares, part = kernel.cross_partition(self._flat or self._pieces, self._times, self.tiles, old,
                                                       self.damping, self.min_share, rects, tris, self.size,
                                                       self._spare, self._bound)
            self._spare = old
            return Partition(*part)
        tris = np.asarray(tris)
        k = len(self.tiles)
        profiles, loads = self._profiles()
        total = _seqsum(loads)
        new = k * loads / total if total > 0 else np.ones(k)
        shares = (1 - self.damping) * new + self.damping * self.shares
        shares = np.maximum(shares, self.min_share)
        self.shares = shares * (k / _seqsum(shares))
        pieces = self._split(profiles)
        return self._partition(pieces, rects, tris)

    def _profiles(self):
        """Per segment: the time profile along its longer axis, and its total time."""
        owner = np.concatenate([np.full(len(p), k) for k, p in enumerate(self._pieces)])
        allp = np.concatenate([np.asarray(p, np.int64).reshape(-1, 4) for p in self._pieces])
        area = (allp[:, 2] - allp[:, 0]) * (allp[:, 3] - allp[:, 1])
        per_rank_area = np.bincount(owner, weights=area, minlength=len(self._pieces))
        density = self._times[owner] / np.maximum(per_rank_area[owner], 1.0)  # time per pixel, per piece
        inter = _overlap_area(allp, self.tiles)  # (P, T)
        loads = np.cumsum(density[:, None] * inter, axis=0)[-1]  # added in piece order
        profiles = []
        for t, (x0, y0, x1, y1) in enumerate(self.tiles):  # segments, then their pieces: not objects
            ax = 0 if x1 - x0 >= y1 - y0 else 1
            a0, a1 = (x0, x1) if ax == 0 else (y0, y1)
            prof = np.zeros(a1 - a0)
            for j in np.flatnonzero(inter[:, t]):
                px0, py0, px1, py1 = allp[j]
                lo, hi = (max(px0, x0), min(px1, x1)) if ax == 0 else (max(py0, y0), min(py1, y1))
                across = (min(py1, y1) - max(py0, y0)) if ax == 0 else (min(px1, x1) - max(px0, x0))
                prof[lo - a0:hi - a0] += density[j] * across
            profiles.append((ax, a0, prof))
        return profiles, loads

    def _split(self, profiles) -> list[list[np.ndarray]]:
        """Rank k's unit [k, k+1) of the resource axis against each segment's share: cuts."""
        k = len(self.tiles)
        start = np.concatenate([[0.0], np.cumsum(self.shares)[:-1]])
        pieces: list[list[np.ndarray]] = [[] for _ in range(k)]
        for t, (ax, a0, prof) in enumerate(profiles):  # segments
            lo_r, hi_r = start[t], start[t] + self.shares[t]
            helpers = [r for r in range(k) if min(r + 1, hi_r) - max(r, lo_r) > 1e-12]
            used = np.array([min(r + 1, hi_r) - max(r, lo_r) for r in helpers])
            cum = np.cumsum(prof) if prof.sum() > 0 else np.arange(1, prof.size + 1, dtype=np.float64)
            targets = np.cumsum(used)[:-1] / _seqsum(used) * cum[-1]
            cuts = np.concatenate([[0], np.searchsorted(cum, targets, side="left") + 1, [prof.size]])
            cuts = np.maximum.accumulate(np.minimum(cuts, prof.size))
            x0, y0, x1, y1 = self.tiles[t]
            for r, c0, c1 in zip(helpers, cuts[:-1], cuts[1:]):
                if c1 <= c0:
                    continue
                rect = [a0 + c0, y0, a0 + c1, y1] if ax == 0 else [x0, a0 + c0, x1, a0 + c1]
                pieces[r].append(np.array(rect, dtype=np.int64))
        return pieces

    def _partition(self, pieces, rects, tris) -> Partition:
        spans, onscreen = pixel_spans(rects, self.size)
        on = np.flatnonzero(onscreen)
        sp = spans.T
        lo_x, lo_y, hi_x, hi_y = (sp[i].take(on) for i in range(4))  # on-screen objects only
        tris = np.asarray(tris, dtype=np.int64)
        tris_on = tris.take(on)
        k, n = len(pieces), len(tris)
        prects, pvis, regions = [], [], np.zeros((k, 4), dtype=np.int64)
        loads, visible = np.zeros(k, dtype=np.int64), np.zeros((k, n), dtype=bool)
        for r, plist in enumerate(pieces):  # ranks, not objects
            pr = np.array(plist, dtype=np.int64).reshape(-1, 4)
            hit = (lo_x < pr[:, 2:3]) & (hi_x >= pr[:, 0:1]) & (lo_y < pr[:, 3:4]) & (hi_y >= pr[:, 1:2])
            m = np.zeros((len(pr), n), dtype=bool)
            m[:, on] = hit
            prects.append(pr)
            pvis.append(m)
            if len(pr):
                regions[r] = [pr[:, 0].min(), pr[:, 1].min(), pr[:, 2].max(), pr[:, 3].max()]
                visible[r, on] = hit.any(axis=0)
                loads[r] = int(np.broadcast_to(tris_on, hit.shape).sum(where=hit))
        # no spans: only the cost model reads a partition's, from its own strips partitions
        return Partition(regions, loads, visible, np.zeros(max(k - 1, 0)), np.zeros(max(k - 1, 0), dtype=np.int64),
                         None, tuple(prects), tuple(pvis))

    def _integers(self, tris) -> bool:
        """Whether ``tris`` holds integers (the compiled plan's weights), kept when it is an
        array: the planner passes the same array every frame, checked once."""
        if tris.__class__ is np.ndarray and tris.dtype.kind in "iu":
            self._integer = tris
            return True
        return np.asarray(tris).dtype.kind in "iu"

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        features = partition.features
        self._flat = features if features is not None and "owner" in features else None
        pieces = partition.pieces
        self._pieces = pieces if pieces is not None else tuple(partition.regions[:, None])  # one (1, 4) piece per rank
        self._times = np.array(times, dtype=np.float64)  # a copy: the caller's buffer changes

    def report(self) -> dict:
        return {"name": self.name, "segment_shares": [round(float(v), 3) for v in self.shares]}
