"""Flying a camera by hand: what the user did since the last frame in, one camera out.

Pure (no windows, no GL, no MPI), so it tests in one process; ``display`` turns keys and the
mouse into an ``Input``, rank 0 steps the ``Navigator`` once a frame and sends the camera to
every rank. Every speed is a fraction of the scene's size per second (a 0.2-unit dragon and
a 2 km track fly alike) and scales with the frame's duration, so a slow frame moves as far
as two quick ones. Two modes: walk (fly where you look, the mouse turns the view) and orbit
(around the scene's centre: the mouse and A/D turn around it, W/S come closer or back off).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from multigpu.core.camera import Camera

#: the movement actions an ``Input`` may hold (the display maps keys to them)
MOVES = ("forward", "back", "left", "right", "up", "down")
#: walk speed: this fraction of the scene's diagonal per second (shift: FAST times that)
WALK = 0.15
FAST = 4.0
#: one speed step (scroll wheel, + / -) multiplies the speed by this
STEP = 1.25
#: the most speed steps one frame applies (from the slowest speed to the fastest takes 73)
MOST_STEPS = 100
#: mouse turning, degrees per pixel dragged; keys turning in orbit mode, degrees per second
TURN = 0.25
ORBIT = 60.0
#: the view never comes closer than this to straight up or down (degrees)
POLE = 1.0
#: a frame longer than this moves as far as one of this length (a stall must not teleport)
MAX_DT = 0.1
#: the eye stays within this many scene diagonals of the centre
REACH = 100.0


@dataclass(frozen=True)
class Input:
    """What the user did since the last frame: movement actions held (or tapped) during it,
    the mouse dragged with a button held (pixels, x right, y down), shift held, speed steps
    taken (+1 faster, -1 slower each), and the orbit and reset keys pressed."""

    moves: frozenset = frozenset()
    drag: tuple[float, float] = (0.0, 0.0)
    fast: bool = False
    speed_steps: int = 0
    orbit: bool = False
    reset: bool = False


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _rotate(v: np.ndarray, axis: np.ndarray, degrees: float) -> np.ndarray:
    """``v`` turned about the unit ``axis`` (Rodrigues)."""
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    return v * c + np.cross(axis, v) * s + axis * float(axis @ v) * (1 - c)


class Navigator:
    """The live camera over a scene with bounds ``lo``..``hi``, starting at ``start`` (whose
    up, fov and near plane it keeps)."""

    def __init__(self, lo, hi, start: Camera):
        lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        self.centre = (lo + hi) / 2
        self.diag = max(float(np.linalg.norm(hi - lo)), 1e-12)
        self.start = start
        self.up = _unit(np.asarray(start.up, dtype=np.float64))
        self.speed = WALK * self.diag
        self.orbiting = False
        self.reset()

    def reset(self) -> None:
        self.position = np.asarray(self.start.position, dtype=np.float64).copy()
        self.forward = _unit(np.asarray(self.start.target, dtype=np.float64) - self.position)
        self.distance = float(np.linalg.norm(self.centre - self.position))
        if self.orbiting:
            self._look_at_centre()

    def _look_at_centre(self) -> None:
        d = self.centre - self.position
        self.distance = max(float(np.linalg.norm(d)), 1e-3 * self.diag)
        if float(np.linalg.norm(d)) > 0:
            self.forward = _unit(d)
        self._keep_off_pole()

    def _keep_off_pole(self) -> None:
        """Keep the view at least ``POLE`` degrees from the up axis (look_at needs a side)."""
        cos = float(self.forward @ self.up)
        limit = math.cos(math.radians(POLE))
        if abs(cos) > limit:
            side = self.forward - cos * self.up
            if np.linalg.norm(side) < 1e-12:  # exactly along up: lean towards any side
                side = np.cross(self.up, [1.0, 0.0, 0.0] if abs(self.up[0]) < 0.9 else [0.0, 1.0, 0.0])
            side = _unit(side)
            self.forward = _unit(side * math.sin(math.radians(POLE)) + self.up * math.copysign(limit, cos))

    def _turn(self, yaw: float, pitch: float) -> None:
        """Turn the view right by ``yaw`` and up by ``pitch`` degrees."""
        self.forward = _unit(_rotate(self.forward, self.up, -yaw))
        right = np.cross(self.forward, self.up)
        if np.linalg.norm(right) > 1e-12:
            cos = float(self.forward @ self.up)
            now = math.degrees(math.acos(max(-1.0, min(1.0, cos))))  # angle from up
            pitch = max(min(pitch, now - POLE), now - (180.0 - POLE))
            self.forward = _unit(_rotate(self.forward, _unit(right), pitch))
        self._keep_off_pole()

    def step(self, inp: Input, dt: float) -> Camera:
        """Apply one frame's input over ``dt`` seconds; the camera to render."""
        dt = min(max(float(dt), 0.0), MAX_DT)
        if inp.speed_steps:  # a flood of steps is as good as MOST_STEPS: the speed is bounded either way
            steps = max(-MOST_STEPS, min(MOST_STEPS, int(inp.speed_steps)))
            self.speed = min(max(self.speed * STEP ** steps, 1e-6 * self.diag), 10.0 * self.diag)
        if inp.reset:
            self.reset()
        if inp.orbit:
            self.orbiting = not self.orbiting
            if self.orbiting:
                self._look_at_centre()
        has = inp.moves.__contains__
        axis = lambda a, b: float(has(a)) - float(has(b))
        dx, dy = inp.drag
        if self.orbiting:
            self._turn(dx * TURN + axis("right", "left") * ORBIT * dt, -dy * TURN + axis("up", "down") * ORBIT * dt)
            rate = (FAST if inp.fast else 1.0) * self.speed / self.diag
            self.distance *= math.exp(-axis("forward", "back") * rate * dt * 3.0)
            self.distance = min(max(self.distance, 1e-4 * self.diag), REACH * self.diag)
            self.position = self.centre - self.forward * self.distance
        else:
            self._turn(dx * TURN, -dy * TURN)
            right = _unit(np.cross(self.forward, self.up))
            move = (self.forward * axis("forward", "back") + right * axis("right", "left")
                    + self.up * axis("up", "down"))
            self.position = self.position + move * (self.speed * (FAST if inp.fast else 1.0) * dt)
            off = self.position - self.centre
            far = float(np.linalg.norm(off))
            if far > REACH * self.diag:
                self.position = self.centre + off * (REACH * self.diag / far)
        return self.camera()

    def camera(self) -> Camera:
        """The camera now: target a little ahead, the far plane behind the whole scene."""
        ahead = max(self.distance if self.orbiting else 0.0, 0.05 * self.diag)
        reach = float(np.linalg.norm(self.position - self.centre)) + self.diag
        return Camera(tuple(self.position.tolist()), tuple((self.position + self.forward * ahead).tolist()),
                      tuple(self.up.tolist()), self.start.fov, self.start.near, max(self.start.far, reach))
