"""Object bounding volumes to normalized screen rects, vectorized over all objects.

Two bounds, one contract: ``rects`` is ``(N, 4)`` ``[xmin, ymin, xmax, ymax]`` in ``[0, 1]^2``
(origin bottom-left), NaN where the object is certainly outside the view frustum.

* ``project_boxes``: the 8 corners of each axis-aligned box. Boxes wholly in front of the
  near plane take a fast path; boxes crossing it are clipped against the near plane (corners in
  front plus the crossings of the 12 edges), so their rect is exact for the visible part and
  never inverted; boxes wholly behind it are invisible.
* ``project_spheres``: the exact perspective bounds of a sphere (tangent lines, Mara &
  McGuire 2013); spheres crossing the near plane use their enclosing box's clipped bounds.

Precision: clip coordinates are formed as ``M @ center + M[:, :3] @ (+-half)``. The center
term is float64, so scenes far from the origin (1e6..1e8 units) keep their precision; the
small per-corner offsets may be float32 (``dtype``) for speed.
"""

from __future__ import annotations

import math

import numpy as np

from multigpu.core import bounds_kernel as kernel
from multigpu.core import jit
from multigpu.core.bounds_kernel import _project_camera, _seen_frames, spatial_groups
from multigpu.core.box_tables import EDGES as _EDGES
from multigpu.core.box_tables import FACES as _FACES
from multigpu.core.box_tables import NEXT as _NEXT
from multigpu.core.box_tables import SIGNS as _SIGNS
from multigpu.core.box_tables import clip_matrix
from multigpu.core.camera import frame_matrices
from multigpu.core.jit import entry


def _check(view, proj) -> np.ndarray:
    """proj @ view, refused unless both are finite 4x4 matrices. Runs every frame, so one
    scalar test: a sum is finite only if every term is (and sixteen entries near 1e308 that
    overflow it are refused too: their product would)."""
    view = np.asarray(view, dtype=np.float64)
    proj = np.asarray(proj, dtype=np.float64)
    if view.shape != (4, 4) or proj.shape != (4, 4):
        raise ValueError("view and projection must be 4x4 matrices")
    if not math.isfinite(view.sum() + proj.sum()):
        raise ValueError("view and projection matrices must be finite")
    return clip_matrix(proj, view)


def _as_matrices(view, proj) -> tuple[np.ndarray, np.ndarray]:
    """view and proj as float64 arrays, refused unless 4x4, with as few numpy calls as can be:
    every frame pays each one's cold-cache cost. Entries are not tested (the kernel does)."""
    if view.__class__ is not np.ndarray or view.dtype != np.float64:
        view = np.asarray(view, dtype=np.float64)
    if proj.__class__ is not np.ndarray or proj.dtype != np.float64:
        proj = np.asarray(proj, dtype=np.float64)
    if view.shape != (4, 4) or proj.shape != (4, 4):
        raise ValueError("view and projection must be 4x4 matrices")
    return view, proj


_SHIFT = np.array([[0.5], [0.5], [0.5], [0.5]])
_WIDEN = np.array([[-0.5], [-0.5], [0.5], [0.5]])


def _write_rects(out, idx, ext, widen: float = 0.0) -> None:
    """NDC extents ``ext`` (4, m) ``[xmin, ymin, xmax, ymax]`` to clipped normalized rects in
    ``out`` (4, N) at columns ``idx`` (an index array or a slice), each side moved outwards by
    ``widen`` (NDC units); rects that miss the screen become NaN. ``ext`` is overwritten."""
    np.multiply(ext, 0.5, out=ext)
    ext += _SHIFT + widen * _WIDEN if widen else _SHIFT
    off = (ext[2] < 0.0) | (ext[0] > 1.0) | (ext[3] < 0.0) | (ext[1] > 1.0)
    np.minimum(np.maximum(ext, 0.0, out=ext), 1.0, out=ext)
    out[:, idx] = ext
    if off.any():
        out[:, np.flatnonzero(off) if isinstance(idx, slice) else idx[off]] = np.nan


