"""The input phase of a window run: rank 0 reads keys and mouse, every rank gets one small message.

Rank 0 takes what its windows collected since the last frame (``display.controls``), steps
the hand-flown camera (``--path interactive``) and applies the commands (overlays, the next
strategy); one broadcast of ``SIZE`` doubles carries the frame's camera and settings to every
rank, so every tile renders the same camera and every rank switches strategy at the same
frame. The camera travels as float64 bits, and ``--record`` stores it in path-file
coordinates (before ``--offset``), so a replay of the recording computes the very same camera.
Nothing here waits for input: the controls only report what has already happened.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from multigpu.core.camera import Camera
from multigpu.core.navigate import Input
from multigpu.display.controls import Taken
from multigpu.rank.exchange import wait_all

#: position 3, target 3, up 3, fov, near, far, strategy index, partition, stats, orbiting, paused, frame-rate
#: target (0: none), render scale, level-of-detail bound, the page's thumbnail wanted this frame, the viewer's head
#: moved from its place by the keys (x, y, z metres), a moving scene's time (seconds) and whether it stands
SIZE = 26
#: seconds between the input phase's broadcasts while the run is paused (the page's commands read each time)
PAUSE_TICK = 0.05


@dataclass(frozen=True)
class Control:
    """One frame's camera (None: the path's) and live settings, the same on every rank."""

    camera: Camera | None
    balance: int  # index into the cycle of strategies (0 when nothing cycles)
    partition: bool
    stats: bool
    orbiting: bool
    quality: tuple = (None, 1.0, 0.0)  # frame-rate target (None: none), render scale, level-of-detail bound
    paused_s: float = 0.0  # seconds the run stood paused before this frame (no frame's time counts them)
    thumb: bool = False  # the operator's page wants a thumbnail of this frame (every rank sends its tile shrunk)
    head: tuple = (0.0, 0.0, 0.0)  # metres the keys moved the viewer's head from its place (a wall with a viewer)
    scene_time: float | None = None  # a moving scene's time this frame (None: the scene stands still)
    scene_paused: bool = False  # the operator holds the scene's time


class Steering:
    """The input phase on one rank; ``controls``, ``panel`` and ``navigator`` exist on rank 0
    only (``controls``: window runs; ``panel``: ``--panel``; ``navigator``: ``--path
    interactive``). ``balances``: the strategies cycled; ``quality``: the frame-rate target,
    render scale and level-of-detail bound at the start."""

    def __init__(self, comm, timeout: float, balances, balance: int, controls=None, navigator=None,
                 offset=(0.0, 0.0, 0.0), interactive: bool = False, panel=None, quality=(None, 1.0, 0.0),
                 clock=None):
        self.comm, self.timeout = comm, timeout
        self.controls, self.navigator, self.panel = controls, navigator, panel
        self.clock = clock  # a moving scene's ``core.motion.SceneClock`` (rank 0 steers it), or None
        self.interactive = interactive
        self.offset = np.asarray(offset, dtype=np.float64)
        self.balances = list(balances)
        self.n_balance = max(len(self.balances), 1)
        self.state = np.zeros(SIZE)
        self.state[12] = balance
        target, scale, lod = quality
        self.state[17:20] = (target or 0.0, scale, lod)
        self.last = time.perf_counter()
        self.recorded: Camera | None = None  # rank 0: this frame's camera in path-file coordinates
        self.last_control: Control | None = None  # the newest agreed control (what the page shows)
        self.stopping = lambda: False  # whether this rank was told to stop (``job.Job.interrupted``)

    def _taken(self) -> Taken:
        """Rank 0: the windows' input and the page's, as one."""
        taken = self.controls.take() if self.controls is not None else Taken(Input())
        if self.panel is None:
            return taken
        p = self.panel
        p.read()
        fly, a = p.flight(), taken.input
        taken.input = Input(a.moves | fly.moves, (a.drag[0] + fly.drag[0], a.drag[1] + fly.drag[1]), a.fast,
                            a.speed_steps + fly.speed_steps, a.orbit != fly.orbit, a.reset or fly.reset)
        moved, home = p.head_moves()
        if home:  # the page's home comes after the keys' moves: only its own move counts
            taken.head, taken.head_home = moved, True
        else:
            taken.head = tuple(k + m for k, m in zip(taken.head, moved))
        s = self.state
        if p.balance is not None:
            s[12] = self.balances.index(p.balance)  # checked by the page's protocol: one of these
            p.balance = None
        for i, name in enumerate(("target_fps", "render_scale", "lod_error")):
            if name in p.settings:
                value = p.settings.pop(name)
                s[17 + i] = 0.0 if value is None else value
        s[16] = float(p.paused)
        s[20] = float(p.wants())
        return taken

    def _read(self, frame: int) -> None:
        """Rank 0: the input since the last frame into ``state``."""
        taken = self._taken()
        if self.clock is not None:  # the page's and the keys' pauses and scrubs, then this frame's time
            scene = self.panel.scene if self.panel is not None else {}
            self.state[24] = self.clock.at(frame, taken.scene_pause, taken.scrub, scene.pop("time", None),
                                           scene.pop("pause", None))
            self.state[25] = float(self.clock.paused)
        now = time.perf_counter()
        dt, self.last = now - self.last, now
        s = self.state
        s[12] = (int(s[12]) + taken.balance) % self.n_balance
        s[13] = (int(s[13]) + taken.partition) % 2
        s[14] = (int(s[14]) + taken.stats) % 2
        if taken.head_home:
            s[21:24] = 0.0
        s[21:24] += taken.head
        if taken.help:
            from multigpu.display.controls import HELP

            print(f"multigpu keys: {HELP}", flush=True)
        if self.navigator is not None and not s[16]:  # paused: the camera stands (and no time passes for it)
            cam = self.navigator.step(taken.input, dt)
            self.recorded = cam
            s[0:3] = np.asarray(cam.position) + self.offset  # as CameraPath.translated does
            s[3:6] = np.asarray(cam.target) + self.offset
            s[6:9], s[9:12] = cam.up, (cam.fov, cam.near, cam.far)
            s[15] = float(self.navigator.orbiting)

    def next(self, frame: int = 0) -> Control:
        """This frame's control, agreed by every rank (one broadcast from rank 0). While the page
        has the run paused, every rank waits here, a broadcast each ``PAUSE_TICK``, until it
        resumes or stops it, or a signal reaches rank 0 (the frames in flight wait with it)."""
        began = None
        while True:
            if self.comm.Get_rank() == 0:
                self._read(frame)
                if self.state[16] and self.stopping():  # Ctrl-C or SIGTERM ends a pause: the frame
                    self.state[16] = 0.0  # loop then stops after this frame, as it does unpaused
            if self.comm.Get_size() > 1:
                wait_all([self.comm.Ibcast(self.state, root=0)], self.timeout, "input broadcast")
            if not self.state[16]:
                break
            began = began or time.perf_counter()
            if self.comm.Get_rank() == 0:
                time.sleep(PAUSE_TICK)
        paused = time.perf_counter() - began if began else 0.0
        s = self.state
        camera = None
        if self.interactive:
            camera = Camera(tuple(s[0:3]), tuple(s[3:6]), tuple(s[6:9]), float(s[9]), float(s[10]), float(s[11]))
        quality = (float(s[17]) or None, float(s[18]), float(s[19]))
        return Control(camera, int(s[12]), bool(s[13]), bool(s[14]), bool(s[15]), quality, paused, bool(s[20]),
                       (float(s[21]), float(s[22]), float(s[23])), float(s[24]) if self.clock else None, bool(s[25]))
