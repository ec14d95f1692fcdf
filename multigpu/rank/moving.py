"""A moving scene in the frame loop: its bodies posed at each frame's scene time, and every
part of the loop that reads object bounds pointed at the posed ones.

The scene's time is the frame's (``core.motion.scene_time``, at ``--anim-speed``), or the
operator's where a run steers it (``Live``): every rank poses the same frame at the same time,
so a replay, a restart after a failure and a one-rank render all see what the wall saw. The
planner's projector (or this rank's slice of a shared projection), the part culler and the
level-of-detail chooser read the posed arrays; the renderer gets the maps the vertex shader
applies. A part of the frame loop (``frames.Frames``) with one job.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.bounds import BoxProjector
from multigpu.core.motion import Posed, scene_time
from multigpu.rank.timer import Timer


class Moving:
    """Poses ``scene`` by ``motion`` for the frame loop's parts (any of them None where absent)."""

    def __init__(self, scene, motion, speed: float, planner, projection, culler, chooser, renderer,
                 spheres: bool = True):
        self.posed = Posed(scene, motion, spheres=spheres or not isinstance(planner.project, BoxProjector))
        self.speed = float(speed)
        self.planner, self.culler, self.renderer = planner, culler, renderer
        self.sub = getattr(projection, "sub", None)  # a shared projection's slice of the boxes
        self.span = (projection.lo, projection.hi) if self.sub is not None else None
        if chooser is not None and self.posed.spheres:  # reads the posed spheres from now on
            chooser.centers, chooser.radii = self.posed.centers, self.posed.radii
        self.time = 0.0  # the scene time of the last frame posed
        self.movers = np.zeros(scene.n_objects, dtype=bool)  # told the renderer once, with the first maps
        self.movers[self.posed.objects] = True

    def time_of(self, f: int, path=None) -> float:
        """Frame ``f``'s scene time as the path plays it: the time its file recorded for the frame
        (a replay of a steered run), else the frame's own (``scene_time``)."""
        times = getattr(path, "times", None)
        if times is not None and 0 <= f < len(times):
            return float(times[f])
        return scene_time(f, self.speed)

    def pose(self, t: Timer, when: float) -> None:
        """Every body where it is at scene time ``when``, for the frame planned next: where the
        motion puts them and their maps to the GL (the ``animate`` phase: the scene's own work, a
        part of rendering), their bounds moved (``pose``: a part of balancing)."""
        motion, p = self.posed.motion, self.posed
        if p.spanned:  # a span of bodies at a time: no rank holds every body's map, nor its rows
            with t.phase("animate"):
                self.renderer.pose(None, self.movers)
            for lo, hi in p.spans():
                with t.phase("animate"):
                    A, b = motion.at_span(when, lo, hi)
                with t.phase("pose"):
                    p.place_span(A, b, lo, hi)
                with t.phase("animate"):
                    self.renderer.pose_span(p.rows[:hi - lo], lo)
            weights, p.t = None, when
        else:
            with t.phase("animate"):
                A, b = motion.at(when)
                weights = getattr(motion, "last_weights", None)  # a model's morph target weights
            with t.phase("pose"):
                p.place(A, b, when, weights)
        with t.phase("pose"):
            project = self.planner.project
            if isinstance(project, BoxProjector):
                project.place(p.center, p.half)
            else:
                project.place(np.ascontiguousarray(p.centers.T), p.radii)
            if self.sub is not None:
                lo, hi = self.span
                self.sub.place(np.ascontiguousarray(p.center[:, lo:hi]), np.ascontiguousarray(p.half[:, lo:hi]))
            if self.culler is not None and p.parts is not None:
                self.culler.place(p.part_center, p.part_half)
        with t.phase("animate"):
            if not p.spanned:
                morph_of = getattr(motion, "morph_of", None) if self.movers is not None else None
                self.renderer.pose(p.rows, self.movers, weights, None if morph_of is None else morph_of[motion.bodies],
                                   getattr(motion, "last_palette", None))
            self.movers = None
        self.time = when
