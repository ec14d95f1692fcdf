"""Objects that move: one rigid (affine) transform per body a frame, and what it does to bounds.

A moving scene keeps its vertices as modelled (one copy per host, never rewritten); each frame a
``Motion`` gives every *body* (a modelled object: the clusters and parts cut from it move with
it) an affine map ``x -> A x + b`` of the scene's local coordinates (vertex coordinates, relative
to ``Scene.origin``). ``Posed`` turns those into everything downstream needs, vectorized over
all objects: the moved objects' boxes (a box's image under ``A`` is contained in the box of half
extents ``|A| h`` about ``A c + b``: Arvo's rule, exact for a box's own corners), their spheres
(radius times a bound of ``A``'s largest stretch), the parts' boxes, and the (N, 12) float32 rows
the vertex shader applies (``gpu/shaders.py``). Every rank computes the same float64 numbers from
the same time, so every rank draws the same float32 vertices: composites stay bit-identical to
one rank's render. Pure numpy: no MPI, no GL.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from multigpu.core import jit
from multigpu.core import motion_kernel as kernel

#: a frame is this many seconds of scene time at ``--anim-speed 1`` (a path's frames, played at 30 Hz)
FRAME_SECONDS = 1.0 / 30.0


def scene_time(frame: int, speed: float = 1.0) -> float:
    """The scene's time (seconds) at frame ``frame`` of the path: the same on every rank, in a
    replay and after a recovery (it is the frame's, not the clock's)."""
    return float(frame) * FRAME_SECONDS * float(speed)


class Motion(Protocol):
    """Where a scene's bodies are at time ``t``: ``at(t)`` gives ``(A (B, 3, 3), b (B, 3))`` float64
    in the scene's local coordinates (arrays it may reuse: valid until its next call); ``bodies``
    (N,) is each object's body; ``moving`` (B,) bool the bodies that ever move (None: all)."""

    bodies: np.ndarray

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]: ...


def bodies_of(scene) -> np.ndarray:
    """(N,) each object's body, numbered from 0: the clusters cut from one modelled object
    (``Scene.body``) move as one."""
    if scene.body is None:
        return np.arange(scene.n_objects, dtype=np.int64)
    _, body = np.unique(np.asarray(scene.body), return_inverse=True)
    return body.astype(np.int64)


def rotations(axis: np.ndarray, angle: np.ndarray, compiled: bool | None = None) -> np.ndarray:
    """(n, 3, 3) rotations by ``angle`` (n,) radians about unit ``axis`` (n, 3) (Rodrigues)."""
    axis = np.ascontiguousarray(axis, dtype=np.float64)
    angle = np.ascontiguousarray(np.broadcast_to(angle, axis.shape[:1]), dtype=np.float64)
    out = np.empty((axis.shape[0], 3, 3))
    if jit.use(compiled):
        kernel._rotations(axis, angle, out)
        return out
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = axis[:, 0], axis[:, 1], axis[:, 2]
    C = 1.0 - c
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = c + x * x * C, x * y * C - z * s, x * z * C + y * s
    out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = y * x * C + z * s, c + y * y * C, y * z * C - x * s
    out[:, 2, 0], out[:, 2, 1], out[:, 2, 2] = z * x * C - y * s, z * y * C + x * s, c + z * z * C
    return out


def apply(A: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, 3) ``A @ v`` per row, summed left to right (as the kernel sums)."""
    return A[:, :, 0] * v[:, 0, None] + A[:, :, 1] * v[:, 1, None] + A[:, :, 2] * v[:, 2, None]


def stretch(A: np.ndarray) -> np.ndarray:
    """(n,) an upper bound of each map's largest stretch (spectral norm): exact where its columns
    are orthogonal (a rotation times a scale: the longest column), else the Frobenius norm."""
    col = [A[:, 0, j] * A[:, 0, j] + A[:, 1, j] * A[:, 1, j] + A[:, 2, j] * A[:, 2, j] for j in range(3)]
    dot = lambda i, j: np.abs(A[:, 0, i] * A[:, 0, j] + A[:, 1, i] * A[:, 1, j] + A[:, 2, i] * A[:, 2, j])  # noqa: E731
    off = np.maximum(np.maximum(dot(0, 1), dot(0, 2)), dot(1, 2))
    top = np.maximum(np.maximum(col[0], col[1]), col[2])
    return np.sqrt(np.where(off <= ORTHOGONAL * top, top, col[0] + col[1] + col[2]))


#: columns whose dot products stay under this share of their squared lengths count as orthogonal
ORTHOGONAL = 1e-12
#: bodies posed at a time where a motion gives its maps a span at a time (``Posed.spans``)
SPAN = 8192


def moved_boxes(center: np.ndarray, half: np.ndarray, A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (n, 3) ``center`` +- ``half`` moved by ``x -> A x + b``: the boxes that hold them."""
    return apply(A, center) + b, apply(np.abs(A), half)


