"""Speed for accuracy while the wall runs: each frame's render scale and level-of-detail bound.

``Controller`` holds a frame-rate target (``--target-fps``) the way Equalizer's DFR equalizer
does: it keeps ``load``, the share of a full-quality frame's cost asked for, and after each
measured frame moves it geometrically toward ``target / measured`` with a damping exponent (a
half of the way in log space: ``DAMPING``), from the median of the last three frames (one
slow frame does not move it) and not at all within a dead band of 5 % around the target, so it
neither oscillates nor leaves full quality while the target is met. ``load`` buys its cost half
in pixels, half in triangles: the render scale is ``load ** (1/4)`` (pixels ``sqrt(load)``), and
the level-of-detail bound grows from the user's ``--lod-error`` by up to ``MAX_LOD_PX`` pixels as
``sqrt(load)`` falls.

``Fidelity`` is a rank's per-frame choice: the controller's quality while the camera moves; the
full quality of a run without a target (``--render-scale``, ``--lod-error``) on a frame whose
camera is the last one's (the camera stopped: that frame is bit for bit what the run without the
target renders for it, and its time does not teach the controller); and each object's level
(``core/lod.py``), so the balancer counts the triangles drawn. Every rank makes the same choices:
the same cameras and the same landed timing rows. Pure; no MPI, no GL.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from multigpu.core.lod import LevelChooser
from multigpu.core.resample import MIN_SCALE

#: the most pixels the controller adds to the level-of-detail bound
MAX_LOD_PX = 8.0
#: the least share of a full frame's cost the controller asks for (the render scale reaches MIN_SCALE)
MIN_LOAD = MIN_SCALE ** 4
#: the exponent of each step toward the target where a frame's time is measured at most two frames
#: after its choice (``--latency`` 0 and 1); halved where it comes later, where 0.5 would oscillate
#: (tests/test_quality.py's simulated wall). On this machine's plant walk 0.5 held the target for
#: 47-49 % of frames, 0.25 for 37 % (its frames vary +-30 % unconstrained: docs/ACCURACY.md)
DAMPING = 0.5
#: no step while the measured frame is within this share of the target
BAND = 0.05
#: measured frames the controller takes the median of
WINDOW = 3
#: the controller's scales and bounds are multiples of 1/STEPS (of a side, of a pixel): timings.csv's
#: four decimals then give back the very frame (``experiment fidelity`` renders it again)
STEPS = 64
#: a run's first frames (setup's last costs, the first waits) teach the controller nothing
WARMUP = 2


@dataclass(frozen=True)
class Quality:
    """One frame's choice: its render scale, its level-of-detail bound (pixels), whether it is
    full quality (what the run renders without a target) and whether its camera moved since the
    last frame (a lossy wire is allowed only then: ``--compress-moving``)."""

    scale: float
    lod_px: float
    full: bool
    moving: bool = True


class Controller:
    """A frame-rate target held by trading pixels and triangles (module docstring)."""

    def __init__(self, target_fps: float, lag: int = 2, band: float = BAND, window: int = WINDOW):
        self.target_ms = 1e3 / float(target_fps)
        self.damping, self.band = DAMPING if lag <= 2 else DAMPING / 2, float(band)
        self.load = 1.0
        self.times: deque = deque(maxlen=int(window))

    def observe(self, frame_ms: float) -> None:
        """One measured frame period (ms) of a frame the controller chose."""
        if not (frame_ms > 0 and math.isfinite(frame_ms)):
            return
        self.times.append(float(frame_ms))
        ratio = self.target_ms / float(np.median(self.times))
        if abs(math.log(ratio)) <= math.log1p(self.band):
            return
        self.load = min(1.0, max(MIN_LOAD, self.load * ratio ** self.damping))

    def quality(self, scale: float, lod_px: float) -> Quality:
        """The quality ``load`` buys below the full one (``scale``, ``lod_px``)."""
        if self.load >= 1.0:
            return Quality(scale, lod_px, True)
        root = math.sqrt(self.load)
        s = max(MIN_SCALE, math.floor(scale * math.sqrt(root) * STEPS) / STEPS)
        extra = math.ceil(MAX_LOD_PX * (1.0 - root) / (1.0 - math.sqrt(MIN_LOAD)) * STEPS) / STEPS
        return Quality(min(s, scale), lod_px + extra, False)


class Fidelity:
    """A rank's per-frame quality: scale, levels of detail and the triangles they draw."""

    def __init__(self, scene, height: int, target_fps: float | None, scale: float = 1.0, lod_error: float = 0.0,
                 lag: int = 2):
        self.scale, self.lod_error = float(scale), float(lod_error)
        self.target_fps, self.lag = target_fps, lag
        self.controller = Controller(target_fps, lag) if target_fps else None
        self.chooser = LevelChooser(scene, height)
        self.last_camera = None
        self.chosen: dict[int, Quality] = {}  # frame -> its quality, until its time is observed

    def settings(self) -> tuple[float | None, float, float]:
        """(frame-rate target, render scale, level-of-detail bound) as set now."""
        return self.target_fps, self.scale, self.lod_error

    def set(self, target_fps: float | None, scale: float, lod_error: float) -> None:
        """New settings from the next frame on (the operator's page; every rank at the same
        frame): a new target starts its controller afresh."""
        if target_fps != self.target_fps:
            self.target_fps = target_fps
            self.controller = Controller(target_fps, self.lag) if target_fps else None
            self.chosen.clear()
        self.scale, self.lod_error = float(scale), float(lod_error)

    @property
    def active(self) -> bool:
        """Whether any frame may differ from an every-pixel, as-modelled one."""
        return self.controller is not None or self.scale != 1.0 or self.lod_error > 0

    def frame(self, f: int, camera, rects: np.ndarray | None = None, moves: bool = False
              ) -> tuple[Quality, np.ndarray | None, np.ndarray]:
        """Frame ``f``'s quality, each object's level (None: all as modelled) and triangles
        (``rects``: the frame's object rects, NaN where unseen: only seen objects are chosen for;
        ``moves``: the scene moves, so no frame is still)."""
        still = camera == self.last_camera and not moves
        moved = self.last_camera is not None and not still  # a run's first frame has not moved
        self.last_camera = camera
        if self.controller is None or still:
            q = Quality(self.scale, self.lod_error, True, moved)
        else:
            q = replace(self.controller.quality(self.scale, self.lod_error), moving=moved)
        if not still and self.controller is not None and f >= WARMUP:
            self.chosen[f] = q
            while len(self.chosen) > 16:  # frames whose times never came (a stopped run)
                del self.chosen[next(iter(self.chosen))]
        levels, tris = self.chooser.choose(camera, q.lod_px, rects)
        return q, levels, tris

    def landed(self, f: int, frame_ms: float) -> None:
        """The measured period of frame ``f`` (the mean over ranks), to the controller where it chose it."""
        if self.chosen.pop(f, None) is not None:
            self.controller.observe(frame_ms)
