"""Balancing strategies behind one small interface, registered in one place.

A strategy has two hooks, like Equalizer's equalizers: ``plan`` before the frame (rects and
triangle counts in, a ``Partition`` out) and ``observe`` after it (the measured per-rank
render times, for strategies that learn from them); ``report`` says what it learned, for
summary.json. Strategies are pure: no MPI, no GL. Every rank runs its own copy on the same
gathered inputs, so all copies take the same decisions.

* ``strips``: Dong & Peng's GPU-tree strip balancer on triangle counts.
* ``cost``: the same tree and strips on a fitted cost ``a*triangles + b*pixels (+ c)``.
* ``time``: Equalizer-style time feedback (splits moved by measured times, damped).
* ``adaptive``: ``cost`` with a per-object correction learned from measured times.
* ``none``: each rank renders its own display tile.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .balance import Partition, SplitTask, partition, partition_tiles, tree_partition
from .regions import pixel_spans


@dataclass
class Strategy:
    """Common configuration; subclasses add ``plan(rects, tris, coverage=None) -> Partition``
    (``coverage``: per-object silhouette fraction of the rect, for strategies that count
    pixels)."""

    grid: tuple[int, int]
    size: tuple[int, int]
    strips: int = 2048

    name = "base"
    needs_coverage = False  # whether ``plan`` wants per-object silhouette coverage

    def observe(self, partition: Partition, render_ms: np.ndarray) -> None:
        """Take the frame's measured per-rank render times (ms). Default: ignore them."""

    def report(self) -> dict:
        """What the strategy decided or learned (for summary.json)."""
        return {"name": self.name}


class Strips(Strategy):
    """Dong & Peng's GPU-tree strip balancer on triangle counts."""

    name = "strips"

    def plan(self, rects, tris, coverage=None):
        return partition(rects, tris, self.grid, self.size, self.strips)


class NoBalance(Strategy):
    """The paper's baseline: each rank renders exactly its own display tile."""

    name = "none"

    def plan(self, rects, tris, coverage=None):
        return partition_tiles(rects, tris, self.grid, self.size)


def rank_pixels(rects: np.ndarray, visible: np.ndarray, regions: np.ndarray, size,
                coverage: np.ndarray | None = None) -> np.ndarray:
    """(K,) pixels each rank fills by the rect estimate: its visible objects' rects clipped to
    its region, times their silhouette ``coverage`` (fraction of the rect, default 1), summed
    (overlapping objects count once each: depth complexity). A (M, N) ``coverage`` gives (K, M):
    several weightings of the same clipped areas in one pass."""
    spans, _ = pixel_spans(rects, size)
    sp = spans.T  # (4, N) int32
    cov = None if coverage is None else np.asarray(coverage, dtype=np.float64)
    out = np.zeros((len(regions),) + (() if cov is None or cov.ndim == 1 else cov.shape[:1]))
    for k, (x0, y0, x1, y1) in enumerate(regions):  # K ranks, not objects
        idx = np.flatnonzero(visible[k])
        w = np.minimum(sp[2].take(idx), x1 - 1) - np.maximum(sp[0].take(idx), x0) + 1
        h = np.minimum(sp[3].take(idx), y1 - 1) - np.maximum(sp[1].take(idx), y0) + 1
        area = np.maximum(w, 0).astype(np.float64) * np.maximum(h, 0)
        out[k] = area.sum() if cov is None else cov.take(idx, axis=-1) @ area
    return out


