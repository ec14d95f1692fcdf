"""One rank's draw calls for a frame: the pieces of its ``Work``, each through its screen's
frustum, with the parts a piece needs culled first (``core/culling.py``) and the regions
widened below render scale 1 (``core/resample.py``); the pixels are read later
(``gpu.pending.Pending``). A part of the frame loop (``frames.Frames``) with one job.
"""

from __future__ import annotations

from multigpu.core.culling import PartCuller
from multigpu.core.resample import Widen, covered, scaled_size
from multigpu.core.work import Work
from multigpu.rank.timer import Timer


class Joined:
    """An eye's pieces drawn screen by screen (``Drawing.through``), read back in piece order."""

    def __init__(self, parts: list, n: int):
        self.parts, self.n = parts, n

    def read(self) -> list:
        out = [None] * self.n
        for idx, pending in self.parts:  # screens
            for i, got in zip(idx, pending.read()):
                out[i] = got
        return out


class Drawing:
    """The draw calls of rank ``rank``: ``renderer`` (``gpu.render``) over ``scene``, planned by
    ``planner`` on ``canvas`` (one eye's on a ``stereo`` wall); ``ahead``: frames in flight may
    leave their pixels in the renderer's ring. ``drawn``: the triangles the last call drew."""

    def __init__(self, scene, renderer, planner, canvas, stereo, rank: int, ahead: bool):
        self.renderer, self.planner, self.canvas, self.stereo = renderer, planner, canvas, stereo
        self.rank, self.ahead = rank, ahead
        self.culler = PartCuller(scene) if renderer.draws.parts else None  # objects cut into parts
        self.widen = Widen(canvas)
        self.drawn = 0

    def frame(self, t: Timer, work: Work, eyes: list | None, mono: tuple, rects, scale: float, levels):
        """The frame's draw calls: through the camera's ``mono`` (view, proj, light), or with a
        viewer each of the ``eyes`` (``Planner.views``) through its own frustums, this rank's eye
        alone where the ranks split by eye (a ring of framebuffers holds one pass)."""
        if eyes is None:
            return self.render(t, work, *mono, rects, scale, levels)
        pending, drawn = [], 0
        mine = None if work.eyes is None else work.eyes[self.rank]
        for e, screens in enumerate(eyes):  # eyes
            if mine is not None and e != mine:
                pending.append(None)
                continue
            pending.append(self.through(t, work, screens, rects, scale, levels))
            drawn += self.drawn
        self.drawn = drawn
        return pending if self.stereo is not None else pending[0]  # a tracked mono wall: one eye

    def through(self, t: Timer, work: Work, screens: list, rects, scale: float, levels):
        """One eye's pieces drawn, each through its screen's frustum (``screens``: the eye's (view,
        proj, light) through each; ``Work.views``: each piece's); read later, in piece order."""
        # one pass a frame (mono, or one eye of a wall split by eye): the ring may hold it
        alone = (self.stereo is None or work.eyes is not None) and len(screens) == 1
        if len(screens) == 1:
            return self.render(t, work, *screens[0], rects, scale, levels, ahead=alone)
        of, parts, drawn = work.views[self.rank], [], 0
        for s, (view, proj, light) in enumerate(screens):  # a few screens
            idx = [i for i, v in enumerate(of) if v == s]  # pieces, a few
            if idx:
                parts.append((idx, self.render(t, work, view, proj, light, rects, scale, levels, False, idx)))
                drawn += self.drawn
        self.drawn = drawn
        return Joined(parts, len(of))

    def render(self, t: Timer, work: Work, view, proj, light, rects, scale: float, levels, ahead: bool = True,
               only: list | None = None):
        """Every piece this rank renders, drawn (read later: ``Pending.read``). Of a scene cut
        into parts, the parts each piece needs are found first (the ``cull`` phase); ``drawn``
        counts the triangles the pieces drew. Below ``scale`` 1 a piece draws what reaches the
        canvas its scaled pixels cover (``core/resample.py``; ``rects``: the objects' visible rects);
        ``levels``: each object's level of detail (None: as modelled)."""
        masks, reach = work.masks[self.rank], work.rects[self.rank]
        if scale != 1.0:
            size = self.canvas.size
            small = scaled_size(size, scale)
            reach = [covered(r, size, small) for r in reach]  # pieces, not objects
            front = len(masks) if not work.depth else work.front[self.rank] if work.front else 0
            if front:  # screen regions widened; sort-last masks are the rank's objects wherever they fall
                masks = [*self.widen.masks(work.rects[self.rank][:front], masks[:front], rects, scale,
                                           self.planner.canvas_rects),
                         *masks[front:]]
        mine = list(zip(work.rects[self.rank], masks, reach))
        if only is not None:  # the pieces of one screen
            mine = [mine[i] for i in only]
        if self.culler is not None:
            with t.phase("cull"):
                self.culler.frame(view, proj, self.canvas.size)
                # ``seen`` rewrites one array: a copy each where there are several pieces
                pieces = [(rect, mask, self.culler.seen(at) if len(mine) == 1 else self.culler.seen(at).copy())
                          for rect, mask, at in mine]  # pieces, not objects
        else:
            pieces = [(rect, mask, None) for rect, mask, _ in mine]
        with t.phase("render"):
            pending = self.renderer.submit(view, proj, light, pieces, work.depth, self.ahead and ahead, scale, levels)
        self.drawn = self.renderer.last_triangles
        return pending
