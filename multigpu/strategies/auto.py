"""``auto``: picks per scene, from measured frames, between ``cross`` and ``strips``.

No single strategy wins everywhere (docs/RESULTS.md, payoff): cross-segment balancing leads on
scenes of many small objects, the paper's strips on scenes of few large or triangle-bound
objects, where cross's extra pieces draw objects twice. ``auto`` runs a short trial (windows of
``window`` frames, the candidates alternating, up to ``rounds`` windows each), scores each
candidate by the mean slowest-rank render time of its frames (the first ``settle`` frames of a
window not counted: a time-feedback strategy settling after a switch), and plans with the winner
for ``hold`` frames before trying again. Rounds run in mirrored pairs (A B, then B A, A the
candidate in use): the camera keeps moving during a trial, and a scene growing heavier along the
path would otherwise always favour the candidate that goes first; over a pair a linear trend
costs both the same. The trial
ends early, after any whole pair, once the best candidate is ahead of every other by ``z``
standard errors of the difference of means: the frames planned by a clear loser are what a
trial costs (a wrong early call needs a difference small against the noise, which is a small
loss). Only one candidate plans a frame, so balancing costs what the chosen one costs; every
candidate learns from every frame's times, so none goes cold. Every rank sees the same gathered
times, so every rank decides alike.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from multigpu.core.balance import Partition
from multigpu.strategies.base import Configured
from multigpu.strategies.cross import CrossSegment
from multigpu.strategies.strips import Strips

#: decisions kept in the report (the latest ones)
REPORT_TRIALS = 8


@dataclass
class Auto(Configured):
    """Chooses cross or strips per scene from trial frames, and re-checks every ``hold`` frames."""

    window: int = 8  # frames per trial window
    settle: int = 2  # first frames of a window not scored
    rounds: int = 4  # most windows per candidate per trial (rounds run in mirrored pairs)
    hold: int = 200  # frames the winner plans between trials
    z: float = 2.5  # a trial ends after a round once the best leads by this many standard errors

    name = "auto"
    reproducible = False  # it follows measured times

    def __post_init__(self):
        if not 0 <= self.settle < self.window or self.rounds < 1 or self.hold < 0 or not self.z > 0:
            raise ValueError("auto: need 0 <= settle < window, rounds >= 1, hold >= 0, z > 0")
        args = (self.grid, self.size, self.strips, self.compiled)
        self.candidates = (CrossSegment(*args), Strips(*args))
        self.chosen = 0  # cross until a trial says otherwise
        self._step = 0  # plans made in the current cycle (trial, then hold)
        self._trial_end: int | None = None  # the step the current trial ended at (None: trialling)
        self._made: deque = deque(maxlen=16)  # (partition, candidate, scored) of recent plans
        self._scores: list[list[float]] = [[] for _ in self.candidates]
        self.trials: deque = deque(maxlen=REPORT_TRIALS)
        self.frames = np.zeros(len(self.candidates), dtype=np.int64)  # frames each candidate planned

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
        pair = 2 * self.round_frames  # a trial ends early only after whole mirrored pairs
        if self._trial_end is None and self._step and (self._step >= self.trial_frames or (
                self._step % pair == 0 and self._clear())):
            self._decide()
            self._trial_end = self._step
        if self._trial_end is None:
            i, scored = self._window(self._step)
        else:
            i, scored = self.chosen, False
        part = self.candidates[i].plan(rects, tris, coverage)
        self._made.append((part, i, scored))
        self.frames[i] += 1
        self._step += 1
        if self._trial_end is not None and self._step >= self._trial_end + self.hold:
            self._step, self._trial_end = 0, None
        return part

    def _clear(self) -> bool:
        """Whether the best mean scored time leads every other candidate's by ``z`` standard
        errors of the difference (every candidate with two scores at least)."""
        if min(len(s) for s in self._scores) < 2:
            return False
        means = np.array([np.mean(s) for s in self._scores])
        var_n = np.array([np.var(s, ddof=1) / len(s) for s in self._scores])  # squared standard errors
        best = int(np.argmin(means))
        others = np.arange(len(means)) != best
        return bool(np.all(means[others] - means[best] > self.z * np.sqrt(var_n[others] + var_n[best])))

    def _decide(self) -> None:
        """The candidate with the lowest mean scored time (ties and missing scores keep the
        current choice); the scores start afresh."""
        means = [float(np.mean(s)) if s else np.inf for s in self._scores]
        best = int(np.argmin(means))
        if means[best] < means[self.chosen]:
            self.chosen = best
        self.trials.append({"scores_ms": {c.name: round(m, 3) if np.isfinite(m) else None
                                          for c, m in zip(self.candidates, means)},
                            "chose": self.candidates[self.chosen].name, "frames": self._step,
                            "scored": [len(s) for s in self._scores]})
        self._scores = [[] for _ in self.candidates]

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        for c in self.candidates:  # every candidate learns from every frame
            c.observe(frame, partition, times)
        for n, (part, i, scored) in enumerate(self._made):
            if part is partition:
                if scored:
                    self._scores[i].append(float(np.max(times)))
                for _ in range(n + 1):  # it and older plans (never observed now): their masks go
                    self._made.popleft()
                break

    def report(self) -> dict:
        return {"name": self.name, "using": self.candidates[self.chosen].name,
                "frames": {c.name: int(n) for c, n in zip(self.candidates, self.frames)},
                "trials": list(self.trials), "segment_shares": self.candidates[0].report()["segment_shares"]}
