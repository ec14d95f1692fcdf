"""``cost``: the strip balancer on a cost ``a*triangles + b*pixels (+ c)`` fitted online from
measured per-rank render times; the pixel term is kept only where the scene needs it."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from multigpu.core import jit
from multigpu.core.balance import Partition, partition
from multigpu.strategies.base import Configured, coverage_of, rank_pixels
from multigpu.strategies.cost_kernel import fit_terms

TERMS = ("triangles", "pixels")  # the fitted terms, in the order of ``fit_terms``' output


@dataclass
class CostModel(Configured):
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
    summary = 'splits by a*triangles + b*pixels, the coefficients fitted online from measured times'
    needs_coverage = True
    reproducible = False  # its coefficients are fitted to measured times

    def __post_init__(self):
        self._samples: deque = deque(maxlen=self.window)
        self.coef = np.array([1.0, 0.0, 0.0])  # a (per triangle), b (per pixel), c
        self.kept = ["triangles"]
        self.why = "warming up: balancing on triangles until enough frames are measured"
        self.observed = self.pixel_frames = 0  # frames learnt from, and those whose fit kept the pixel term

    def plan(self, rects, tris, coverage: np.ndarray | None = None):
        a, b = self.coef[0], self.coef[1]
        cov = coverage_of(coverage, len(tris))
        if "pixels" in self.kept and b > 0:
            # only the ratio matters: a triangle weighs 1 and a covered pixel b / a triangles
            weights, fill = (tris, cov * (b / a)) if a > 0 else (np.zeros(len(tris)), cov)
            p = partition(rects, weights, self.grid, self.size, self.strips, fill=fill, compiled=self.compiled)
            if a <= 0:  # loads stay triangle counts
                p = Partition(p.regions, p.visible @ np.asarray(tris, np.int64), p.visible, p.splits, p.split_pixels)
        else:
            p = partition(rects, tris, self.grid, self.size, self.strips, compiled=self.compiled)
        px = rank_pixels(np.asarray(rects, np.float64), p.visible, p.regions, self.size, cov, p.spans, self.compiled)
        return p._replace(features={"triangles": p.loads.astype(np.float64), "pixels": px})

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        """One sample per rank from the features of the partition it planned for ``frame``."""
        if partition.features is None:  # planned elsewhere (a broadcast partition)
            return
        tri, px = partition.features["triangles"], partition.features["pixels"]
        self._samples.append(np.column_stack([tri, px, np.asarray(times, np.float64)]))
        if len(self._samples) >= self.warmup:
            self._fit(np.concatenate(self._samples))
        self.observed += 1
        self.pixel_frames += "pixels" in self.kept

    def _fit(self, data: np.ndarray) -> None:
        """The fit of ``cost_kernel.py`` (compiled, or its plain-Python self: the same
        coefficients), blended into the current ones; numpy's where the system is singular."""
        fit = fit_terms if jit.use(self.compiled) else getattr(fit_terms, "py_func", fit_terms)
        out = np.empty(10)
        if not fit(np.ascontiguousarray(data, dtype=np.float64), float(self.min_share), float(self.max_rel_se), out):
            return self._fit_numpy(data)
        b_tri, b_px, b_c, *_, code = out.tolist()
        terms = [t for i, t in enumerate(TERMS) if int(code) >> i & 1]
        verdicts = {t: (out[7 + i] == 1.0, float(out[3 + i]), float(out[5 + i])) for i, t in enumerate(TERMS)
                    if t in terms}
        new = np.array([max(b_tri, 0.0) if "triangles" in terms else 0.0,
                        max(b_px, 0.0) if "pixels" in terms else 0.0, b_c])
        self._update(new, terms, verdicts)

    def _fit_numpy(self, data: np.ndarray) -> None:
        """The same fit in numpy, with the pseudo-inverse where the normal equations are singular."""
        y = data[:, 2]
        full = np.column_stack([data[:, 0], data[:, 1], np.ones_like(y)])  # triangles, pixels, 1
        scale = np.maximum(np.abs(full).max(axis=0), 1e-300)
        Xs = full / scale
        gram, rhs, yy = Xs.T @ Xs, Xs.T @ y, float(y @ y)  # the normal equations, formed once
        col = {"triangles": 0, "pixels": 1}
        terms = ["triangles", "pixels"]
        while True:  # drop terms until every kept one is positive, material and stable
            use = [col[t] for t in terms] + [2]
            G = gram[np.ix_(use, use)]
            try:
                inv = np.linalg.inv(G)
            except np.linalg.LinAlgError:
                inv = np.linalg.pinv(G)
            bs = inv @ rhs[use]
            beta = bs / scale[use]
            dof = max(len(y) - len(use), 1)
            sigma2 = max(yy - 2 * bs @ rhs[use] + bs @ G @ bs, 0.0) / dof  # residual sum of squares / dof
            se = np.sqrt(np.maximum(sigma2 * np.diag(inv), 0.0)) / scale[use]
            means = full[:, use].mean(axis=0) * beta  # mean contribution of each term
            pred = max(float(means.sum()), 1e-12)
            verdicts = {}
            for i, t in enumerate(terms):
                rel = float(se[i] / beta[i]) if beta[i] > 0 else np.inf
                share = float(means[i] / pred)
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
        self._update(new, terms, verdicts)

    def _update(self, new: np.ndarray, terms: list[str], verdicts: dict) -> None:
        """Blend the fitted coefficients ``new`` into the current ones; keep ``terms`` if the
        first passed its tests (``verdicts``: term -> (passed, share, rel. s.e.))."""
        if new[0] <= 0 and new[1] <= 0:  # nothing explains the time: stay on triangles
            new[0] = 1.0
        self.coef = (1 - self.damping) * self.coef + self.damping * new
        if "pixels" not in terms:
            self.coef[1] = 0.0
        self.kept = terms if verdicts[terms[0]][0] else ["triangles"]
        self.why = "; ".join(f"{t}: share {v[1]:.1%}, rel. s.e. {v[2]:.2f}, {'kept' if t in self.kept else 'dropped'}"
                             for t, v in verdicts.items())

    def report(self) -> dict:
        frames, pixel_frames = max(self.observed, 1), self.pixel_frames
        return {"name": self.name, "terms": list(self.kept), "coef_ms": {"per_triangle": float(self.coef[0]),
                "per_pixel": float(self.coef[1]), "per_rank": float(self.coef[2])}, "why": self.why,
                "pixel_term_frames_share": pixel_frames / frames}
