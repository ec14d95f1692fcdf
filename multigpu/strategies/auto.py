"""``auto``: picks per scene, from measured frames, between ``cross`` and ``strips`` (``shares``
on walls of ``BIG_WALL`` ranks or more).

No single strategy wins everywhere (docs/RESULTS.md, payoff): cross-segment balancing leads on
scenes of many small objects, the paper's strips on scenes of few large or triangle-bound
objects, where cross's extra pieces draw objects twice. ``auto`` runs a short trial (windows of
``window`` frames, the candidates alternating, up to ``rounds`` windows each), plans with the
winner for ``hold`` frames, then tries again. A re-check that keeps the candidate in use doubles
the hold that follows (up to ``max_hold``), a switch restores ``hold``: on a long flight whose
winner does not change, the frames re-checks spend on the loser become rare. The first
``settle`` frames of a window are not scored (a time-feedback strategy settling after a switch).

Scoring. The camera keeps moving during a trial, so a frame's time says as much about where the
camera looks as about who planned it. Each scored frame's slowest-rank render time ``y`` is
therefore compared through its load ``x``, the triangles of every object in view (the same for
every candidate: it comes from the projected rects, before any partition): least squares of
``log y = a_candidate + b log(1 + x)`` over the trial's frames. ``a`` is a candidate's time at a
common load; the one with the lowest wins. ``b`` is dropped (plain mean log times) where the
loads do not vary or the fit gives a slope no renderer has (outside 0..2). Rounds also run in
mirrored pairs (A B, then B A, A the candidate in use), so a trend the load does not explain
costs both the same over a pair. The trial ends early, after any whole pair, once the best
candidate is ahead of every other by ``z`` standard errors of the difference: the frames planned
by a clear loser are what a trial costs. Only one candidate plans a frame, so balancing costs
what the chosen one costs; every candidate learns from every frame's times, so none goes cold.
Every rank sees the same gathered times and rects, so every rank decides alike.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from multigpu.core import jit
from multigpu.core.balance import Partition
from multigpu.strategies import auto_kernel
from multigpu.strategies.base import Configured
from multigpu.strategies.cross import CrossSegment
from multigpu.strategies.shares import Shares
from multigpu.strategies.strips import Strips

#: decisions kept in the report (the latest ones)
REPORT_TRIALS = 8
#: walls of at least this many ranks try ``shares`` instead of ``strips``
BIG_WALL = 9


@dataclass
class Auto(Configured):
    """Chooses cross or strips (shares on big walls) per scene from trial frames, and re-checks
    every ``hold`` frames."""

    window: int = 8  # frames per trial window
    settle: int = 2  # first frames of a window not scored
    rounds: int = 4  # most windows per candidate per trial (rounds run in mirrored pairs)
    hold: int = 200  # frames the winner plans between trials (after a switch)
    max_hold: int = 800  # the longest hold, reached by doubling after trials that keep the choice
    z: float = 2.5  # a trial ends after a round once the best leads by this many standard errors

    name = "auto"
    summary = ('chooses cross or strips (shares on walls of 9+ ranks) per scene from trial frames, and checks '
               'again now and then')
    reproducible = False  # it follows measured times

    def __post_init__(self):
        if (not 0 <= self.settle < self.window or self.rounds < 1 or not 0 <= self.hold <= self.max_hold
                or not self.z > 0):
            raise ValueError("auto: need 0 <= settle < window, rounds >= 1, 0 <= hold <= max_hold, z > 0")
        args = (self.grid, self.size, self.strips, self.compiled)
        # on big walls the strips' second candidate learns each rank's share (``experiment sixteen``:
        # render imbalance 1.39 against strips' 1.58 on 16 ranks); smaller walls keep the paper's strips
        big = int(self.grid[0]) * int(self.grid[1]) >= BIG_WALL
        self.candidates = (CrossSegment(*args), (Shares if big else Strips)(*args))
        # the candidates that learn from measured times (a no-op ``observe`` is not called per frame)
        self._learners = tuple(c for c in self.candidates if type(c).observe is not Configured.observe)
        self.chosen = 0  # cross until a trial says otherwise
        self._hold = self.hold  # the hold after the current trial
        self._step = 0  # plans made in the current cycle (trial, then hold)
        self._trial_end: int | None = None  # the step the current trial ended at (None: trialling)
        self._made: deque = deque(maxlen=16)  # (partition, candidate, load or None) of recent trial plans
        self._scores: list[tuple[int, float, float]] = []  # (candidate, load, slowest time) of scored frames
        self.trials: deque = deque(maxlen=REPORT_TRIALS)
        self.frames = [0] * len(self.candidates)  # frames each candidate planned
        self._compiled = jit.use(self.compiled)  # the trial's load in one compiled pass

    @property
    def round_frames(self) -> int:
        return self.window * len(self.candidates)

    def _window(self, step: int) -> tuple[int, bool]:
        """The candidate planning trial step ``step`` and whether the frame is scored: rounds
        in mirrored pairs (even rounds in order, odd rounds reversed), the order starting with
        the candidate in use, so a trial that confirms it has switched only for the windows
        the others needed."""
        k = len(self.candidates)
        at = (step % self.round_frames) // self.window
        at = at if (step // self.round_frames) % 2 == 0 else k - 1 - at
        return (self.chosen + at) % k, step % self.window >= self.settle

    @property
    def trial_frames(self) -> int:
        """The longest a trial runs (``rounds`` whole rounds)."""
        return self.round_frames * self.rounds

    def plan(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Partition:
        step, end = self._step, self._trial_end
        if end is None:  # trialling (a trial ends early only after whole mirrored pairs)
            if step and (step >= self.trial_frames or (step % (2 * self.round_frames) == 0 and self._clear())):
                self._decide()
                self._trial_end = end = step
        i, scored = self._window(step) if end is None else (self.chosen, False)  # trialling, or holding the choice
        part = self.candidates[i].plan(rects, tris, coverage)
        if end is None:  # a trial plan is remembered for its score (holding, nothing is scored)
            self._made.append((part, i, self._load(rects, tris) if scored else None))
        self.frames[i] += 1
        self._step = step = step + 1
        if end is not None and step >= end + self._hold:
            self._step, self._trial_end = 0, None
        return part

    def _load(self, rects: np.ndarray, tris: np.ndarray) -> float:
        """A scored frame's load: the triangles in view (NaN rects are the unseen objects);
        compiled where it can be (numpy's masked sum: ~75 us for 6,690 objects, caches warm)."""
        if self._compiled:
            return auto_kernel.seen_triangles(rects, tris)
        return float(np.sum(tris, where=rects[:, 0] == rects[:, 0]))

    def effects(self) -> tuple[np.ndarray, np.ndarray, float | None]:
        """Each candidate's log time at the trial's mean load, their covariance and the load
        slope (None: dropped) from the scored frames; NaN effects where a candidate has none."""
        k = len(self.candidates)
        cand = np.array([c for c, _, _ in self._scores], dtype=np.int64)
        lx = np.log1p(np.array([x for _, x, _ in self._scores]))
        ly = np.log(np.maximum(np.array([y for _, _, y in self._scores]), 1e-9))
        seen = self._counts() > 0
        A = np.zeros((len(cand), k + 1))
        A[np.arange(len(cand)), cand] = 1.0
        A[:, k] = lx - lx.mean() if len(lx) else 0.0
        cols = np.flatnonzero(np.r_[seen, True])
        coef, slope = self._fit(A[:, cols], ly)
        if slope is None or not 0.0 <= slope <= 2.0:  # no load term (flat loads or an implausible slope)
            cols = cols[:-1]
            coef, slope = self._fit(A[:, cols], ly)[0], None
        effects, cov = np.full(k, np.nan), np.full((k, k), np.inf)
        m = int(seen.sum())
        effects[seen] = coef[:m]
        n, p = A.shape[0], len(cols)
        if n > p:
            resid = ly - A[:, cols] @ coef
            inv = np.linalg.pinv(A[:, cols].T @ A[:, cols])
            s2 = float(resid @ resid) / (n - p)
            sel = np.flatnonzero(seen)
            cov[np.ix_(sel, sel)] = s2 * inv[:m, :m]
        return effects, cov, slope

    def _counts(self) -> np.ndarray:
        """Scored frames per candidate in the current trial."""
        return np.bincount([c for c, _, _ in self._scores], minlength=len(self.candidates))

    @staticmethod
    def _fit(A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float | None]:
        """Least-squares coefficients and the last one (the load slope) where the design has
        full rank (None: the loads are confounded or flat)."""
        coef, _, rank, _ = np.linalg.lstsq(A, y, rcond=None)
        return coef, (float(coef[-1]) if rank == A.shape[1] else None)

    def _clear(self) -> bool:
        """Whether the best candidate's effect leads every other's by ``z`` standard errors of
        the difference (every candidate with two scored frames at least)."""
        if self._counts().min() < 2:
            return False
        eff, cov, _ = self.effects()
        best = int(np.argmin(eff))
        for o in range(len(eff)):
            if o != best:
                se = np.sqrt(max(cov[o, o] + cov[best, best] - 2 * cov[o, best], 0.0))
                if not eff[o] - eff[best] > self.z * se:
                    return False
        return True

    def _decide(self) -> None:
        """The candidate with the lowest effect (ties and missing scores keep the current
        choice); the scores start afresh. The report gives each candidate's time at the
        trial's mean load (ms)."""
        eff, _, slope = self.effects() if self._scores else (np.full(len(self.candidates), np.nan), None, None)
        means = np.where(np.isnan(eff), np.inf, eff)
        best = int(np.argmin(means))
        if means[best] < means[self.chosen]:
            self.chosen, self._hold = best, self.hold
        elif self.trials:  # kept after a re-check: hold it longer (the first trial sets ``hold``)
            self._hold = min(2 * self._hold, self.max_hold)
        self.trials.append({"scores_ms": {c.name: round(float(np.exp(m)), 3) if np.isfinite(m) else None
                                          for c, m in zip(self.candidates, means)},
                            "load_slope": None if slope is None else round(slope, 3),
                            "chose": self.candidates[self.chosen].name, "frames": self._step, "hold": self._hold,
                            "scored": self._counts().tolist()})
        self._scores = []

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        for c in self._learners:  # every candidate learns from every frame
            c.observe(frame, partition, times)
        for n, (part, i, load) in enumerate(self._made):  # trial plans (none are added while holding)
            if part is partition:
                if load is not None:
                    self._scores.append((i, load, float(np.max(times))))
                for _ in range(n + 1):  # it and older plans (never observed now): their masks go
                    self._made.popleft()
                break

    def report(self) -> dict:
        return {"name": self.name, "using": self.candidates[self.chosen].name,
                "frames": {c.name: int(n) for c, n in zip(self.candidates, self.frames)},
                "trials": list(self.trials), "segment_shares": self.candidates[0].report()["segment_shares"]}
