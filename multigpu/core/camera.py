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
    return np.array(_look_at_rows(eye, target, up))


def _look_at_rows(eye, target, up) -> list[list[float]]:
    """``look_at`` as rows of Python floats. Scalar float arithmetic: it runs once per frame,
    where numpy's per-call overhead (cross, norm) would cost tens of microseconds for nine
    products."""
    ex, ey, ez = (float(v) for v in eye)
    fx, fy, fz = float(target[0]) - ex, float(target[1]) - ey, float(target[2]) - ez
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    if not math.isfinite(norm) or norm == 0:
        raise ValueError("camera position and target coincide")
    fx, fy, fz = fx / norm, fy / norm, fz / norm
    ux, uy, uz = (float(v) for v in up)
    sx, sy, sz = fy * uz - fz * uy, fz * ux - fx * uz, fx * uy - fy * ux
    if math.sqrt(sx * sx + sy * sy + sz * sz) < 1e-12:  # looking along up: pick any perpendicular
        ux, uy, uz = (1.0, 0.0, 0.0) if abs(fx) < 0.9 else (0.0, 1.0, 0.0)
        sx, sy, sz = fy * uz - fz * uy, fz * ux - fx * uz, fx * uy - fy * ux
    n = math.sqrt(sx * sx + sy * sy + sz * sz)
    sx, sy, sz = sx / n, sy / n, sz / n
    ux, uy, uz = sy * fz - sz * fy, sz * fx - sx * fz, sx * fy - sy * fx
    return [[sx, sy, sz, -(sx * ex + sy * ey + sz * ez)],
            [ux, uy, uz, -(ux * ex + uy * ey + uz * ez)],
            [-fx, -fy, -fz, fx * ex + fy * ey + fz * ez],
            [0.0, 0.0, 0.0, 1.0]]


def perspective(fov_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """Symmetric GL perspective projection (vertical fov in degrees)."""
    return np.array(_perspective_rows(fov_deg, aspect, near, far))


def _perspective_rows(fov_deg: float, aspect: float, near: float, far: float) -> list[list[float]]:
    t = near * math.tan(math.radians(fov_deg) / 2.0)
    r = t * aspect
    return _frustum_rows(-r, r, -t, t, near, far)


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


def frame_matrices(camera, size) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float]]:
    """view, projection (float64; views of one array: one numpy call per frame, not several)
    and the light direction (towards the viewer, slightly above)."""
    W, H = size
    v = _look_at_rows(camera.position, camera.target, camera.up)
    both = np.array((v, _perspective_rows(camera.fov, W / H, camera.near, camera.far)), dtype=np.float64)
    (a0, a1, a2, _), (b0, b1, b2, _), (c0, c1, c2, _), _ = v
    lx, ly, lz = 0.3 * a0 + 0.5 * b0 + 0.8 * c0, 0.3 * a1 + 0.5 * b1 + 0.8 * c1, 0.3 * a2 + 0.5 * b2 + 0.8 * c2
    n = math.sqrt(lx * lx + ly * ly + lz * lz)  # view^T (0.3, 0.5, 0.8), normalized
    return both[0], both[1], (lx / n, ly / n, lz / n)
