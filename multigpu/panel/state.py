"""What the operator's page shows and what it asked for: the one place the frame loop and the
page's server thread meet.

The frame loop only ever hands things over (a row of numbers, a reference to a shrunk wall, a
status) under a lock held for a copy, and takes the page's commands from a queue that never
waits; the server thread reads at its own pace. So a page that is slow, gone, or hostile costs
the wall at most those copies. Pure: threads only, no sockets, no MPI.
"""

from __future__ import annotations

import queue
import threading
import time

import numpy as np

#: frames of plot history the page gets when it connects (the plots scroll over the newest)
HISTORY = 600
#: the newest events kept for a page that connects
MOST_EVENTS = 200
#: the plotted series before the per-rank ones: frame, fps, balance id, swap skew, imbalance; then each
#: rank's frame time (ms), then each rank's render CPU time (ms: how evenly the work was balanced)
SERIES = ("frame", "fps", "balance", "swap_skew_ms", "imbalance")


def width(ranks: int) -> int:
    """Numbers in one plot row of a ``ranks``-rank wall."""
    return len(SERIES) + 2 * ranks


def names(ranks: int) -> list[str]:
    """The plot row's numbers, by name."""
    return [*SERIES, *(f"frame_ms {k}" for k in range(ranks)), *(f"render_cpu_ms {k}" for k in range(ranks))]


def plot_rows(per: np.ndarray, col: dict) -> np.ndarray:
    """Frames' timing rows, (F, K, columns) in rank order (``col``: column name to index), as the
    page's plot rows (F, ``width(K)``), named by ``names``: the live run's and a finished one's."""
    n, ranks = per.shape[:2]
    frame_ms, render = per[:, :, col["frame_ms"]], per[:, :, col["rendering_cpu_ms"]]
    mean = render.mean(axis=1)
    out = np.empty((n, width(ranks)))
    out[:, 0] = per[:, 0, col["frame"]]
    out[:, 1] = 1e3 / np.maximum(frame_ms.max(axis=1), 1e-9)
    out[:, 2] = per[:, 0, col["balance"]]
    out[:, 3] = per[:, :, col["swap_skew_ms"]].max(axis=1)
    out[:, 4] = np.where(mean > 0, render.max(axis=1) / np.where(mean > 0, mean, 1.0), 1.0)
    out[:, len(SERIES):len(SERIES) + ranks] = frame_ms
    out[:, len(SERIES) + ranks:] = render
    return out


class PanelState:
    """The run as the page sees it. ``header``: the run's facts (scene, wall, strategy, ...);
    ``balances``: the strategies the page may switch between; ``ranks``: the wall's ranks."""

    def __init__(self, header: dict, balances: tuple[str, ...], ranks: int, events: list[str] | None = None,
                 history: int = HISTORY):
        self.header, self.balances, self.K = header, tuple(balances), ranks
        self.lock = threading.Lock()
        self.history = history
        self.plot = np.full((history, width(ranks)), np.nan)
        self.seq = 0  # plot rows ever added
        self.thumb: tuple[int, np.ndarray, object, int] | None = None  # (seq, image top row first, rects, shrink)
        self.thumb_seq = 0
        self.status: dict = {}
        self.events: list[tuple[float, str]] = [(time.time(), e) for e in (events or [])][-MOST_EVENTS:]
        self.events_total = len(events or [])  # events ever, the trimmed ones included
        self.summary: dict | None = None
        self.commands: queue.SimpleQueue = queue.SimpleQueue()
        self.clients = 0  # pages connected now (the server's count)
        self.changed = threading.Condition(self.lock)

    # -- the frame loop's side (rank 0)

    def add_row(self, values: np.ndarray) -> None:
        """One landed frame: ``SERIES``, each rank's frame time, each rank's render CPU time (ms)."""
        with self.lock:
            self.plot[self.seq % self.history] = values
            self.seq += 1

    def set_thumb(self, img: np.ndarray, rects, shrink: int) -> None:
        """The newest whole wall, shrunk ``shrink`` times (kept by reference: the caller made it
        for this and lets go of it), with the partition's ``rects`` in full-size pixels, bottom row
        first (the page draws them)."""
        with self.lock:
            self.thumb_seq += 1
            self.thumb = (self.thumb_seq, img, rects, shrink)

    def set_status(self, **status) -> None:
        with self.lock:
            self.status = {**self.status, **status}

    def event(self, text: str) -> None:
        """Something the operator should see as it happens (a recovery, a dark tile, a refusal)."""
        with self.lock:
            self.events.append((time.time(), text))
            self.events_total += 1
            del self.events[:-MOST_EVENTS]

    def events_since(self, seen: int) -> tuple[int, list]:
        """The events after the first ``seen`` ever (those still kept), and how many there were
        ever: a page counts events, not places in the trimmed list."""
        with self.lock:
            new = min(self.events_total - seen, len(self.events))
            return self.events_total, self.events[len(self.events) - new:] if new > 0 else []

    def finish(self, summary: dict) -> None:
        """The run's end: its summary, for the page to show."""
        with self.changed:
            self.summary = summary
            self.changed.notify_all()

    def take_commands(self) -> list:
        """The page's checked commands since the last call (never waits)."""
        got = []
        while True:
            try:
                got.append(self.commands.get_nowait())
            except queue.Empty:
                return got

    # -- the server's side

    def rows_since(self, seq: int, most: int | None = None) -> tuple[int, np.ndarray]:
        """The plot rows added after row ``seq`` (at most ``history``, and at most ``most`` of the
        oldest of them: the rest come on the next call), and the count up to the last returned."""
        with self.lock:
            n = self.seq
            first = max(seq, n - self.history)
            last = n if most is None else min(n, first + most)
            idx = np.arange(first, last) % self.history
            return last, self.plot[idx].copy()
