"""The strategy contract: one small interface, like Equalizer's equalizers and IceT's strategies.

A strategy has three hooks: ``plan`` before the frame (object rects and triangle counts in, a
``Partition`` out), ``observe`` after it (the frame's measured per-rank render times, for
strategies that learn), ``report`` for summary.json. Strategies are pure (no MPI, no GL).
Every rank runs its own copy on the same gathered inputs, so all copies decide alike.
Strategies that learn from measured times (``cost``, ``time``, ``adaptive``, ``cross``) are
not bit-reproducible across reruns, since the times differ from run to run; the others
(``strips``, ``none``) are, and each strategy's ``reproducible`` flag says which.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from multigpu.core import jit
from multigpu.core.balance import Partition
from multigpu.core.regions import pixel_spans
from multigpu.strategies.base_kernel import rank_pixels as _compiled_pixels


@runtime_checkable
class Strategy(Protocol):
    """What the frame loop needs of a balancing strategy."""

    name: ClassVar[str]
    summary: ClassVar[str]  # one plain line (no markup) for --help and the docs
    needs_coverage: ClassVar[bool]  # whether ``plan`` wants per-object silhouette coverage
    reproducible: ClassVar[bool]  # same inputs, same partitions in every run

    def plan(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Partition:
        """This frame's partition from (N, 4) normalized rects and (N,) triangle counts."""

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        """Take frame ``frame``'s measured (K,) per-rank render times in ms."""

    def report(self) -> dict:
        """What the strategy decided or learned (for summary.json)."""


@dataclass
class Configured:
    """Common state of the built-in strategies: the wall and the strip count, default hooks."""

    grid: tuple[int, int]
    size: tuple[int, int]
    strips: int = 2048
    compiled: bool | None = None  # the compiled kernel (None: where numba is installed; False: numpy reference)

    name: ClassVar[str] = "base"
    needs_coverage: ClassVar[bool] = False
    reproducible: ClassVar[bool] = True

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        """Default: measured times are not used."""

    def report(self) -> dict:
        return {"name": self.name}


def coverage_of(coverage: np.ndarray | None, n: int) -> np.ndarray:
    """Per-object silhouette coverage as float64 (1 where unknown or not finite)."""
    if coverage is None:
        return np.ones(n)
    cov = np.asarray(coverage, dtype=np.float64)
    return cov if np.isfinite(cov).all() else np.nan_to_num(cov, nan=1.0, posinf=1.0, neginf=0.0)


def rank_pixels(rects: np.ndarray, visible: np.ndarray, regions: np.ndarray, size,
                coverage: np.ndarray | None = None, spans: np.ndarray | None = None,
                compiled: bool | None = None) -> np.ndarray:
    """(K,) pixels each rank fills by the rect estimate: its visible objects' rects clipped to
    its region, times their silhouette ``coverage`` (fraction of the rect, default 1), summed
    in object order (overlapping objects count once each: depth complexity). A (M, N)
    ``coverage`` gives (K, M): several weightings of the same clipped areas in one pass.
    ``spans`` (the partition's) saves recomputing the pixel spans. ``compiled`` (None: where
    numba is installed) runs ``base_kernel.py``, the same sums bit for bit."""
    sp = pixel_spans(rects, size)[0].T if spans is None else spans  # (4, N) int32, once per frame
    cov = None if coverage is None else np.asarray(coverage, dtype=np.float64)
    if jit.use(compiled):
        weights = np.ones((1, visible.shape[1])) if cov is None else np.atleast_2d(cov)
        out = np.empty((len(regions), weights.shape[0]))
        _compiled_pixels(np.ascontiguousarray(sp), visible, np.asarray(regions, dtype=np.int64),
                        np.ascontiguousarray(weights), out)
        return out[:, 0] if cov is None or cov.ndim == 1 else out
    out = np.zeros((len(regions),) + (() if cov is None or cov.ndim == 1 else cov.shape[:1]))
    for k, (x0, y0, x1, y1) in enumerate(regions):  # K ranks, not objects
        idx = np.flatnonzero(visible[k])
        w = np.minimum(sp[2].take(idx), x1 - 1) - np.maximum(sp[0].take(idx), x0) + 1
        h = np.minimum(sp[3].take(idx), y1 - 1) - np.maximum(sp[1].take(idx), y0) + 1
        area = np.maximum(w, 0).astype(np.float64) * np.maximum(h, 0)
        if cov is None:  # whole pixel counts: exact in any order
            out[k] = area.sum()
        elif idx.size:  # in object order, as the kernel adds them
            out[k] = np.cumsum(cov.take(idx, axis=-1) * area, axis=-1)[..., -1]
    return out