@dataclass
class CostModel(Strategy):
    """Balance ``a*triangles + b*pixels``, the coefficients fitted online from measured times.

    Every frame records, per rank, the triangles it drew, the pixels its objects' rects cover
    in its region, and its measured render time. Least squares over the last ``window``
    frames (``time = a*tris + b*pixels + c``) gives new coefficients, blended into the current
    ones with ``damping`` so the splits do not oscillate. A term is kept only while it is
    positive, explains at least ``min_share`` of the predicted time and is determined to
    within ``max_rel_se`` (relative standard error); without the pixel term the plan is
    exactly ``strips`` (triangle-bound scenes pay only the feature bookkeeping).
    """

    window: int = 30
    damping: float = 0.3
    min_share: float = 0.05
    max_rel_se: float = 0.5
    warmup: int = 3

    name = "cost"
    needs_coverage = True

    def __post_init__(self):
        self._samples: deque = deque(maxlen=self.window)
        self._features: tuple[np.ndarray, np.ndarray] | None = None
        self.coef = np.array([1.0, 0.0, 0.0])  # a (per triangle), b (per pixel), c
        self.kept = ["triangles"]
        self.why = "warming up: balancing on triangles until enough frames are measured"
        self.history: list[tuple[str, ...]] = []

    def plan(self, rects, tris, coverage: np.ndarray | None = None):
        a, b = self.coef[0], self.coef[1]
        cov = np.ones(len(tris)) if coverage is None else np.nan_to_num(np.asarray(coverage, np.float64))
        if "pixels" in self.kept and b > 0:
            # only the ratio matters: a triangle weighs 1 and a covered pixel b / a triangles
            weights, fill = (tris, cov * (b / a)) if a > 0 else (np.zeros(len(tris)), cov)
            p = partition(rects, weights, self.grid, self.size, self.strips, fill=fill)
            if a <= 0:  # loads stay triangle counts
                p = Partition(p.regions, p.visible @ np.asarray(tris, np.int64), p.visible, p.splits, p.split_pixels)
        else:
            p = partition(rects, tris, self.grid, self.size, self.strips)
        self._features = (p.loads.astype(np.float64), rank_pixels(np.asarray(rects, np.float64), p.visible,
                                                                   p.regions, self.size, cov))
        return p

    def observe(self, partition: Partition, render_ms: np.ndarray) -> None:
        if self._features is None:
            return
        tri, px = self._features
        self._samples.append(np.column_stack([tri, px, np.asarray(render_ms, np.float64)]))
        if len(self._samples) >= self.warmup:
            self._fit(np.concatenate(self._samples))
        self.history.append(tuple(self.kept))

    def _fit(self, data: np.ndarray) -> None:
        y = data[:, 2]
        cols = {"triangles": data[:, 0], "pixels": data[:, 1]}
        terms = ["triangles", "pixels"]
        while True:  # drop terms until every kept one is positive, material and stable
            X = np.column_stack([*(cols[t] for t in terms), np.ones_like(y)])
            scale = np.maximum(np.abs(X).max(axis=0), 1e-300)
            beta, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
            beta = beta / scale
            dof = max(len(y) - X.shape[1], 1)
            resid = y - X @ beta
            sigma2 = float(resid @ resid) / dof
            try:
                cov = sigma2 * np.linalg.inv(X.T @ X)
                se = np.sqrt(np.maximum(np.diag(cov), 0.0))
            except np.linalg.LinAlgError:
                se = np.full(X.shape[1], np.inf)
            pred = X @ beta
            verdicts = {}
            for i, t in enumerate(terms):
                share = float(np.mean(beta[i] * X[:, i]) / max(np.mean(pred), 1e-12))
                rel = float(se[i] / beta[i]) if beta[i] > 0 else np.inf
                verdicts[t] = (beta[i] > 0 and share >= self.min_share and rel <= self.max_rel_se, share, rel)
            bad = [t for t in terms if not verdicts[t][0]]
            if not bad or len(terms) == 1:
                break
            # drop the weakest failing term and refit
            terms.remove(min(bad, key=lambda t: verdicts[t][1]))
        new = np.zeros(3)
        for i, t in enumerate(terms):
            new[0 if t == "triangles" else 1] = max(beta[i], 0.0)
        new[2] = beta[-1]
        if new[0] <= 0 and new[1] <= 0:  # nothing explains the time: stay on triangles
            new[0] = 1.0
        self.coef = (1 - self.damping) * self.coef + self.damping * new
        if "pixels" not in terms:
            self.coef[1] = 0.0
        self.kept = terms if verdicts[terms[0]][0] else ["triangles"]
        self.why = "; ".join(f"{t}: share {v[1]:.1%}, rel. s.e. {v[2]:.2f}, {'kept' if t in self.kept else 'dropped'}"
                             for t, v in verdicts.items())

    def report(self) -> dict:
        frames = max(len(self.history), 1)
        pixel_frames = sum("pixels" in h for h in self.history)
        return {"name": self.name, "terms": list(self.kept), "coef_ms": {"per_triangle": float(self.coef[0]),
                "per_pixel": float(self.coef[1]), "per_rank": float(self.coef[2])}, "why": self.why,
                "pixel_term_frames_share": pixel_frames / frames}


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

    def __post_init__(self):
        super().__post_init__()
        self.corr: np.ndarray | None = None
        self._pred: np.ndarray | None = None
        self._visible: np.ndarray | None = None

    def plan(self, rects, tris, coverage: np.ndarray | None = None):
        tris = np.asarray(tris)
        n = len(tris)
        if self.corr is None or len(self.corr) != n:
            self.corr = np.ones(n)
        a, b, c = self.coef
        cov = np.ones(n) if coverage is None else np.nan_to_num(np.asarray(coverage, np.float64))
        use_px = "pixels" in self.kept and b > 0
        weights = tris * self.corr * (1.0 if a > 0 or not use_px else 0.0)
        fill = cov * self.corr * (b / a if a > 0 else 1.0) if use_px else None
        p = partition(rects, weights, self.grid, self.size, self.strips, fill=fill)
        vis = p.visible
        loads = vis @ tris.astype(np.int64)
        p = Partition(p.regions, loads, vis, p.splits, p.split_pixels)
        px, px_corr = rank_pixels(np.asarray(rects, np.float64), vis, p.regions, self.size,
                                  np.stack([cov, cov * self.corr])).T
        self._features = (loads.astype(np.float64), px)  # the fit sees raw features
        self._pred = a * (vis @ (tris * self.corr)) + b * px_corr + c
        self._visible = vis
        return p

    def observe(self, partition: Partition, render_ms: np.ndarray) -> None:
        super().observe(partition, render_ms)
        if self._pred is None or len(self._samples) < self.warmup:
            return
        t = np.asarray(render_ms, dtype=np.float64)
        pred = np.maximum(self._pred, 1e-9)
        if not (np.isfinite(t).all() and (t > 0).all()):
            return
        log_s = np.log(t / pred)
        log_s -= log_s.mean()  # relative error only
        vis = self._visible
        count = vis.sum(axis=0)
        seen = count > 0
        step = (log_s @ vis)[seen] / count[seen]  # mean log error over the ranks that drew it
        self.corr[seen] *= np.exp(self.rate * step)
        np.clip(self.corr, 1.0 / self.limit, self.limit, out=self.corr)

    def report(self) -> dict:
        doc = super().report()
        if self.corr is not None:
            q = np.percentile(self.corr, [5, 50, 95])
            doc["correction_p5_p50_p95"] = [float(v) for v in q]
        return doc


