"""Camera matrices (OpenGL conventions, float64): look-at view, symmetric and off-axis projection."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Camera:
    """One frame's camera: eye, target, up (world space), vertical fov in degrees, clip planes."""

    position: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov: float = 60.0
    near: float = 0.1
    far: float = 1000.0

    def view(self) -> np.ndarray:
        return look_at(self.position, self.target, self.up)

    def projection(self, aspect: float) -> np.ndarray:
        return perspective(self.fov, aspect, self.near, self.far)


def look_at(eye, target, up) -> np.ndarray:
    """World-to-view matrix; the camera looks down -z with +y up."""
    return _frame(eye, target, up, 60.0, 1.0, 2.0, 1.0)[0].copy()


def perspective(fov_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """Symmetric GL perspective projection (vertical fov in degrees)."""
    return _frame((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), fov_deg, near, far, aspect)[1].copy()


def camera_into(ex, ey, ez, tx, ty, tz, ux, uy, uz, fov_deg, near, far, aspect, out) -> bool:
    """A camera's view (``out[0]``) and symmetric projection (``out[1]``) matrices, and the light
    direction (``out[2, 0, :3]``: view^T (0.3, 0.5, 0.8), normalized: towards the viewer,
    slightly above), written into ``out`` (3, 4, 4) float64, the other entries left as they
    are. Scalar arithmetic on Python floats, one routine for both paths: here for numpy, and
    compiled unchanged into the projection kernel (``bounds_kernel.py``), which forms a frame's
    matrices and rects in one call; IEEE double either way, so the two agree bit for bit.
    False (nothing written) where the position and target coincide or are not finite."""
    fx, fy, fz = tx - ex, ty - ey, tz - ez
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    if not math.isfinite(norm) or norm == 0:
        return False
    fx, fy, fz = fx / norm, fy / norm, fz / norm
    sx, sy, sz = fy * uz - fz * uy, fz * ux - fx * uz, fx * uy - fy * ux
    if math.sqrt(sx * sx + sy * sy + sz * sz) < 1e-12:  # looking along up: pick any perpendicular
        ux, uy, uz = (1.0, 0.0, 0.0) if abs(fx) < 0.9 else (0.0, 1.0, 0.0)
        sx, sy, sz = fy * uz - fz * uy, fz * ux - fx * uz, fx * uy - fy * ux
    n = math.sqrt(sx * sx + sy * sy + sz * sz)
    sx, sy, sz = sx / n, sy / n, sz / n
    ux, uy, uz = sy * fz - sz * fy, sz * fx - sx * fz, sx * fy - sy * fx
    out[0, 0, 0], out[0, 0, 1], out[0, 0, 2], out[0, 0, 3] = sx, sy, sz, -(sx * ex + sy * ey + sz * ez)
    out[0, 1, 0], out[0, 1, 1], out[0, 1, 2], out[0, 1, 3] = ux, uy, uz, -(ux * ex + uy * ey + uz * ez)
    out[0, 2, 0], out[0, 2, 1], out[0, 2, 2], out[0, 2, 3] = -fx, -fy, -fz, fx * ex + fy * ey + fz * ez
    out[0, 3, 0], out[0, 3, 1], out[0, 3, 2], out[0, 3, 3] = 0.0, 0.0, 0.0, 1.0
    t = near * math.tan(math.radians(fov_deg) / 2.0)
    r = t * aspect
    out[1, 0, 0], out[1, 0, 1], out[1, 0, 2], out[1, 0, 3] = 2 * near / (r - -r), 0.0, (r + -r) / (r - -r), 0.0
    out[1, 1, 0], out[1, 1, 1], out[1, 1, 2], out[1, 1, 3] = 0.0, 2 * near / (t - -t), (t + -t) / (t - -t), 0.0
    out[1, 2, 0], out[1, 2, 1] = 0.0, 0.0
    out[1, 2, 2], out[1, 2, 3] = -(far + near) / (far - near), -2 * far * near / (far - near)
    out[1, 3, 0], out[1, 3, 1], out[1, 3, 2], out[1, 3, 3] = 0.0, 0.0, -1.0, 0.0
    lx, ly, lz = 0.3 * sx + 0.5 * ux + 0.8 * -fx, 0.3 * sy + 0.5 * uy + 0.8 * -fy, 0.3 * sz + 0.5 * uz + 0.8 * -fz
    m = math.sqrt(lx * lx + ly * ly + lz * lz)
    out[2, 0, 0], out[2, 0, 1], out[2, 0, 2] = lx / m, ly / m, lz / m
    return True


def _frame(eye, target, up, fov_deg, near, far, aspect) -> np.ndarray:
    """``camera_into`` on a fresh (3, 4, 4) array; refuses coinciding position and target."""
    out = np.zeros((3, 4, 4))
    if not camera_into(float(eye[0]), float(eye[1]), float(eye[2]), float(target[0]), float(target[1]),
                       float(target[2]), float(up[0]), float(up[1]), float(up[2]), float(fov_deg), float(near),
                       float(far), float(aspect), out):
        raise ValueError("camera position and target coincide")
    return out


def frustum(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """GL off-axis perspective projection (glFrustum)."""
    return np.array(_frustum_rows(left, right, bottom, top, near, far), dtype=np.float64)


def _frustum_rows(left: float, right: float, bottom: float, top: float, near: float, far: float) -> list:
    return [[2 * near / (right - left), 0.0, (right + left) / (right - left), 0.0],
            [0.0, 2 * near / (top - bottom), (top + bottom) / (top - bottom), 0.0],
            [0.0, 0.0, -(far + near) / (far - near), -2 * far * near / (far - near)],
            [0.0, 0.0, -1.0, 0.0]]


def region_clip(region, size) -> np.ndarray:
    """4x4 clip-space map taking the full display's NDC over ``region`` to [-1, 1]^2: applied
    after the full projection it gives the region's off-axis sub-frustum (glFrustum over the
    region's share of the near plane), algebraically."""
    W, H = size
    x0, y0, x1, y1 = region
    w, h = x1 - x0, y1 - y0
    c = np.eye(4)
    c[0, 0], c[0, 3] = W / w, (W - 2.0 * x0 - w) / w
    c[1, 1], c[1, 3] = H / h, (H - 2.0 * y0 - h) / h
    return c


def model_view(view: np.ndarray, origin) -> np.ndarray:
    """view @ translate(origin) in float64: the camera relative to the scene's vertex origin,
    so float32 vertex coordinates stay small wherever the scene lies in the world."""
    t = np.eye(4)
    t[:3, 3] = np.asarray(origin, dtype=np.float64)
    return np.asarray(view, dtype=np.float64) @ t


def frame_matrices(camera, size) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """view, projection (float64) and the (3,) light direction (towards the viewer, slightly
    above) of ``camera`` on a ``size`` display: views of one array (``camera_into``)."""
    W, H = size
    out = _frame(camera.position, camera.target, camera.up, camera.fov, camera.near, camera.far, W / H)
    return out[0], out[1], out[2, 0, :3]


def unshifted(camera: Camera, offset) -> Camera:
    """``camera`` in path-file coordinates (before ``--offset``)."""
    off = np.asarray(offset, dtype=np.float64)
    if not off.any():
        return camera
    return Camera(tuple(np.asarray(camera.position) - off), tuple(np.asarray(camera.target) - off), camera.up,
                  camera.fov, camera.near, camera.far)