class BoxProjector:
    """Axis-aligned boxes prepared once (centres and half extents, coordinate-major) so that
    each frame's projection is a handful of contiguous numpy passes.

    ``BoxProjector(bmin, bmax)(view, proj)`` equals ``project_boxes(bmin, bmax, view, proj)``.
    """

    def __init__(self, bmin, bmax, dtype=np.float32, chunk: int = 1 << 15, compiled: bool | None = None,
                 plain: int = -1):
        bmin = np.asarray(bmin, dtype=np.float64)
        bmax = np.asarray(bmax, dtype=np.float64)
        if bmin.ndim != 2 or bmin.shape[1] != 3 or bmax.shape != bmin.shape:
            raise ValueError(f"bmin and bmax must both have shape (N, 3), got {bmin.shape} and {bmax.shape}")
        self.dtype = np.dtype(dtype)
        self.chunk = int(chunk)
        self.center = np.ascontiguousarray(((bmin + bmax) * 0.5).T)  # (3, N) float64
        self.half64 = np.ascontiguousarray(np.abs(bmax - bmin).T * 0.5)  # (3, N) float64
        self.half = self.half64.astype(self.dtype)  # per-corner offsets in ``dtype``
        if compiled and not jit.available():
            raise ValueError("compiled=True needs numba (pip install numba)")
        # the compiled projection (bounds_kernel.py: the same rects, bit for bit) where
        # numba is installed, unless compiled=False asks for this module's numpy reference
        self.compiled = jit.available() if compiled is None else bool(compiled)
        self.plain = int(plain)  # compiled: boxes in their own order where few are culled (-1), always (1), never (0)
        self.widen = float(np.finfo(self.dtype).eps) * 16  # rects widened by this (NDC) against rounding
        self.plain_boxes = (self.center, self.half64)
        if self.compiled:  # the kernel culls neighbours a group at a time: boxes in a spatial order
            self.grouped = spatial_groups(self.center, self.half64)
            self._kernel = kernel.project_boxes
            order, center, half64, starts, gbox = self.grouped
            self._boxes = (center, self.half, half64, order, starts, gbox, *self.plain_boxes)  # the kernel's own order
            self._camera_kernel = _project_camera
            self._entry = None  # its entry point for ``frame``'s own argument types (bound at the first frame)
            # ``frame``'s outputs, two sets used in turn: a frame's rects and matrices stay valid
            # through the next call (no array allocated per frame: ~15 us of CPU with cold caches)
            self._outputs = [(np.empty((4, len(self))), np.zeros((3, 4, 4))) for _ in range(2)]
            self._turn = 0

    def __len__(self) -> int:
        return self.center.shape[1]

    def place(self, center: np.ndarray, half: np.ndarray) -> None:
        """Moved boxes: (3, N) float64 centres and half extents (``core.motion.Posed``'s arrays,
        held, not copied: call again once they change). From then on the boxes are projected in
        their own order, the spatial groups having been made for the boxes at rest."""
        if center.shape != self.center.shape or half.shape != self.center.shape:
            raise ValueError(f"moved boxes must be {self.center.shape}, got {center.shape} and {half.shape}")
        self.center, self.half64 = center, half
        np.copyto(self.half, half, casting="unsafe")
        self.plain_boxes = (center, half)
        self.plain = 1
        if self.compiled:  # the groups go (no memory held for them): the kernel never reads them again
            none = np.empty((3, 0))
            self.grouped = (np.empty(0, dtype=np.int64), none, none, np.zeros(1, dtype=np.int64), np.empty((6, 0)))
            order, c, h, starts, gbox = self.grouped
            self._boxes = (c, self.half, h, order, starts, gbox, center, half)

    def __call__(self, view, proj, coverage: np.ndarray | None = None) -> np.ndarray:
        """(N, 4) float64 normalized rects (a view of a coordinate-major array), NaN if unseen.

        With ``coverage`` (an (N,) float array) also writes each box's projected silhouette
        area as a fraction of its rect's area (1 for boxes crossing the near plane, 0 unseen):
        the cost model's estimate of the fragments an object generates per rect pixel.
        """
        n = len(self)
        if self.compiled:  # the kernel tests the matrices' entries and forms proj @ view: here just shapes
            view, proj = _as_matrices(view, proj)
            out = np.empty((4, n))
            if not self._kernel(self.grouped, self.plain_boxes, self.half, view, proj, self.widen, FAR_TOL, out,
                                coverage, self.plain):
                raise ValueError("view and projection matrices must be finite")
            return out.T
        M = _check(view, proj)
        out = np.empty((4, n))
        for s in range(0, n, self.chunk):  # blocks of objects, not objects
            e = min(n, s + self.chunk)
            _boxes_block(self.center[:, s:e], self.half[:, s:e], self.half64[:, s:e], M, self.dtype, out[:, s:e],
                         None if coverage is None else coverage[s:e])
        return out.T

    def frame(self, camera, size, coverage: np.ndarray | None = None) -> tuple:
        """(view, proj, light, rects) of ``camera`` on a ``size`` display: ``frame_matrices``
        and then this projector's rects. Compiled, one kernel call forms both (the per-frame
        fixed cost is mostly per call and per Python line, the caches cold after rendering)
        into arrays this projector owns and reuses every other call: they stay valid through
        the next ``frame`` call, not longer (copy them to keep them)."""
        if not self.compiled:
            view, proj, light = frame_matrices(camera, size)
            return view, proj, light, self(view, proj, coverage)
        (ex, ey, ez), (tx, ty, tz), (ux, uy, uz) = camera.position, camera.target, camera.up
        self._turn ^= 1
        out, m = self._outputs[self._turn]
        args = (*self._boxes, self.plain, float(ex), float(ey), float(ez), float(tx), float(ty), float(tz), float(ux),
                float(uy), float(uz), float(camera.fov), float(camera.near), float(camera.far),
                float(size[0] / size[1]), self.widen, FAR_TOL, out, _NO_COVERAGE if coverage is None else coverage,
                coverage is not None, m)
        if coverage is None:  # every argument this projector's own or a float: the kernel's entry point
            if self._entry is None:
                self._entry = entry(self._camera_kernel, args)
            status = self._entry(*args)
        else:  # the caller's coverage array: numba checks its type
            status = self._camera_kernel(*args)
        if status:
            raise ValueError("camera position and target coincide" if status == 1
                             else "view and projection matrices must be finite")
        return m[0], m[1], m[2, 0, :3], out.T


    def frames_seen(self, position, target, up, fov, near, far, size) -> np.ndarray:
        """(F,) int8 for F cameras (rows of the arrays) on a ``size`` display: 1 where some box's
        rect reaches the display, 0 where none does, -1 where ``frame`` refuses the camera (it
        raises why). Compiled, every frame in one call (a generated path's check at setup: 100,000
        frames in ~0.1 s, not ~3); else ``frame`` a frame at a time."""
        F = len(position)
        seen = np.empty(F, dtype=np.int8)
        if self.compiled:
            arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (position, target, up, fov, near, far)]
            _seen_frames(*self._boxes, self.plain, *arrays, float(size[0] / size[1]), self.widen, FAR_TOL,
                         np.empty((4, len(self))), _NO_COVERAGE, np.zeros((3, 4, 4)), seen)
            return seen
        from multigpu.core.camera import Camera

        for f in range(F):
            try:
                r = self.frame(Camera(tuple(position[f]), tuple(target[f]), tuple(up[f]), float(fov[f]),
                                      float(near[f]), float(far[f])), size)[3]
            except ValueError:
                seen[f] = -1
                continue
            with np.errstate(invalid="ignore"):
                seen[f] = ((r[:, 2] >= 0) & (r[:, 0] <= 1) & (r[:, 3] >= 0) & (r[:, 1] <= 1)).any()
        return seen


