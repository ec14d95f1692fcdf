"""The frame planner: one frame's ``Work`` from its camera, with no MPI and no GL.

It owns what planning needs across frames: the scene's bounds prepared for projection, the
wall's canvas (bezels), and one decomposition per balancing strategy (built from the
configuration through the decompositions' registry the first time it is used, so every rank
builds the same ones). ``plan(frame, camera)`` projects the bounds, balances, and moves the
work onto the canvas; ``observe(frame, times)`` hands the measured per-rank times of an earlier
frame to the decomposition that planned it, together with the work it planned then (keyed by
frame, as Equalizer's load equalizer keys its history), so no strategy learns from state a
later ``plan`` left behind. The frame loop, ``bench frame`` and the floor benchmark all plan
through this one class.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from multigpu.core.eyes import FOCUS_SAMPLES, Pose, eye_frames, focused, head_problem
from multigpu.core.projectors import make_projector
from multigpu.core.stereo import doubled, halved, make_stereo
from multigpu.core.work import Work
from multigpu.decompositions import REGISTRY
from multigpu.strategies import REGISTRY as STRATEGIES

#: planned frames kept for ``observe`` (a frame's times arrive one frame later)
KEEP = 8


def balances_of(cfg) -> list[str]:
    """What an operator cycles through (B, the page): every strategy of the screen decomposition,
    else just that decomposition; with ``--panel``, every strategy and every other decomposition
    this wall can run (``records.report.BALANCE_NAMES``' order), so the page switches either.
    Where the exchange may be a shared segment, sized once for the decomposition the run starts
    with, only those that fit its room are offered (no depth in a screen run's; a hybrid's holds
    them all): a page never costs the wall memory it did not ask for."""
    if cfg.panel is None or cfg.partition != "redundant":
        return list(STRATEGIES) if cfg.decomposition == "screen" else [cfg.decomposition]
    import dataclasses

    from multigpu.decompositions import REGISTRY

    own = REGISTRY[cfg.decomposition]
    fits = lambda k: cfg.exchange == "messages" or (k.depth <= own.depth and k.layers <= own.layers)  # noqa: E731
    modes = list(STRATEGIES) if fits(REGISTRY["screen"]) else []
    for name, kind in REGISTRY.items():
        if name == "screen" or not fits(kind):
            continue
        try:  # a decomposition this wall cannot run (too few bins) is left out: the door's InputError
            dataclasses.replace(cfg, decomposition=name)
        except ValueError:
            continue
        modes.append(name)
    return modes


def mode_of(cfg, name: str) -> tuple[str, str]:
    """(decomposition, strategy) of an entry of ``balances_of``: a strategy balances the screen
    decomposition; a decomposition balances with ``--balance`` (where it balances)."""
    return ("screen", name) if name in STRATEGIES else (name, cfg.balance)


def most_of(cfg, balances) -> tuple[bool, int]:
    """Whether any of ``balances`` composites by depth, and the most layers any needs: what the
    exchange must make room for when the operator may switch between them."""
    from multigpu.decompositions import REGISTRY

    kinds = [REGISTRY[mode_of(cfg, b)[0]] for b in balances]
    return any(k.depth for k in kinds), max(k.layers for k in kinds)


def screen_rects(screens, canvas) -> np.ndarray:
    """(S, 4) canvas rect of each screen: the bounding rect of its tiles."""
    tiles = canvas.tiles()
    return np.array([[tiles[list(sc.tiles), 0].min(), tiles[list(sc.tiles), 1].min(), tiles[list(sc.tiles), 2].max(),
                      tiles[list(sc.tiles), 3].max()] for sc in screens], dtype=np.int64).reshape(-1, 4)


def on_canvas(rect, size) -> np.ndarray:
    """The clip-space map taking a screen's own NDC onto its ``rect`` of the whole canvas."""
    from multigpu.core.camera import region_clip

    return np.linalg.inv(region_clip(rect, size))


def clipped(rects: np.ndarray, rect, size) -> np.ndarray:
    """Normalized ``rects`` cut to the canvas ``rect`` (NaN where they miss it)."""
    W, H = size
    box = np.asarray(rect, dtype=np.float64) / np.array([W, H, W, H])
    out = np.concatenate([np.maximum(rects[:, :2], box[:2]), np.minimum(rects[:, 2:], box[2:])], axis=1)
    with np.errstate(invalid="ignore"):
        out[~((out[:, 2] > out[:, 0]) & (out[:, 3] > out[:, 1]))] = np.nan
    return out


def cut_at(work: Work, screens: np.ndarray) -> Work:
    """``work``'s pieces cut at the screens' rects, each part knowing its screen (``Work.views``),
    a hybrid's front pieces first still."""
    rects, masks, views, front = [], [], [], None if work.front is None else [0] * work.ranks
    for k in range(work.ranks):  # ranks, not objects
        R = np.asarray(work.rects[k], dtype=np.int64).reshape(-1, 4)
        lo = np.maximum(R[:, None, :2], screens[None, :, :2])
        hi = np.minimum(R[:, None, 2:], screens[None, :, 2:])
        p, s = np.nonzero((hi > lo).all(axis=-1))  # (piece, screen), by piece
        rects.append(np.concatenate([lo[p, s], hi[p, s]], axis=1))
        masks.append(work.masks[k][p] if len(work.masks[k]) == len(R) else work.masks[k])
        views.append(s.tolist())
        if front is not None:
            front[k] = int(np.count_nonzero(p < work.front[k]))
    return work._replace(rects=tuple(rects), masks=tuple(masks), front=None if front is None else tuple(front),
                         views=tuple(views))


def eye_config(cfg, stereo):
    """``cfg`` as one eye's wall: its tile and bezels at the eye's pixels, mono (what the
    decompositions plan from; a stereo projector wall's warps are the display's, not the plan's)."""
    import dataclasses

    return dataclasses.replace(cfg, tile=stereo.eye.tile, mullion=stereo.eye.mullion, stereo="mono", eyes="joint",
                               head=None, head_poses=None, poses=(), mpcdi=None, mpcdi_right=None)


def focus_of(scene) -> tuple[np.ndarray, np.ndarray]:
    """What ``core.eyes.focused`` needs of a scene: its centre, and (M, 4) float32 homogeneous
    positions about it of every k-th vertex (``FOCUS_SAMPLES`` at most)."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.bounds)
    centre = (lo + hi) / 2
    step = max(1, -(-len(scene.vertices) // FOCUS_SAMPLES))
    pts = scene.vertices[::step, :3].astype(np.float64) + (np.asarray(scene.origin, dtype=np.float64) - centre)
    return centre, np.c_[pts, np.ones(len(pts))].astype(np.float32)


class Planner:
    """Plans frames for one rank of a ``WalkConfig`` wall (``rank`` None: every rank's masks)."""

    def __init__(self, cfg, scene, rank: int | None = None):
        self.cfg, self.scene, self.rank = cfg, scene, rank
        # a stereo wall plans on one eye's canvas and both eyes render the plan (core/stereo.py)
        self.stereo = make_stereo(cfg.stereo, cfg.canvas, cfg.eyes == "own")
        self.plan_cfg = cfg if self.stereo is None else eye_config(cfg, self.stereo)
        # eye decomposition (``--eyes``, ``WalkConfig.eyes_split``): half the ranks a screen plan, each eye's half
        # drawing it
        self.halves = None if not cfg.eyes_split else cfg.grid if cfg.eyes == "own" else halved(cfg.grid)
        self._split: set[int] = set()  # the strategies (``balances`` indices) built for half the ranks
        self.canvas = self.plan_cfg.canvas
        self.viewer = cfg.viewer  # None: the camera's own frustum
        self.views: list = []  # the last frame's (view, proj, light) of every eye through every screen, [eye][screen]
        # the screens the eyes look through (a CAVE's: one per plane), each a rect of the canvas
        self.screens = self.viewer.planes(cfg.ranks) if self.viewer is not None else ()
        self.screen_rects = screen_rects(self.screens, self.canvas)
        # a wall of no given size: the zero-parallax plane at the scene's centre (``core.eyes.focused``)
        self.focus = focus_of(scene) if cfg.focus else None
        self.canvas_rects = None  # the last frame's object rects on the canvas, where bezels make them differ
        self.pose = None  # a tracked head's newest pose (``rank/head_link.py``): before the pose file's
        self.head_offset = (0.0, 0.0, 0.0)  # metres the keys moved the head from its pose (an interactive run)
        self.bezels = self.canvas.cuts  # without bezels or dark tiles the visible space is the canvas: no calls
        self.balances = balances_of(cfg)
        self.using = self.balances.index(cfg.balance if cfg.decomposition == "screen" else cfg.decomposition)
        self.depth, self.layers = most_of(cfg, self.balances)  # the room the exchange makes
        self._built: dict[int, object] = {}
        self._d = None  # the decomposition in use, once built (``use`` clears it): no lookups per frame
        self.size = self.canvas.size
        self._planned: dict[int, tuple[object, Work]] = {}
        self.project = make_projector(scene, cfg.bounds)
        self.coverage = np.ones(scene.n_objects)  # per-object silhouette coverage, for strategies that use it
        # triangles per object, formed once (``scene.tris`` divides every object's index count:
        # ~12 us of CPU per frame with the caches cold)
        self.tris = scene.tris

    def rescene(self, scene) -> None:
        """Plan ``scene`` from the next frame on (a series' next step): its bounds, triangles and
        the decompositions' per-scene state made anew (each at its first use); frames planned
        before keep theirs."""
        self.scene = scene
        self.project = make_projector(scene, self.cfg.bounds)
        self.coverage = np.ones(scene.n_objects)
        self.tris = scene.tris  # (the zero-parallax plane stays where the first step put it)
        self._built.clear()
        self._split.clear()
        self._d = None

    @property
    def decomposition(self):
        """The decomposition planning with the strategy in use (built at its first use)."""
        d = self._built.get(self.using)
        if d is None:
            name, balance = mode_of(self.cfg, self.balances[self.using])
            if self.halves is not None and name == "screen":  # one eye's half of the ranks (``stereo.doubled``)
                half = self.halves[0] * self.halves[1]  # one eye's ranks
                d = REGISTRY[name].from_config(self.plan_cfg, self.scene, balance,
                                               None if self.rank is None else self.rank % half, grid=self.halves)
                self._split.add(self.using)
            else:
                d = REGISTRY[name].from_config(self.plan_cfg, self.scene, balance, self.rank)
            self._built[self.using] = d
        self._d = d
        return d

    def use(self, i: int) -> None:
        """Plan with strategy ``balances[i]`` from the next frame on."""
        self.using = int(i)
        self._d = None

    def frame(self, camera, f: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(view, proj, light, rects) of ``camera`` on the canvas: the (N, 4) normalized object
        rects in the visible space (NaN: not seen), and the coverage too where the
        decomposition in use wants it. Compiled, matrices and rects come from one kernel call,
        into the projector's own arrays: valid through the next call, not longer. With a viewer
        (``f``: the frame, for its head pose) see ``_viewed``."""
        d = self._d or self.decomposition
        if self.viewer is not None:
            return self._viewed(camera, f, d)
        view, proj, light, rects = self.project.frame(camera, self.size, self.coverage if d.needs_coverage else None)
        return view, proj, light, self.visible(rects)

    def visible(self, rects: np.ndarray) -> np.ndarray:
        """The canvas ``rects`` in the visible space (kept as ``canvas_rects`` where they differ:
        a render scale below 1 widens by them, ``resample.Widen``)."""
        if not self.bezels:
            return rects
        self.canvas_rects = rects
        return self.canvas.to_visible(rects)

    def _viewed(self, camera, f: int, d):
        """A viewer's frame: each eye's off-axis matrices (``views``, the first returned), and
        every object's rect over all eyes (their union: a region's objects are those either eye
        sees in it, so one plan serves both)."""
        poses = self.cfg.poses
        pose = self.pose or (poses[min(f, len(poses) - 1)] if poses else None)
        if any(self.head_offset):  # the keys moved the head from where it is (at home without a pose)
            base = pose or self.viewer.head or Pose(tuple(self.viewer.home(camera)))
            moved = replace(base, position=tuple(float(v) for v in np.add(base.position, self.head_offset)))
            pose = moved if head_problem(moved, self.viewer, self.cfg.ranks) is None else base  # never behind a screen
        viewer = self.viewer if self.focus is None else focused(self.viewer, camera, *self.focus, self.size)
        self.views = eye_frames(camera, viewer, pose, 1 if self.stereo is None else 2, self.cfg.ranks)
        several = len(self.screens) > 1
        if several:  # each screen's frustum onto its own rect of the canvas
            self.views = [[(v, on_canvas(r, self.size) @ p, li) for (v, p, li), r in zip(eye, self.screen_rects)]
                          for eye in self.views]  # eyes, screens
        rects = None
        for eye in self.views:  # eyes
            for (view, proj, _), rect in zip(eye, self.screen_rects):  # screens
                r = self.project(view, proj, self.coverage if d.needs_coverage and rects is None else None)
                if several:  # a screen's frustum shows only its own tiles
                    r = clipped(r, rect, self.size)
                rects = r if rects is None else np.concatenate([np.fmin(rects[:, :2], r[:, :2]),
                                                                np.fmax(rects[:, 2:], r[:, 2:])], axis=1)
        view, proj, light = self.views[0][0]
        return view, proj, light, self.visible(rects)

    def work(self, frame: int, rects: np.ndarray, relay: Callable | None = None,
             tris: np.ndarray | None = None) -> Work:
        """Frame ``frame``'s work on the canvas from its visible ``rects``. ``relay`` (screen
        only): called with a thunk that computes the partition, it returns the partition to use
        (``--partition broadcast``: rank 0 computes it, every rank receives it). ``tris``: the
        triangles each object draws this frame (its level of detail; None: as modelled)."""
        d, tris = self._d or self.decomposition, self.tris if tris is None else tris
        if relay is not None:
            cov = self.coverage if d.needs_coverage else None
            work = d.from_partition(relay(lambda: d.partition(rects, tris, cov)), tris)
        else:
            work = d.plan(frame, rects, tris, self.coverage) if d.needs_coverage else d.plan(frame, rects, tris)
        if self.bezels:
            work = self.canvas.to_canvas(work, rects, tris)
        if len(self.screens) > 1:  # each part drawn through its screen's frustum
            work = cut_at(work, self.screen_rects)
        if self.using in self._split:  # each eye's half of the ranks the same pieces
            work = doubled(work)
        planned = self._planned
        planned[frame] = (d, work)
        if len(planned) > KEEP:  # the oldest (frames are planned in order)
            del planned[next(iter(planned))]
        return work

    def plan(self, frame: int, camera, relay: Callable | None = None) -> tuple[Work, tuple]:
        """Frame ``frame``'s work and its (view, proj, light)."""
        view, proj, light, rects = self.frame(camera, frame)
        return self.work(frame, rects, relay), (view, proj, light)

    def observe(self, frame: int, times: np.ndarray) -> None:
        """The measured (K,) per-rank render times of ``frame``, to the decomposition that
        planned it, with the work it planned (a frame not planned here is ignored)."""
        got = self._planned.pop(frame, None)
        planned = self._planned
        while planned and (oldest := next(iter(planned))) < frame:  # older frames (planned first) will not be observed
            del planned[oldest]
        if got is not None:
            d, work = got
            if work.eyes is not None:  # split by eye: a region's time is its slower eye's
                half = work.ranks // 2
                times = np.maximum(times[:half], times[half:])
            d.observe(frame, work, times)

    def report(self) -> dict:
        return self.decomposition.report()
