"""``auto``: picks per scene, from measured frames, between ``cross`` and ``strips``.

No single strategy wins everywhere (docs/RESULTS.md, payoff): cross-segment balancing leads on
scenes of many small objects, the paper's strips on scenes of few large or triangle-bound
objects, where cross's extra pieces draw objects twice. ``auto`` runs a short trial (windows of
``window`` frames, the candidates alternating, ``rounds`` windows each), scores each candidate
by the mean slowest-rank render time of its frames (the first ``settle`` frames of a window not
counted: a time-feedback strategy settling after a switch), and plans with the winner for
``hold`` frames before trying again. Only one candidate plans a frame, so balancing costs what
the chosen one costs; every candidate learns from every frame's times, so none goes cold.
Every rank sees the same gathered times, so every rank decides alike.
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
    rounds: int = 3  # windows per candidate per trial
    hold: int = 200  # frames the winner plans between trials

    name = "auto"
    reproducible = False  # it follows measured times

    def __post_init__(self):
        if not 0 <= self.settle < self.window or self.rounds < 1 or self.hold < 0:
            raise ValueError("auto: need 0 <= settle < window, rounds >= 1, hold >= 0")
        args = (self.grid, self.size, self.strips, self.compiled)
        self.candidates = (CrossSegment(*args), Strips(*args))
        self.chosen = 0  # cross until a trial says otherwise
        self._step = 0  # plans made in the current cycle (trial, then hold)
        self._made: deque = deque(maxlen=16)  # (partition, candidate, scored) of recent plans
        self._scores: list[list[float]] = [[] for _ in self.candidates]
        self.trials: deque = deque(maxlen=REPORT_TRIALS)
        self.frames = np.zeros(len(self.candidates), dtype=np.int64)  # frames each candidate planned

    @property
    def trial_frames(self) -> int:
        return self.window * self.rounds * len(self.candidates)

    def plan(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Partition:
        if self._step == self.trial_frames:
            self._decide()
        if self._step < self.trial_frames:
            i, pos = (self._step // self.window) % len(self.candidates), self._step % self.window
            scored = pos >= self.settle
        else:
            i, scored = self.chosen, False
        part = self.candidates[i].plan(rects, tris, coverage)
        self._made.append((part, i, scored))
        self.frames[i] += 1
        self._step += 1
        if self._step >= self.trial_frames + self.hold:
            self._step = 0
        return part

    def _decide(self) -> None:
        """The candidate with the lowest mean scored time (ties and missing scores keep the
        current choice); the scores start afresh."""
        means = [float(np.mean(s)) if s else np.inf for s in self._scores]
        best = int(np.argmin(means))
        if means[best] < means[self.chosen]:
            self.chosen = best
        self.trials.append({"scores_ms": {c.name: round(m, 3) if np.isfinite(m) else None
                                          for c, m in zip(self.candidates, means)},
                            "chose": self.candidates[self.chosen].name})
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