def shader_rows(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, 12) float32: each map's three rows ``[A_i0, A_i1, A_i2, b_i]`` (the vertex shader's)."""
    return np.concatenate([A, b[:, :, None]], axis=2).reshape(len(A), 12).astype(np.float32)


class Posed:
    """A scene's bounds at each time of its ``motion``, made from its bounds at rest.

    ``at(t)`` fills, for every object: ``center``/``half`` (3, N) float64 world boxes, coordinate-
    major as ``core.bounds.BoxProjector`` holds them; ``centers`` (N, 3) and ``radii`` (N,) its
    spheres; ``rows`` (N, 12) float32 its map for the GPU; and for a scene cut into parts each
    part's ``part_center``/``part_half`` (3, P). Only bodies that move (``Motion.moving``, all
    where it says nothing) are computed; the others keep their rest values."""

    def __init__(self, scene, motion: Motion, compiled: bool | None = None, spheres: bool = True):
        self.motion = motion
        self.compiled = jit.use(compiled)
        self.spheres = spheres = bool(spheres)  # the spheres posed too (levels of detail, sphere bounds read them)
        self.origin = np.asarray(scene.origin, dtype=np.float64)
        body = np.asarray(motion.bodies, dtype=np.int64)
        if body.shape != (scene.n_objects,):
            raise ValueError(f"a motion for {body.shape[0]} objects cannot move a scene of {scene.n_objects}")
        bmin, bmax = np.asarray(scene.bmin, dtype=np.float64), np.asarray(scene.bmax, dtype=np.float64)
        moving = getattr(motion, "moving", None)
        self.objects = (np.arange(scene.n_objects) if moving is None
                        else np.flatnonzero(np.asarray(moving, dtype=bool)[body]))  # the objects that move
        self.body = body[self.objects]
        self.rest = (bmin, bmax, np.asarray(scene.centers, dtype=np.float64), np.asarray(scene.radii, dtype=np.float64))
        self.center = np.ascontiguousarray(((bmin + bmax) * 0.5).T)
        self.half = np.ascontiguousarray(((bmax - bmin) * 0.5).T)
        # the spheres only where they are read (levels of detail, sphere bounds)
        self.centers = np.array(scene.centers, dtype=np.float64) if spheres else np.empty((0, 3))
        self.radii = np.array(scene.radii, dtype=np.float64) if spheres else np.empty(0)
        self.rows = np.tile(np.array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0], dtype=np.float32), (scene.n_objects, 1))
        self.parts = None
        start = scene.part_start
        if start is not None and int(start[-1]) > scene.n_objects:
            pmin, pmax = np.asarray(scene.part_bmin, dtype=np.float64), np.asarray(scene.part_bmax, dtype=np.float64)
            part_obj = np.repeat(np.arange(scene.n_objects), np.diff(start))
            rows = np.flatnonzero(np.isin(part_obj, self.objects))
            self.parts = (rows, body[part_obj[rows]], np.ascontiguousarray((pmin + pmax)[rows] * 0.5 - self.origin),
                          np.ascontiguousarray((pmax - pmin)[rows] * 0.5))
            self.part_center = np.ascontiguousarray(((pmin + pmax) * 0.5).T)
            self.part_half = np.ascontiguousarray(((pmax - pmin) * 0.5).T)
        self.morph = self._morphs(scene, motion, body)
        self.skin = self._skins(scene, motion, body)
        # span by span (``spans``): every object a body of its own that moves, and nothing more
        self.spanned = (callable(getattr(motion, "at_span", None)) and moving is None and self.parts is None
                        and self.morph is None and self.skin is None
                        and np.array_equal(body, np.arange(scene.n_objects)))
        self.count = int(self.objects.size)
        if self.spanned:  # the rest bounds read a span at a time from the scene's (the host's) arrays,
            self.c0 = self.h0 = self.s0 = self.r0 = self.body = None  # the rows a span's (``place_span``)
            self.objects = slice(0, self.count)
            self.rows = self.rows[:SPAN].copy()
        else:  # rest boxes and spheres of the moving objects, local
            self.c0, self.h0, self.s0, self.r0 = self._rest(self.objects)
        self.t = None

    def _rest(self, idx) -> tuple:
        """Objects ``idx``'s (an index array or a slice) rest boxes and spheres, local."""
        bmin, bmax, centers, radii = self.rest
        c0 = np.ascontiguousarray((bmin[idx] + bmax[idx]) * 0.5 - self.origin)
        h0 = np.ascontiguousarray((bmax[idx] - bmin[idx]) * 0.5)
        if not self.spheres and self.spanned:
            return c0, h0, np.empty((0, 3)), np.empty(0)
        return c0, h0, np.ascontiguousarray(centers[idx] - self.origin), np.ascontiguousarray(radii[idx])

    def spans(self) -> list[tuple[int, int]]:
        """The bodies' spans ``place_span`` takes, each of at most ``SPAN`` (the whole where the
        motion cannot give a span of its bodies' maps: ``Motion.at_span``)."""
        n = self.count
        if not self.spanned:
            return [(0, n)]
        return [(lo, min(lo + SPAN, n)) for lo in range(0, n, SPAN)]

    def _skins(self, scene, motion, body: np.ndarray):
        """Of the moving objects, the skinned ones (``Scene.skin_pairs``, the motion's
        ``last_palette``): their positions among the moving objects and bodies, each (body,
        joint) pair's rest box (local), and the part rows of each (its position, -1: none)."""
        if scene.skin_pairs is None or getattr(motion, "palette", None) is None:
            return None
        known = np.unique(scene.body) if scene.body is not None else np.arange(scene.n_objects)
        pb = np.searchsorted(known, scene.skin_pairs[:, 0])  # the pairs' bodies, as ``body`` numbers them
        sel = np.flatnonzero(np.isin(body[self.objects], pb))
        boxes = np.asarray(scene.skin_boxes, dtype=np.float64)
        pc, ph = (boxes[:, :3] + boxes[:, 3:]) * 0.5 - self.origin, (boxes[:, 3:] - boxes[:, :3]) * 0.5
        parts = None
        if self.parts is not None:
            where = np.full(int(body.max()) + 1, -1, dtype=np.int64)
            where[body[self.objects[sel]]] = body[self.objects[sel]]
            part_obj = np.repeat(np.arange(scene.n_objects), np.diff(scene.part_start))
            parts = where[body[part_obj[self.parts[0]]]]
        return sel, body[self.objects[sel]], pb, np.asarray(scene.skin_pairs[:, 1]), pc, ph, parts

    def skinned(self, palette, c0, h0, s0, r0, pc, ph):
        """The skinned objects' boxes this frame (the bodies' boxes: every (body, joint) pair's rest
        box moved by its joint, united), into copies of the rest arrays given."""
        sel, bodies, pb, pj, bc, bh, parts = self.skin
        A, b = palette
        c, h = moved_boxes(bc, bh, A[pj], b[pj])
        n = int(max(pb.max(), bodies.max())) + 1
        lo, hi = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
        np.minimum.at(lo, pb, c - h)
        np.maximum.at(hi, pb, c + h)
        c0, h0, s0, r0 = c0.copy(), h0.copy(), s0.copy(), r0.copy()
        c0[sel], h0[sel] = (lo + hi)[bodies] * 0.5, (hi - lo)[bodies] * 0.5
        s0[sel], r0[sel] = c0[sel], np.linalg.norm(h0[sel], axis=1)
        if parts is not None:
            has = parts >= 0
            pc, ph = pc.copy(), ph.copy()
            pc[has], ph[has] = (lo + hi)[parts[has]] * 0.5, (hi - lo)[parts[has]] * 0.5
        return c0, h0, s0, r0, pc, ph

    def _morphs(self, scene, motion, body: np.ndarray):
        """Of the moving objects, those a morph target moves (``Scene.morph_lo``/``morph_hi`` and the
        motion's ``morph_of``): their positions among the moving objects, extents, weight slots; and
        the part rows of each (its position, -1: a part of an object that does not morph)."""
        of = getattr(motion, "morph_of", None)
        if scene.morph_lo is None or of is None:
            return None
        per = np.asarray(of, dtype=np.int64)[body[self.objects]]  # (first slot, count) of each moving object
        sel = np.flatnonzero(per[:, 1] > 0)
        if not sel.size:
            return None
        T = scene.morph_lo.shape[1]
        valid = np.arange(T) < per[sel, 1:2]
        slots = np.where(valid, per[sel, :1] + np.arange(T), 0)
        obj = self.objects[sel]
        parts = None
        if self.parts is not None:
            where = np.full(scene.n_objects, -1, dtype=np.int64)
            where[obj] = np.arange(sel.size)
            part_obj = np.repeat(np.arange(scene.n_objects), np.diff(scene.part_start))
            parts = where[part_obj[self.parts[0]]]
        return sel, np.asarray(scene.morph_lo)[obj], np.asarray(scene.morph_hi)[obj], slots, valid, parts

    def grown(self, weights: np.ndarray):
        """The moving objects' rest boxes and spheres (``c0``, ``h0``, ``r0``) and the moving parts'
        (``pc``, ``ph``), grown by their morph targets' deltas at ``weights``: each axis by the sum
        over the targets of the least and greatest weighted delta."""
        sel, lo, hi, slots, valid, parts = self.morph
        w = np.where(valid, np.asarray(weights, dtype=np.float64)[slots], 0.0)[:, :, None]
        dlo, dhi = np.minimum(w * lo, w * hi).sum(axis=1), np.maximum(w * lo, w * hi).sum(axis=1)
        c0, h0, r0 = self.c0.copy(), self.h0.copy(), self.r0.copy()
        c0[sel] += (dlo + dhi) * 0.5
        h0[sel] += (dhi - dlo) * 0.5
        r0[sel] += np.linalg.norm(np.maximum(-dlo, dhi), axis=1)
        pc = ph = None
        if self.parts is not None:
            pc, ph = self.parts[2].copy(), self.parts[3].copy()
            has = parts >= 0
            pc[has] += (dlo + dhi)[parts[has]] * 0.5
            ph[has] += (dhi - dlo)[parts[has]] * 0.5
        return c0, h0, r0, pc, ph

    @property
    def n_moving(self) -> int:
        return self.count

    def at(self, t: float, sink=None) -> "Posed":
        """Every array above at time ``t`` (rewritten in place; this object, for chaining).
        ``sink(rows, lo)`` takes each span's rows (objects lo:lo + len(rows)) as they are made:
        where the bodies are posed a span at a time, ``rows`` holds the last span's only."""
        if self.spanned:
            for lo, hi in self.spans():
                self.place_span(*self.motion.at_span(float(t), lo, hi), lo, hi)
                if sink is not None:
                    sink(self.rows[:hi - lo], lo)
            self.t = t
            return self
        self.place(*self.motion.at(float(t)), t, getattr(self.motion, "last_weights", None))
        if sink is not None:
            sink(self.rows, 0)
        return self

    def place_span(self, A: np.ndarray, b: np.ndarray, lo: int, hi: int) -> "Posed":
        """Objects lo:hi (bodies of their own: ``spanned``) moved by their maps ``A``, ``b``
        (``Motion.at_span``'s): the arrays ``place`` writes, a span of them (``rows``: this span's,
        from row 0)."""
        if self.compiled:  # the rest bounds made in the kernel: no temporaries a span
            bmin, bmax, centers, radii = self.rest
            A, b = np.ascontiguousarray(A, dtype=np.float64), np.ascontiguousarray(b, dtype=np.float64)
            kernel._pose_span(A, b, lo, bmin, bmax, centers, radii, self.origin, ORTHOGONAL, self.spheres,
                              self.center, self.half, self.centers, self.radii, self.rows)
            return self
        c0, h0, s0, r0 = self._rest(slice(lo, hi))
        self._put(slice(lo, hi), A, b, c0, h0, s0, r0, slice(0, hi - lo))
        return self

    def _put(self, idx, Ao: np.ndarray, bo: np.ndarray, c0, h0, s0, r0, rows=None) -> None:
        """Objects ``idx``'s moved boxes, spheres and rows (``rows``: where in ``self.rows``; the
        reference)."""
        c, h = moved_boxes(c0, h0, Ao, bo)
        self.center[:, idx] = (c + self.origin).T
        self.half[:, idx] = h.T
        if self.spheres:
            self.centers[idx] = apply(Ao, s0) + bo + self.origin
            self.radii[idx] = r0 * stretch(Ao)
        self.rows[idx if rows is None else rows] = shader_rows(Ao, bo)

    def place(self, A: np.ndarray, b: np.ndarray, t: float | None = None, weights=None) -> "Posed":
        """Every array above for the bodies' maps ``A``, ``b`` (``Motion.at``'s, at time ``t``), the
        morphing objects' rest bounds grown first by their targets at ``weights``."""
        if self.spanned:
            for lo, hi in self.spans():
                self.place_span(A[lo:hi], b[lo:hi], lo, hi)
            self.t = t
            return self
        c0, h0, s0, r0 = self.c0, self.h0, self.s0, self.r0
        parts = self.parts
        if self.morph is not None and weights is not None:
            c0, h0, r0, pc, ph = self.grown(weights)
            parts = parts if parts is None else (*parts[:2], pc, ph)
        palette = getattr(self.motion, "last_palette", None)
        if self.skin is not None and palette is not None:
            pc, ph = (None, None) if parts is None else parts[2:]
            c0, h0, s0, r0, pc, ph = self.skinned(palette, c0, h0, s0, r0, pc, ph)
            parts = parts if parts is None else (*parts[:2], pc, ph)
        if self.compiled:  # one pass (``motion_kernel.py``), the same numbers
            A, b = np.ascontiguousarray(A, dtype=np.float64), np.ascontiguousarray(b, dtype=np.float64)
            kernel._pose(A, b, self.body, self.objects, c0, h0, s0, r0, self.origin, ORTHOGONAL,
                         self.spheres, self.center, self.half, self.centers, self.radii, self.rows, 0)
            if parts is not None:
                kernel._boxes(A, b, *parts, self.origin, self.part_center, self.part_half)
            self.t = t
            return self
        self._put(self.objects, A[self.body], b[self.body], c0, h0, s0, r0)
        if parts is not None:
            rows, pbody, pc, ph = parts
            c, h = moved_boxes(pc, ph, A[pbody], b[pbody])
            self.part_center[:, rows] = (c + self.origin).T
            self.part_half[:, rows] = h.T
        self.t = t
        return self

    def bmin_bmax(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) the moved boxes' corners (tests, tools)."""
        return (self.center - self.half).T, (self.center + self.half).T


class SceneClock:
    """A moving scene's time as an operator steers it (``rank/steer.py``, rank 0): the frame's
    time on the path (``scene_time``, bit for bit) until someone pauses, resumes or scrubs it;
    from then on ``base`` plus the path's time since frame ``anchor`` while it runs, ``base``
    while it stands. Every rank receives what rank 0's clock says."""

    def __init__(self, speed: float = 1.0):
        self.speed = float(speed)
        self.base, self.anchor, self.paused = 0.0, 0, False

    def now(self, frame: int) -> float:
        return self.base if self.paused else self.base + scene_time(frame - self.anchor, self.speed)

    def at(self, frame: int, toggles: int = 0, scrub: float = 0.0, set_to: float | None = None,
           pause: bool | None = None) -> float:
        """Frame ``frame``'s time after the operator's ``toggles`` (pause/resume presses), ``pause``
        (the page's pause or play), ``set_to`` (a time to jump to) and ``scrub`` (seconds on)."""
        want = self.paused != bool(toggles % 2) if pause is None else bool(pause)
        if want != self.paused or scrub or set_to is not None:
            now = self.now(frame) if set_to is None else float(set_to)
            self.base, self.anchor, self.paused = now + float(scrub), frame, want
        return self.now(frame)
