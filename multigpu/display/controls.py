"""Keys and mouse of rank 0's windows, collected between frames and handed over once a frame.

glfw calls back while ``poll_events`` runs (which never waits); ``Controls`` keeps what
happened since the last ``take``: movement keys held or tapped (a key pressed and released
within one frame still moves it for that frame), the mouse dragged with a button held, speed
steps, and the commands (orbit, reset, overlays, next strategy). The keys, as the help says:
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from multigpu.core.navigate import Input

HELP = ("W/S or Up/Down: forward/back; A/D or Left/Right: left/right; E/Q or PageUp/PageDown: up/down; "
        "mouse drag: turn; Shift: faster; +/- or the wheel: speed; O: orbit the centre; R: back to the start; "
        "P: partition overlay; I: statistics overlay; B / Shift+B: next / previous --balance; "
        "T: pause / resume a moving scene's time; [ / ]: its time back / on 1 s (Shift: 5 s); "
        "J/L, U/M, Y/N: the viewer's head left/right, up/down, nearer/farther (5 cm, Shift: 25 cm; a wall with a "
        "viewer); K: the head home; H: this help; Escape: quit")
#: metres a head key moves the viewer's head (Shift: five times as far)
HEAD_STEP = 0.05
#: seconds a scrub key moves a moving scene's time with Shift (1 without)
SCRUB_SHIFT = 5.0
#: the most speed steps one wheel event takes
MOST_WHEEL = 10


def _keymap(glfw) -> tuple[dict, dict]:
    moves = {glfw.KEY_W: "forward", glfw.KEY_UP: "forward", glfw.KEY_S: "back", glfw.KEY_DOWN: "back",
             glfw.KEY_A: "left", glfw.KEY_LEFT: "left", glfw.KEY_D: "right", glfw.KEY_RIGHT: "right",
             glfw.KEY_E: "up", glfw.KEY_PAGE_UP: "up", glfw.KEY_Q: "down", glfw.KEY_PAGE_DOWN: "down"}
    commands = {glfw.KEY_O: "orbit", glfw.KEY_R: "reset", glfw.KEY_HOME: "reset", glfw.KEY_P: "partition",
                glfw.KEY_I: "stats", glfw.KEY_B: "balance", glfw.KEY_H: "help", glfw.KEY_EQUAL: "faster",
                glfw.KEY_KP_ADD: "faster", glfw.KEY_MINUS: "slower", glfw.KEY_KP_SUBTRACT: "slower",
                glfw.KEY_J: "head-x", glfw.KEY_L: "head+x", glfw.KEY_M: "head-y", glfw.KEY_U: "head+y",
                glfw.KEY_Y: "head-z", glfw.KEY_N: "head+z", glfw.KEY_K: "head home", glfw.KEY_T: "scene pause",
                glfw.KEY_LEFT_BRACKET: "scene back", glfw.KEY_RIGHT_BRACKET: "scene on"}
    return moves, commands


@dataclass
class Taken:
    """One frame's input: the navigator's part, and the commands for the frame loop."""

    input: Input
    partition: int = 0  # times P was pressed
    stats: int = 0
    balance: int = 0  # strategy steps: +1 next, -1 previous
    help: bool = False
    head: tuple = (0.0, 0.0, 0.0)  # metres the viewer's head moved (room axes)
    head_home: bool = False  # the head back home before the move
    scene_pause: int = 0  # times T was pressed (a moving scene's time paused / resumed)
    scrub: float = 0.0  # seconds the scene's time was moved on (back: below 0)


class Controls:
    """Collects the input of the windows it is attached to (rank 0's tile and monitor)."""

    def __init__(self, glfw):
        self.glfw = glfw
        self.moves_of, self.commands_of = _keymap(glfw)
        self.held: set[str] = set()
        self.buttons = 0
        self.shift_held = False
        self.cursor: tuple[float, float] | None = None
        self._clear()

    def _clear(self) -> None:
        self.tapped: set[str] = set()
        self.drag = [0.0, 0.0]
        self.counts = {"orbit": 0, "reset": 0, "partition": 0, "stats": 0, "balance": 0, "help": 0, "speed": 0,
                       "head home": 0, "scene pause": 0}
        self.head = [0.0, 0.0, 0.0]
        self.scrub = 0.0
        self.shift = False

    def attach_mouse(self, window) -> None:
        """Mouse buttons, motion and wheel of ``window`` (its keys come through ``on_key``)."""
        g = self.glfw
        g.set_mouse_button_callback(window, self._on_button)
        g.set_cursor_pos_callback(window, self._on_cursor)
        g.set_scroll_callback(window, self._on_scroll)

    def on_key(self, window, key, scancode, action, mods) -> None:
        g = self.glfw
        shift = bool(int(mods) & g.MOD_SHIFT)
        self.shift = self.shift or shift
        if key in (g.KEY_LEFT_SHIFT, g.KEY_RIGHT_SHIFT):
            self.shift_held = action != g.RELEASE
            self.shift = self.shift or self.shift_held
            return
        if key in self.moves_of:
            move = self.moves_of[key]
            if action == g.PRESS:
                self.held.add(move)
                self.tapped.add(move)
            elif action == g.RELEASE:
                self.held.discard(move)
            return
        if action != g.PRESS:
            return
        what = self.commands_of.get(key)
        if what == "faster":
            self.counts["speed"] += 1
        elif what == "slower":
            self.counts["speed"] -= 1
        elif what == "balance":
            self.counts["balance"] += -1 if shift else 1
        elif what in ("scene back", "scene on"):
            self.scrub += (-1.0 if what == "scene back" else 1.0) * (SCRUB_SHIFT if shift else 1.0)
        elif what is not None and what.startswith("head") and what != "head home":
            self.head["xyz".index(what[-1])] += (-1 if what[4] == "-" else 1) * HEAD_STEP * (5 if shift else 1)
        elif what is not None:
            self.counts[what] += 1

    def _on_button(self, window, button, action, mods) -> None:
        if not 0 <= button < 32:  # glfw's are 0..7
            return
        bit = 1 << button  # the cursor's place comes from the motion events (queued in order with this one)
        self.buttons = self.buttons | bit if action == self.glfw.PRESS else self.buttons & ~bit

    def _on_cursor(self, window, x: float, y: float) -> None:
        if self.buttons and self.cursor is not None:
            self.drag[0] += x - self.cursor[0]
            self.drag[1] += y - self.cursor[1]
        self.cursor = (x, y)

    def _on_scroll(self, window, dx: float, dy: float) -> None:
        if math.isfinite(dy):
            self.counts["speed"] += int(round(max(-MOST_WHEEL, min(MOST_WHEEL, dy))))

    def take(self) -> Taken:
        """Everything since the last call; shift counts when held now or at any moment meanwhile."""
        c = self.counts
        fast = self.shift or self.shift_held
        nav = Input(frozenset(self.held | self.tapped), (self.drag[0], self.drag[1]), fast, c["speed"],
                    c["orbit"] % 2 == 1, c["reset"] > 0)
        got = Taken(nav, c["partition"], c["stats"], c["balance"], c["help"] > 0, tuple(self.head), c["head home"] > 0,
                    c["scene pause"], self.scrub)
        self._clear()
        return got


class Arrows:
    """The arrow keys of a window, collected between frames (``wall test``'s mullion nudges)."""

    def __init__(self, glfw):
        self.keys = {glfw.KEY_LEFT: "left", glfw.KEY_RIGHT: "right", glfw.KEY_UP: "up", glfw.KEY_DOWN: "down"}
        self.press = glfw.PRESS
        self.queue: list[str] = []

    def on_key(self, window, key, scancode, action, mods) -> None:
        if action == self.press and key in self.keys:
            self.queue.append(self.keys[key])

    def attach_mouse(self, window) -> None:
        """No mouse here."""

    def take(self) -> list[str]:
        got, self.queue = self.queue, []
        return got
