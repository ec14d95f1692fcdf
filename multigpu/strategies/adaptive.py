"""``adaptive``: ``cost`` with per-object corrections learned from measured times (not
bit-reproducible between runs: it follows the times each run measures)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multigpu.core import jit
from multigpu.core.balance import Partition, partition
from multigpu.strategies.adaptive_kernel import _object_sums, _rank_sums
from multigpu.strategies.base import coverage_of, rank_pixels
from multigpu.strategies.cost import CostModel


@dataclass
class Adaptive(CostModel):
    """``cost`` whose per-object costs are corrected by what each rank measured.

    The fitted model sees triangles and rect pixels; it cannot see depth complexity, shading
    or clipping cost, which differ between parts of a scene. After each frame, every rank's
    measured time over its predicted time (``s_k``, normalized by their geometric mean, so only
    the relative error is learned; the level stays the fit's job) multiplies the correction of
    the objects it drew, by ``rate`` in log space (objects drawn by several ranks take the mean
    of their logs). The correction rides with the objects to the next frame, where the camera
    has moved a little, so the splits follow costs the model cannot predict. Corrections are
    kept within [1/``limit``, ``limit``].
    """

    rate: float = 0.5
    limit: float = 8.0

    name = "adaptive"
    summary = 'cost, its per-object costs corrected by what each rank measured'
    reproducible = False  # it follows measured times, which differ between runs

    def __post_init__(self):
        super().__post_init__()
        self.corr: np.ndarray | None = None
        self._compiled = jit.use(self.compiled)  # the sums over the masks compiled (once, not per frame)

    def plan(self, rects, tris, coverage: np.ndarray | None = None):
        tris = np.asarray(tris)
        n = len(tris)
        if self.corr is None or len(self.corr) != n:
            self.corr = np.ones(n)
        a, b, c = self.coef
        cov = coverage_of(coverage, n)
        use_px = "pixels" in self.kept and b > 0
        weights = tris * self.corr * (1.0 if a > 0 or not use_px else 0.0)
        fill = cov * self.corr * (b / a if a > 0 else 1.0) if use_px else None
        p = partition(rects, weights, self.grid, self.size, self.strips, fill=fill, compiled=self.compiled)
        vis = p.visible
        loads, weighed = self._rank_sums(vis, tris.astype(np.int64), tris * self.corr)
        px, px_corr = rank_pixels(np.asarray(rects, np.float64), vis, p.regions, self.size,
                                  np.stack([cov, cov * self.corr]), p.spans, self.compiled).T
        # the fit sees raw features; the correction step, this partition's prediction
        features = {"triangles": loads.astype(np.float64), "pixels": px, "predicted": a * weighed + b * px_corr + c}
        return Partition(p.regions, loads, vis, p.splits, p.split_pixels, p.spans, features=features)

    def _rank_sums(self, vis: np.ndarray, tris: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per rank: the triangles it draws (int64 ``tris``) and its objects' corrected
        ``weights`` summed in object order (compiled: ``adaptive_kernel.py``, the same sums)."""
        k = len(vis)
        if self._compiled:
            loads, weighed = np.empty(k, dtype=np.int64), np.empty(k)
            _rank_sums(np.ascontiguousarray(vis), tris, np.ascontiguousarray(weights, dtype=np.float64), loads,
                       weighed)
            return loads, weighed
        weighed = np.cumsum(np.where(vis, weights, 0.0), axis=1)[:, -1] if vis.shape[1] else np.zeros(k)
        return vis @ tris, weighed

    def _object_sums(self, vis: np.ndarray, log_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per object: the log errors of the ranks that drew it summed in rank order, and how
        many did (compiled: ``adaptive_kernel.py``, the same sums)."""
        if self._compiled:
            sums, count = np.empty(vis.shape[1]), np.empty(vis.shape[1], dtype=np.int64)
            _object_sums(np.ascontiguousarray(vis), log_s, sums, count)
            return sums, count
        return np.cumsum(np.where(vis, log_s[:, None], 0.0), axis=0)[-1], vis.sum(axis=0)

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        super().observe(frame, partition, times)
        if partition.features is None or self.corr is None or len(self._samples) < self.warmup:
            return
        t = np.asarray(times, dtype=np.float64)
        pred = np.maximum(partition.features["predicted"], 1e-9)
        if not (np.isfinite(t).all() and (t > 0).all()):
            return
        log_s = np.log(t / pred)
        log_s -= log_s.mean()  # relative error only
        sums, count = self._object_sums(partition.visible, log_s)
        seen = count > 0
        step = sums[seen] / count[seen]  # mean log error over the ranks that drew it
        self.corr[seen] *= np.exp(self.rate * step)
        np.clip(self.corr, 1.0 / self.limit, self.limit, out=self.corr)

    def report(self) -> dict:
        doc = super().report()
        if self.corr is not None:
            q = np.percentile(self.corr, [5, 50, 95])
            doc["correction_p5_p50_p95"] = [float(v) for v in q]
        return doc
