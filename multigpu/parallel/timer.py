"""A frame's phases by name: wall clock (``perf_counter``) and process CPU time of each.

``with timer.phase("render"): ...``; a phase entered twice in one frame adds up (the exchange
is split around the synchronization barrier). ``ms(name)`` and ``cpu_ms(name)`` read them;
``total_ms`` spans the first phase's start to the last one's end.
"""

from __future__ import annotations

import time
from contextlib import contextmanager


class Timer:
    """The named phases of one frame on one rank."""

    def __init__(self):
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self.start: float | None = None
        self.end = 0.0

    @contextmanager
    def phase(self, name: str):
        w0 = time.perf_counter()
        if self.start is None:
            self.start = w0
        c0 = time.process_time()  # the CPU clock read last here and first below: the phase's CPU
        try:                      # time holds its body, not the timer's own bookkeeping
            yield
        finally:
            c1 = time.process_time()
            self.end = time.perf_counter()
            self.wall[name] = self.wall.get(name, 0.0) + (self.end - w0) * 1e3
            self.cpu[name] = self.cpu.get(name, 0.0) + (c1 - c0) * 1e3

    def ms(self, *names: str) -> float:
        """Wall-clock milliseconds spent in these phases."""
        return sum(self.wall.get(n, 0.0) for n in names)

    def cpu_ms(self, *names: str) -> float:
        """Process CPU milliseconds spent in these phases."""
        return sum(self.cpu.get(n, 0.0) for n in names)

    @property
    def total_ms(self) -> float:
        return 0.0 if self.start is None else (self.end - self.start) * 1e3