_NO_COVERAGE = np.empty(0)


def _silhouette_fraction(x: np.ndarray, y: np.ndarray, ext) -> np.ndarray:
    """Projected area of a box (half the summed |area| of its 6 projected faces: front and
    back faces each cover the silhouette once) over the area of its bounding rect."""
    cross = x[_FACES] * y[_NEXT]  # (6, 4, m) shoelace terms
    cross -= x[_NEXT] * y[_FACES]
    area = np.abs(cross.sum(axis=1)).sum(axis=0)
    area *= 0.25  # 1/2 for the shoelace, 1/2 for front + back
    rect = (ext[2] - ext[0]).astype(np.float64) * (ext[3] - ext[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.clip(np.where(rect > 0, area / rect, 1.0), 0.0, 1.0)


def project_boxes(bmin, bmax, view, proj, dtype=np.float32, chunk: int = 1 << 15) -> np.ndarray:
    """Normalized screen rects of axis-aligned boxes (exact bounds of the 8 projected corners).

    Parameters
    ----------
    bmin, bmax : (N, 3) float  box corners in world space.
    view, proj : (4, 4) float  OpenGL-style view and projection matrices.
    dtype : float type of the per-corner arithmetic; the box centres are always transformed in
        float64. Rects are widened by a few units in the last place of ``dtype`` (relative to
        the screen) so rounding never makes them smaller than the true bounds.
    chunk : objects per block (blocks keep the 8-corner temporaries in cache).

    Returns
    -------
    rects : (N, 4) float64 (a view of a coordinate-major array).

    For per-frame use build a ``BoxProjector`` once and call it each frame.
    """
    return BoxProjector(bmin, bmax, dtype, chunk)(view, proj)


#: GPUs clip at the far plane in float32 (``z_clip <= w``), so a point beyond it by less than
#: a few float32 ulps of ``w`` may still be drawn; only boxes and spheres beyond the far plane by
#: more than this (relative to ``w``) are culled. With far/near above ~1e6 nothing beyond the
#: far plane is reliably clipped by the GPU, and nothing is culled there.
FAR_TOL = 16 * 2.0**-23


def _far_slack(proj: np.ndarray) -> float:
    """How far (view-space units per unit of far) beyond the far plane the GPU may still draw:
    a point at distance ``d`` is clipped reliably once ``2n(d - f) / ((f - n) d) > FAR_TOL``;
    inf when no ``d`` qualifies."""
    near = _near_distance(proj)
    a, b = proj[2, 2], proj[2, 3]
    far = b / (a + 1.0) if a != -1.0 else np.inf
    k = FAR_TOL * (far - near) / (2.0 * near)
    return np.inf if not k < 1.0 else 1.0 / (1.0 - k) - 1.0


# the 6 frustum planes as combinations of clip rows (x, y, z, w): inside means >= 0
_PLANES = np.array([[1, 0, 0, 1], [-1, 0, 0, 1], [0, 1, 0, 1], [0, -1, 0, 1], [0, 0, 1, 1], [0, 0, -1, 1]],
                   dtype=np.float64)
_NEAR, _FAR = 4, 5


def _affine(M: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(4, n) clip coordinates of points ``p`` (3, n): ((m0*x + m1*y) + m2*z) + m3 per row,
    added left to right (no BLAS: the compiled kernel forms every value the same way)."""
    out = M[:, 0:1] * p[0]
    out += M[:, 1:2] * p[1]
    out += M[:, 2:3] * p[2]
    out += M[:, 3:]
    return out


def _dot3(a: np.ndarray, h: np.ndarray) -> np.ndarray:
    """(n,) a0*h0 + a1*h1 + a2*h2 for ``h`` (3, n), added left to right."""
    out = a[0] * h[0]
    out += a[1] * h[1]
    out += a[2] * h[2]
    return out


def reach_rows(M: np.ndarray) -> np.ndarray:
    """(6, 3) |plane @ M[:, :3]|: how far a box's half extents reach along each plane's normal."""
    return np.abs(_PLANES @ M[:, :3])


def _boxes_block(center, half, half64, M, dtype, out, coverage=None) -> None:
    """Rects of one block: ``center``/``half64`` (3, n) float64, ``half`` (3, n) in ``dtype``;
    silhouette fractions into ``coverage`` when given.

    A plane distance is affine in the corner, so each box's extreme distance to a frustum plane
    needs no corners: boxes wholly outside a plane are culled first, and only the rest get
    their 8 corners projected.
    """
    clip_c = _affine(M, center)  # (4, n) float64, camera-relative
    w_r = _dot3(np.abs(M[3, :3]), half64)
    outside = np.zeros(clip_c.shape[1], dtype=bool)
    front = None  # set by the near plane
    reach_all = reach_rows(M)
    for i in range(6):  # planes, not objects: one pass each over the block
        axis = i // 2
        # the centre's distance (a plane adds or subtracts one row to w: exact in any order)
        centre = clip_c[axis] + clip_c[3] if i % 2 == 0 else -clip_c[axis] + clip_c[3]
        reach = _dot3(reach_all[i], half64)  # how far the box reaches along the normal
        if i == _NEAR:
            front = centre >= reach  # wholly in front of the near plane
        centre += reach  # the box's farthest point inside
        if i == _FAR:  # beyond the far plane only by more than the GPU's float32 clip test can tell
            outside |= centre < -FAR_TOL * (np.abs(clip_c[3]) + w_r)
        else:
            outside |= centre < 0
    shown = front & ~outside
    count = int(np.count_nonzero(shown))
    # most boxes shown: project the whole block (no gathers) and blank the rest afterwards;
    # few shown: gather them first
    show = slice(None) if 2 * count > shown.size else np.flatnonzero(shown)
    if isinstance(show, np.ndarray):
        out[:] = np.nan
    if coverage is not None:
        coverage[:] = 1.0
    if count:
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            x, y = _corner_ndc(clip_c[:, show], half[:, show], M, dtype)
            ext = np.stack([x.min(axis=0), y.min(axis=0), x.max(axis=0), y.max(axis=0)]).astype(np.float64)
            if coverage is not None:
                coverage[show] = _silhouette_fraction(x, y, ext)
        # rounding in ``dtype`` moves a corner by a few ulps of its NDC value; only values
        # within [-1, 1] matter after clipping, so a fixed widening of 16 ulps of 1 is enough
        _write_rects(out, show, ext, widen=float(np.finfo(dtype).eps) * 16)
    if isinstance(show, slice) and count < shown.size:
        out[:, ~shown] = np.nan
        if coverage is not None:
            coverage[~shown] = 1.0
    slow = np.flatnonzero(~front & ~outside)
    if slow.size:  # few boxes cross the near plane
        off = half64[:, slow].T[:, None, :] * _SIGNS  # (m, 8, 3) corner offsets
        corners = np.empty((4,) + off.shape[:2])
        for r in range(4):  # clip rows, each ((ox*m0 + oy*m1) + oz*m2) + centre
            corners[r] = off[..., 0] * M[r, 0]
            corners[r] += off[..., 1] * M[r, 1]
            corners[r] += off[..., 2] * M[r, 2]
            corners[r] += clip_c[r, slow][:, None]
        _clipped_rects(corners, out, slow)


def _corner_ndc(clip_c, half, M, dtype) -> tuple[np.ndarray, np.ndarray]:
    """NDC x and y, each (8, m), of the 8 corners of boxes wholly in front of the near plane."""
    cx, cy, cw = (_corners(clip_c[r].astype(dtype), half[0], half[1], half[2], M[r, :3].astype(dtype))
                  for r in (0, 1, 3))
    np.divide(cx, cw, out=cx)
    np.divide(cy, cw, out=cy)
    return cx, cy


def _corners(base, hx, hy, hz, row) -> np.ndarray:
    """(8, m) value of one clip row at the 8 corners: base +- hx*row0 +- hy*row1 +- hz*row2.

    Corner k has signs (bit 2: x, bit 1: y, bit 0: z), the same for every row. In place, no
    temporaries beyond the three (m,) offsets: contiguous passes that stay fast at 10^6 boxes.
    """
    ax, ay, az = hx * row[0], hy * row[1], hz * row[2]
    out = np.empty((8, base.shape[0]), dtype=base.dtype)
    np.subtract(base, ax, out=out[0])
    np.add(base, ax, out=out[4])
    np.add(out[0], ay, out=out[2])
    np.add(out[4], ay, out=out[6])
    out[0] -= ay
    out[4] -= ay
    np.add(out[0::2], az, out=out[1::2])
    out[0::2] -= az
    return out


_OFF = np.array([[2.0], [2.0], [3.0], [3.0]])  # an extent wholly off screen (becomes NaN)


def _clipped_rects(P, out, idx) -> None:
    """Rects of boxes that cross the near plane: the part in front of it, projected.

    ``P`` (4, m, 8) holds clip x, y, z, w at each box's 8 corners; the candidate points are
    the corners in front of the near plane and the crossings of the 12 edges with it."""
    d = P[2] + P[3]  # signed distance to the near plane (>= 0 in front)
    d0, d1 = d[:, _EDGES[:, 0]], d[:, _EDGES[:, 1]]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = d0 / (d0 - d1)
        E0 = P[[0, 1, 3]][:, :, _EDGES[:, 0]]
        crossing = E0 + t * (P[[0, 1, 3]][:, :, _EDGES[:, 1]] - E0)  # (3, m, 12) x, y, w on the plane
        pts = np.concatenate([P[[0, 1, 3]], crossing], axis=2)  # (3, m, 20)
        keep = np.concatenate([d >= 0, (d0 >= 0) != (d1 >= 0)], axis=1) & (pts[2] > 0)
        xy = pts[:2] / pts[2]
    # a point on the near plane has w = near > 0, so its projection is finite; clamp wild
    # values (a near plane at 1e-7 gives huge NDC) before taking extents
    np.clip(xy, -4.0, 4.0, out=xy)
    ext = np.concatenate([np.where(keep, xy, np.inf).min(axis=2), np.where(keep, xy, -np.inf).max(axis=2)])
    np.copyto(ext, _OFF, where=~keep.any(axis=1))  # nothing in front: off screen
    _write_rects(out, idx, ext)


def _near_distance(proj: np.ndarray) -> float:
    """Near-plane distance of a GL perspective matrix."""
    a, b = proj[2, 2], proj[2, 3]
    return float(b / (a - 1.0))
