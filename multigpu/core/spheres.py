"""Bounding spheres projected to normalized screen rects (``--bounds sphere``): the tangent
extents of each sphere's projection, culled by the frustum planes, NaN where unseen. The box
bounds (``bounds.py``) are the default; this is the cheaper, looser alternative the accuracy
study compares them with."""

from __future__ import annotations

import numpy as np

from multigpu.core.bounds import _check, _far_slack, _near_distance, _write_rects, project_boxes
from multigpu.core.camera import frame_matrices


class SphereProjector:
    """Bounding spheres prepared once (centres coordinate-major) for per-frame projection.

    ``SphereProjector(centers, radii)(view, proj)`` equals ``project_spheres(...)``.
    """

    def __init__(self, centers, radii, chunk: int = 1 << 15):
        centers = np.asarray(centers, dtype=np.float64)
        radii = np.asarray(radii, dtype=np.float64)
        if centers.ndim != 2 or centers.shape[1] != 3 or radii.shape != centers.shape[:1]:
            raise ValueError(f"centers must be (N, 3) and radii (N,), got {centers.shape} and {radii.shape}")
        self.center = np.ascontiguousarray(centers.T)  # (3, N)
        self.radii = np.abs(radii)
        self.chunk = int(chunk)

    def __len__(self) -> int:
        return self.radii.shape[0]

    def place(self, center: np.ndarray, radii: np.ndarray) -> None:
        """Moved spheres: (3, N) centres and (N,) radii (``core.motion.Posed``'s, held)."""
        self.center, self.radii = center, radii

    def __call__(self, view, proj, coverage: np.ndarray | None = None) -> np.ndarray:
        """(N, 4) float64 normalized rects (a view of a coordinate-major array), NaN if unseen.
        ``coverage`` receives pi/4 per sphere (a disc in its square; the ellipse of an
        off-centre sphere is close to that)."""
        if coverage is not None:
            coverage[:] = np.pi / 4
        view = np.asarray(view, dtype=np.float64)
        proj = np.asarray(proj, dtype=np.float64)
        _check(view, proj)
        n = len(self)
        out = np.empty((4, n))
        # frustum planes in view space (Gribb-Hartmann on the projection), normalized
        planes = np.stack([proj[3] + proj[0], proj[3] - proj[0], proj[3] + proj[1],
                           proj[3] - proj[1], proj[3] + proj[2], proj[3] - proj[2]])
        planes /= np.linalg.norm(planes[:, :3], axis=1, keepdims=True)
        near = _near_distance(proj)
        far = proj[2, 3] / (proj[2, 2] + 1.0)
        # the far plane moved out by what the GPU's float32 clip test cannot resolve (FAR_TOL)
        planes[5, 3] += far * _far_slack(proj) if np.isfinite(_far_slack(proj)) else np.inf
        for s in range(0, n, self.chunk):  # blocks of objects, not objects
            e = min(n, s + self.chunk)
            _spheres_block(self.center[:, s:e], self.radii[s:e], view, proj, planes, near, out[:, s:e])
        return out.T

    def frame(self, camera, size, coverage: np.ndarray | None = None) -> tuple:
        """(view, proj, light, rects) of ``camera`` on a ``size`` display."""
        view, proj, light = frame_matrices(camera, size)
        return view, proj, light, self(view, proj, coverage)


def project_spheres(centers, radii, view, proj, chunk: int = 1 << 15) -> np.ndarray:
    """Normalized screen rects of bounding spheres (exact tangent bounds, float64).

    Assumes a perspective ``proj`` of the usual GL form (``w_clip = -z_view``); ``view`` may be
    any rigid transform (rotation and translation). Spheres crossing the near plane get the
    near-clipped bounds of their enclosing box. For per-frame use build a ``SphereProjector``.
    """
    return SphereProjector(centers, radii, chunk)(view, proj)


def _spheres_block(center, radii, view, proj, planes, near, out) -> None:
    """Rects of one block of spheres: ``center`` (3, n), ``radii`` (n,)."""
    vc = np.dot(view[:3, :3], center)  # (3, n) view space
    vc += view[:3, 3:]
    dist = np.dot(planes[:, :3], vc)  # (6, n) signed distances
    dist += planes[:, 3:]
    dist += radii
    invisible = (dist < 0).any(axis=0)
    depth = -vc[2]
    crossing = (depth - radii < near) & ~invisible
    shown = ~invisible & ~crossing
    if shown.all():
        ok = slice(None)
    else:
        out[:] = np.nan
        ok = np.flatnonzero(shown) if shown.any() else None
    if ok is not None:
        x, y, z, r = vc[0, ok], vc[1, ok], depth[ok], radii[ok]
        lo_x, hi_x = _tangent_range(x, z, r)
        lo_y, hi_y = _tangent_range(y, z, r)
        # ndc = P00 * x/depth - P02 (and likewise for y) for a GL perspective matrix
        nx0, nx1 = proj[0, 0] * lo_x - proj[0, 2], proj[0, 0] * hi_x - proj[0, 2]
        ny0, ny1 = proj[1, 1] * lo_y - proj[1, 2], proj[1, 1] * hi_y - proj[1, 2]
        _write_rects(out, ok, np.stack([np.minimum(nx0, nx1), np.minimum(ny0, ny1),
                                        np.maximum(nx0, nx1), np.maximum(ny0, ny1)]))
    cross = np.flatnonzero(crossing)
    if cross.size:
        r = radii[cross, None]
        c = center[:, cross].T
        out[:, cross] = project_boxes(c - r, c + r, view, proj, np.float64).T


def _tangent_range(x, z, r):
    """Range of x/z over a circle (center (x, z), radius r, wholly at z > r) seen from 0."""
    t = np.sqrt(np.maximum(x * x + z * z - r * r, 0.0))
    xt, rz, zt, rx = x * t, r * z, z * t, r * x
    return (xt - rz) / (zt + rx), (xt + rz) / (zt - rx)