def time_chooser(regions: np.ndarray, times: np.ndarray, prev_cuts: np.ndarray | None, damping: float):
    """Split chooser from the last frame's measured times: each rank's time is spread evenly
    over its region (Equalizer's assumption); the cut balances the time on either side in
    the ratio of the ranks, then moves only ``damping`` of the way from the previous cut."""
    regions = np.asarray(regions, dtype=np.float64)
    density = np.asarray(times, dtype=np.float64) / np.maximum(
        (regions[:, 2] - regions[:, 0]) * (regions[:, 3] - regions[:, 1]), 1.0)

    def choose(t: SplitTask, spans: np.ndarray) -> int:
        ax, ot = t.axis, 1 - t.axis
        r0, r1 = regions[:, ax], regions[:, ax + 2]
        o = np.clip(np.minimum(regions[:, ot + 2], t.reg[ot + 2]) - np.maximum(regions[:, ot], t.reg[ot]), 0, None)
        w = density * o  # time per pixel along the axis, per old region
        c = t.cuts.astype(np.float64)[:, None]
        below = np.clip(np.minimum(c, r1) - np.maximum(t.a, r0), 0, None) @ w
        total = float(np.clip(np.minimum(t.b, r1) - np.maximum(t.a, r0), 0, None) @ w)
        if total <= 0:
            return t.target
        with np.errstate(divide="ignore", invalid="ignore"):
            diff = np.abs(below / (total - below) - t.nl / t.nr)
        diff[~t.valid | (below <= 0) | (total - below <= 0)] = np.inf
        if not np.isfinite(diff.min()):
            return t.target
        cut = int(t.cuts[int(np.argmin(diff))])
        if prev_cuts is not None:
            old = int(prev_cuts[t.n])
            cut = int(round(old + damping * (cut - old)))
        return cut

    return choose


@dataclass
class TimeFeedback(Strategy):
    """Equalizer's load equalizer, as the state-of-the-art baseline: no scene knowledge, the
    splits follow the previous frame's measured render times with ``damping``."""

    damping: float = 0.5

    name = "time"

    def __post_init__(self):
        self._last: Partition | None = None
        self._times: np.ndarray | None = None

    def plan(self, rects, tris, coverage=None):
        if self._last is None:
            return partition(rects, tris, self.grid, self.size, self.strips)
        choose = time_chooser(self._last.regions, self._times, self._last.split_pixels, self.damping)
        return tree_partition(rects, tris, self.grid, self.size, self.strips, choose)

    def observe(self, partition: Partition, render_ms: np.ndarray) -> None:
        self._last, self._times = partition, np.asarray(render_ms, dtype=np.float64).copy()


REGISTRY: dict[str, type[Strategy]] = {cls.name: cls for cls in (Strips, CostModel, TimeFeedback, Adaptive, NoBalance)}


def make_strategy(name: str, grid, size, strips: int) -> Strategy:
    if name not in REGISTRY:
        raise ValueError(f"unknown balancing strategy '{name}' (known: {', '.join(REGISTRY)})")
    return REGISTRY[name](tuple(grid), tuple(size), strips)
