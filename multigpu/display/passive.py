"""A passive stereo tile's two outputs: a window per eye on the rank's X display.

A passive wall gives each tile two projectors (or monitors behind polarizing filters), one per
eye; one GPU drives both, as two outputs of one X screen. The rank shows its composed tile (the
left eye's picture beside the right eye's, ``core/stereo.py``) as two borderless windows, one at
each output's place (full screen there where the wall file says ``fullscreen``), and swaps
them in one refresh after the swap barrier: the left eye's with vsync, the right eye's just after
it without a second wait. The left eye's window
holds the GL context the rank renders in; the right eye's has its own, made current only to
show and swap (as the operator's monitor does).
"""

from __future__ import annotations

import numpy as np


class Passive:
    """Two windows, the ``left`` eye's and the ``right`` eye's (``display.window.Window``), shown
    as one presenter (``display.Presenter``)."""

    mode = "window"

    def __init__(self, left, right):
        self.left, self.right = left, right
        self.context = left.context
        self.display = left.display
        left.current()

    def show(self, tile: np.ndarray) -> None:
        """The composed (th, 2 tw, 3) tile: its left half to the left eye's output, its right half to the right's."""
        w = tile.shape[1] // 2
        self.left.show(tile[:, :w])
        self.right.current()
        try:
            self.right.show(tile[:, w:])
        finally:
            self.left.current()

    def swap(self) -> float:
        """Both eyes in one refresh: the left eye's window waits for the vertical blank, the
        right eye's (no vsync) swaps right after it, never a second wait."""
        took = self.left.swap()
        self.right.current()
        try:
            self.right.swap()
        finally:
            self.left.current()
        return took

    def poll(self) -> str | None:
        return self.left.poll() or self.right.poll()

    def take_input(self, controls) -> None:
        """Keys and mouse from the left eye's window (rank 0's)."""
        self.left.take_input(controls)

    def current(self) -> None:
        self.left.current()

    def close(self) -> None:
        self.right.close()
        self.left.close()
