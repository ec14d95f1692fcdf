"""Where a composed tile goes each frame: the presenter (a window, or nothing headless), the
overlays and the operator's monitor of a window run, and the swap barrier that keeps every tile
of the wall in step. A part of the frame loop (``frames.Frames``) with one job.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.work import Work
from multigpu.rank.exchange import barrier
from multigpu.rank.timer import Timer
from multigpu.records.stops import STOP_FLAG

#: the longest sleep between tests of the swap barrier (s): every rank swaps within about as much of the last
#: one's arrival (the default 2 ms let the swap skew grow with frames in flight)
SWAP_POLL = 1e-4


class Showing:
    """Rank ``comm``'s display: ``presenter`` (``display.make_presenter``), ``stereo`` packing
    (None: mono), ``live`` (a window run's overlays and monitor, or None); ``window``: whether
    tiles swap in step (the barrier, bounded by ``timeout``); ``projector``: a projector wall's
    output of this rank (``rank/outputs.py``), whose picture of the tile is what is shown."""

    def __init__(self, comm, presenter, stereo, live, window: bool, timeout: float, projector=None):
        self.comm, self.presenter, self.stereo, self.live = comm, presenter, stereo, live
        self.window, self.timeout, self.projector = window, timeout, projector

    @property
    def picture(self) -> np.ndarray | None:
        """The last frame's picture of a projector output (row 0 at the bottom), else None."""
        return None if self.projector is None else self.projector.picture

    def present(self, t: Timer, back: np.ndarray, work: Work, control, rows) -> tuple[float, int]:
        """Display: the composed tile ``back`` (and the overlays that are on) into the back buffer, the
        swap barrier (every tile composed before any swaps), the swap; then window events and
        the operator's monitor. Returns when the swap returned and the stop flag of a window
        event (0: none)."""
        with t.phase("display"):
            tile = back if self.stereo is None else self.stereo.pack(back)  # what the display shows
            shown = tile if self.live is None else self.live.tile(tile, work, control, rows)
            if self.projector is not None:  # warped, blended and coloured for its projector
                shown = self.projector.run(shown)
            self.presenter.show(shown)
        if self.window:
            with t.phase("swap_wait"):
                barrier(self.comm, self.timeout, SWAP_POLL)
        with t.phase("display"):
            swapped = self.presenter.swap()
            why = self.presenter.poll()
            if self.live is not None:
                seen = self.live.show_monitor(tile, work, control, rows)
                if seen and not why:
                    return swapped, STOP_FLAG.get(seen, STOP_FLAG["window closed (the monitor)"])
        return swapped, STOP_FLAG.get(why, 0)
