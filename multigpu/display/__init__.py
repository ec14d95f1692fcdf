"""Where a composed tile goes: nowhere (headless) or a window on the tile's display.

A presenter is the frame loop's last phase (the paper's Display component) behind one small
interface: ``show(tile)`` puts the composed tile in the back buffer, ``swap()`` makes it visible
and returns when it did, ``poll()`` reads window events without waiting and says why the run
should stop (Escape, a closed window) or None. The window presenter also gives the rank its GL
context, so rendering and presenting share one context. The frame loop puts a barrier between
``show`` and ``swap`` (the software swap barrier), so no tile shows frame f+1 before every tile
has composed it.
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np


class Presenter(Protocol):
    mode: str
    context: object | None  # a GL context the renderer should use, or None for its own (EGL)

    def show(self, tile: np.ndarray) -> None:
        """Put the composed (th, tw, 3) uint8 tile, row 0 at the bottom, in the back buffer."""

    def swap(self) -> float:
        """Make it visible; the wall-clock moment (``time.time()``) the swap returned."""

    def poll(self) -> str | None:
        """Window events, never waiting: why the run should stop, or None."""

    def close(self) -> None:
        """Close the window (safe to call twice)."""


class Headless:
    """No display: the composed tile is the run's output (mosaics, video) and nothing else."""

    mode = "headless"
    context = None

    def show(self, tile: np.ndarray) -> None:
        pass

    def swap(self) -> float:
        return time.time()

    def poll(self) -> str | None:
        return None

    def close(self) -> None:
        pass


def make_presenter(mode: str, rank: int, tile_size: tuple[int, int], position: tuple[int, int],
                   display: str | None, where: str, fullscreen: bool = False,
                   right: tuple[int, int] | None = None) -> Presenter:
    """The presenter of ``mode`` for rank label ``rank``; ``where`` names the wall-file entry
    or flag behind ``display`` for error messages; ``fullscreen``: the window covers its
    screen from the top-left corner, above the other windows (the tile is the screen's size).
    ``right``: a passive stereo tile's right-eye output's place (``display/passive.py``): two
    windows of ``tile_size``, the left eye's at ``position``."""
    if mode == "headless":
        return Headless()
    from multigpu.display.window import Window

    if right is None:
        return Window(rank, tile_size, position, display, where, fullscreen=fullscreen)
    from multigpu.display.passive import Passive

    # each eye's output full screen at its own place (two outputs of one X screen); the right eye's
    # window swaps without waiting, just after the left eye's vsync swap (``Passive.swap``)
    left = Window(rank, tile_size, position, display, where, title=f"multigpu tile {rank} left eye",
                  fullscreen=fullscreen, origin=position)
    try:
        other = Window(rank, tile_size, right, display, where, title=f"multigpu tile {rank} right eye", vsync=False,
                       fullscreen=fullscreen, origin=right)
    except BaseException:
        left.close()
        raise
    return Passive(left, other)


class Monitor:
    """Rank 0's operator view (``--monitor``): one more window, with its own GL context; it
    never waits for vertical sync (the wall's swaps set the pace) and gives the rank's GL
    context back to ``tile`` after each frame."""

    def __init__(self, size: tuple[int, int], position: tuple[int, int], tile):
        from multigpu.display.window import Window

        self.tile = tile
        self.window = Window(0, size, position, None, "--monitor", title="multigpu monitor", vsync=False)
        tile.current()

    def present(self, img: np.ndarray) -> None:
        """Show ``img`` (bottom row first) at once."""
        self.window.current()
        try:
            self.window.show(img)
            self.window.swap()
        finally:
            self.tile.current()

    def poll(self) -> str | None:
        return self.window.poll()

    def close(self) -> None:
        self.window.close()


def take_input(*windows):
    """Controls that collect the keys and mouse of ``windows`` (rank 0's tile and monitor)."""
    import glfw

    from multigpu.display.controls import Controls

    controls = Controls(glfw)
    for w in windows:
        w.take_input(controls)
    return controls


def take_arrows(window):
    """The arrow keys of ``window`` (rank 0's tile in ``wall test``), collected between frames."""
    import glfw

    from multigpu.display.controls import Arrows

    arrows = Arrows(glfw)
    window.take_input(arrows)
    return arrows
