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
from multigpu.rank.exchange import wait_all

#: position 3, target 3, up 3, fov, near, far, strategy index, partition, stats, orbiting
SIZE = 16


@dataclass(frozen=True)
class Control:
    """One frame's camera (None: the path's) and live settings, the same on every rank."""

    camera: Camera | None
    balance: int  # index into the cycle of strategies (0 when nothing cycles)
    partition: bool
    stats: bool
    orbiting: bool


class Steering:
    """The input phase on one rank; ``controls`` and ``navigator`` exist on rank 0 only
    (``navigator`` only for ``--path interactive``)."""

    def __init__(self, comm, timeout: float, n_balance: int, balance: int, controls=None, navigator=None,
                 offset=(0.0, 0.0, 0.0), interactive: bool = False):
        self.comm, self.timeout = comm, timeout
        self.controls, self.navigator = controls, navigator
        self.interactive = interactive
        self.offset = np.asarray(offset, dtype=np.float64)
        self.n_balance = max(n_balance, 1)
        self.state = np.zeros(SIZE)
        self.state[12] = balance
        self.last = time.perf_counter()
        self.recorded: Camera | None = None  # rank 0: this frame's camera in path-file coordinates

    def _read(self) -> None:
        """Rank 0: the input since the last frame into ``state``."""
        taken = self.controls.take()
        now = time.perf_counter()
        dt, self.last = now - self.last, now
        s = self.state
        s[12] = (int(s[12]) + taken.balance) % self.n_balance
        s[13] = (int(s[13]) + taken.partition) % 2
        s[14] = (int(s[14]) + taken.stats) % 2
        if taken.help:
            from multigpu.display.controls import HELP

            print(f"multigpu keys: {HELP}", flush=True)
        if self.navigator is not None:
            cam = self.navigator.step(taken.input, dt)
            self.recorded = cam
            s[0:3] = np.asarray(cam.position) + self.offset  # as CameraPath.translated does
            s[3:6] = np.asarray(cam.target) + self.offset
            s[6:9], s[9:12] = cam.up, (cam.fov, cam.near, cam.far)
            s[15] = float(self.navigator.orbiting)

    def next(self) -> Control:
        """This frame's control, agreed by every rank (one broadcast from rank 0)."""
        if self.comm.Get_rank() == 0:
            self._read()
        if self.comm.Get_size() > 1:
            wait_all([self.comm.Ibcast(self.state, root=0)], self.timeout, "input broadcast")
        s = self.state
        camera = None
        if self.interactive:
            camera = Camera(tuple(s[0:3]), tuple(s[3:6]), tuple(s[6:9]), float(s[9]), float(s[10]), float(s[11]))
        return Control(camera, int(s[12]), bool(s[13]), bool(s[14]), bool(s[15]))
