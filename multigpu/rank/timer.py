"""A frame's phases by name: wall clock (``perf_counter``), process CPU time and the rank's own
thread's CPU time of each (wall minus thread time: how long the rank waited in the phase, for
peers, the GL or a core).

``with timer.phase("render"): ...``; a phase entered twice in one frame adds up (the exchange
is split around the synchronization barrier). ``ms(name)`` and ``cpu_ms(name)`` read them;
``total_ms`` spans the first phase's start to the last one's end.

A phase is a small object with ``__enter__``/``__exit__`` rather than a generator context
manager: the clocks are read as the last step of entering and the first of leaving, so a
phase's CPU time holds its body and almost none of the timer's own steps (a generator's
resumption ran inside the window: with the caches cold after rendering, microseconds a phase).
"""

from __future__ import annotations

from time import perf_counter, process_time, thread_time


class _Phase:
    """One entry into a named phase (entered once)."""

    __slots__ = ("timer", "name", "w0", "c0", "t0")

    def __init__(self, timer: "Timer", name: str):
        self.timer, self.name = timer, name

    def __enter__(self) -> None:
        self.w0 = w0 = perf_counter()
        if self.timer.start is None:
            self.timer.start = w0
        self.t0 = thread_time()
        self.c0 = process_time()

    def __exit__(self, *exc) -> None:
        c1 = process_time()
        t1 = thread_time()
        t = self.timer
        t.end = end = perf_counter()
        name = self.name
        t.wall[name] = t.wall.get(name, 0.0) + (end - self.w0) * 1e3
        t.cpu[name] = t.cpu.get(name, 0.0) + (c1 - self.c0) * 1e3
        t.ran[name] = t.ran.get(name, 0.0) + (t1 - self.t0) * 1e3
        t.spans.append((name, self.w0, end))


class Timer:
    """The named phases of one frame on one rank."""

    def __init__(self):
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self.ran: dict[str, float] = {}  # the rank's own thread's CPU time
        self.spans: list[tuple[str, float, float]] = []  # (phase, start, end) in perf_counter seconds: the timeline
        self.start: float | None = None
        self.end = 0.0

    def phase(self, name: str) -> _Phase:
        """``with timer.phase(name):`` times its body into ``name``."""
        return _Phase(self, name)

    def ms(self, *names: str) -> float:
        """Wall-clock milliseconds spent in these phases."""
        return sum(self.wall.get(n, 0.0) for n in names)

    def cpu_ms(self, *names: str) -> float:
        """Process CPU milliseconds spent in these phases."""
        return sum(self.cpu.get(n, 0.0) for n in names)

    def waited_ms(self, *names: str) -> float:
        """Wall milliseconds of these phases the rank's thread did not run: waits for peers,
        for the GL's pixels, or for a core."""
        return sum(max(self.wall.get(n, 0.0) - self.ran.get(n, 0.0), 0.0) for n in names)

    def paused(self, seconds: float, name: str | None = None) -> None:
        """The run stood paused ``seconds`` (the operator's page) during this frame, in phase
        ``name`` if given: the frame's span, and that phase's wall time, leave it out."""
        if self.start is not None:
            self.start += seconds
        if name is not None and name in self.wall:
            self.wall[name] = max(self.wall[name] - seconds * 1e3, 0.0)

    @property
    def total_ms(self) -> float:
        return 0.0 if self.start is None else (self.end - self.start) * 1e3
