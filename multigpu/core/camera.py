"""Camera matrices (OpenGL conventions, float64): look-at view, symmetric and off-axis projection."""

from __future__ import annotations

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
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    f = target - eye
    norm = np.linalg.norm(f)
    if not np.isfinite(norm) or norm == 0:
        raise ValueError("camera position and target coincide")
    f /= norm
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-12:  # looking along up: pick any perpendicular
        s = np.cross(f, [1.0, 0.0, 0.0] if abs(f[0]) < 0.9 else [0.0, 1.0, 0.0])
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """Symmetric GL perspective projection (vertical fov in degrees)."""
    t = near * np.tan(np.radians(fov_deg) / 2.0)
    r = t * aspect
    return frustum(-r, r, -t, t, near, far)


def frustum(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """GL off-axis perspective projection (glFrustum)."""
    m = np.zeros((4, 4))
    m[0, 0] = 2 * near / (right - left)
    m[1, 1] = 2 * near / (top - bottom)
    m[0, 2] = (right + left) / (right - left)
    m[1, 2] = (top + bottom) / (top - bottom)
    m[2, 2] = -(far + near) / (far - near)
    m[2, 3] = -2 * far * near / (far - near)
    m[3, 2] = -1.0
    return m


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
    """view, projection (float64) and the light direction (towards the viewer, slightly above)."""
    W, H = size
    view = camera.view()
    proj = camera.projection(W / H)
    light = view[:3, :3].T @ np.array([0.3, 0.5, 0.8])
    return view, proj, light / np.linalg.norm(light)
