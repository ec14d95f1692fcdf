"""Camera paths: a JSON format, smooth interpolation, and walkthrough / orbit generators.

File format (``--path FILE``), version 1, either keyframes::

    {"version": 1, "frames": 1200, "fov": 60, "near": 0.05, "far": 600, "up": [0, 0, 1],
     "keyframes": [{"position": [x, y, z], "target": [x, y, z]}, ...]}

where each keyframe may also set ``up``, ``fov``, ``near`` and ``far``; positions and targets
are interpolated with a Catmull-Rom spline through the keyframes (C1-continuous), fov, near and
far linearly, ``up`` by normalized linear interpolation; or explicit cameras, one per frame::

    {"version": 1, "cameras": [{"position": ..., "target": ..., "up": ..., "fov": ...}, ...]}

``frames`` (keyframe form) defaults to 1200, like the paper's walkthrough.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .camera import Camera
from .errors import InputError, check_file

DEFAULTS = {"fov": 60.0, "near": 0.1, "far": 1000.0, "up": [0.0, 0.0, 1.0]}
MAX_FRAMES = 10_000_000  # a path longer than this is a typo, not a walkthrough
MAX_COORD = 1e15  # world coordinates beyond this lose all float64 precision below a metre


@dataclass
class CameraPath:
    """Per-frame cameras as arrays: position, target, up (F, 3); fov, near, far (F,)."""

    position: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov: np.ndarray
    near: np.ndarray
    far: np.ndarray

    def __len__(self) -> int:
        return int(self.position.shape[0])

    def camera(self, i: int) -> Camera:
        return Camera(tuple(self.position[i]), tuple(self.target[i]), tuple(self.up[i]),
                      float(self.fov[i]), float(self.near[i]), float(self.far[i]))

    def translated(self, offset) -> "CameraPath":
        """The same path moved by ``offset`` world units."""
        off = np.asarray(offset, dtype=np.float64).reshape(3)
        return CameraPath(self.position + off, self.target + off, self.up, self.fov, self.near, self.far)

    def to_json(self) -> dict:
        cams = [{"position": self.position[i].tolist(), "target": self.target[i].tolist(),
                 "up": self.up[i].tolist(), "fov": float(self.fov[i]), "near": float(self.near[i]),
                 "far": float(self.far[i])} for i in range(len(self))]
        return {"version": 1, "cameras": cams}

    def save(self, path: Path) -> None:
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(self.to_json()))
        tmp.replace(path)


def catmull_rom(points: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Uniform Catmull-Rom spline through ``points`` (K, D) at parameters ``t`` in [0, K-1]."""
    k = points.shape[0]
    if k == 1:
        return np.repeat(points, t.size, axis=0)
    ext = np.concatenate([2 * points[:1] - points[1:2], points, 2 * points[-1:] - points[-2:-1]])
    i = np.clip(np.floor(t).astype(int), 0, k - 2)
    u = (t - i)[:, None]
    p0, p1, p2, p3 = ext[i], ext[i + 1], ext[i + 2], ext[i + 3]
    return 0.5 * ((2 * p1) + (-p0 + p2) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u**2 + (-p0 + 3 * p1 - 3 * p2 + p3) * u**3)


def from_keyframes(keys: list[dict], frames: int, defaults: dict) -> CameraPath:
    pos = np.array([k["position"] for k in keys], dtype=np.float64)
    tgt = np.array([k["target"] for k in keys], dtype=np.float64)
    t = np.linspace(0, len(keys) - 1, frames)
    lin = lambda name: np.interp(t, np.arange(len(keys)), [float(k.get(name, defaults[name])) for k in keys])
    ups = np.array([k.get("up", defaults["up"]) for k in keys], dtype=np.float64)
    i = np.clip(np.floor(t).astype(int), 0, max(len(keys) - 2, 0))
    u = (t - i)[:, None]
    j = np.minimum(i + 1, len(keys) - 1)
    up = ups[i] * (1 - u) + ups[j] * u
    up /= np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-12)
    return CameraPath(catmull_rom(pos, t), catmull_rom(tgt, t), up, lin("fov"), lin("near"), lin("far"))


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _float(v) -> float | None:
    """A JSON number as a finite float, or None (bools, strings, NaN, numbers beyond float)."""
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        return None
    try:
        f = float(v)
    except OverflowError:
        return None
    return f if np.isfinite(f) else None


def _vec3(value, where: str) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise InputError(f"{where} must be a list of 3 numbers, got {_short(value)}")
    out = [_float(v) for v in value]
    if any(v is None or abs(v) > MAX_COORD for v in out):
        raise InputError(f"{where} must be 3 finite numbers of magnitude <= {MAX_COORD:g}, got {_short(value)}")
    return out


def _number(value, where: str, lo: float, hi: float) -> float:
    f = _float(value)
    if f is None or not (lo < f < hi):
        raise InputError(f"{where} must be a number in ({lo:g}, {hi:g}), got {_short(value)}")
    return f


def _check_camera(cam, where: str, defaults: dict, need_up: bool = False) -> dict:
    if not isinstance(cam, dict):
        raise InputError(f"{where} must be an object, got {type(cam).__name__}")
    out = {}
    for key in ("position", "target"):
        if key not in cam:
            raise InputError(f"{where} is missing the field '{key}'")
        out[key] = _vec3(cam[key], f"{where}.{key}")
    out["up"] = _vec3(cam.get("up", defaults["up"]), f"{where}.up")
    out["fov"] = _number(cam.get("fov", defaults["fov"]), f"{where}.fov", 0.0, 180.0)
    out["near"] = _number(cam.get("near", defaults["near"]), f"{where}.near", 0.0, float("inf"))
    out["far"] = _number(cam.get("far", defaults["far"]), f"{where}.far", out["near"], float("inf"))
    if np.allclose(out["position"], out["target"]):
        raise InputError(f"{where}: position and target coincide")
    return out


def load_path(path: str | Path) -> CameraPath:
    """Read and validate a path file; every problem is one InputError naming file and field."""
    path = check_file(path, "--path", "path file")
    try:
        doc = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    except RecursionError:
        raise InputError(f"{path}: not a camera path (JSON nested too deeply)") from None
    except ValueError as exc:  # e.g. an integer of more digits than Python converts
        raise InputError(f"{path}: not a camera path ({str(exc).splitlines()[0]})") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: the top level must be a JSON object")
    if doc.get("version", 1) != 1:
        raise InputError(f"{path}: field 'version' must be 1, got {doc.get('version')!r}")
    defaults = dict(DEFAULTS)
    for key in ("fov", "near", "far"):
        if key in doc:
            defaults[key] = _number(doc[key], f"{path}: field '{key}'", 0.0, 180.0 if key == "fov" else float("inf"))
    if "up" in doc:
        defaults["up"] = _vec3(doc["up"], f"{path}: field 'up'")
    if "cameras" in doc:
        cams = doc["cameras"]
        if not isinstance(cams, list) or not cams:
            raise InputError(f"{path}: field 'cameras' must be a non-empty list")
        cams = [_check_camera(c, f"{path}: cameras[{i}]", defaults) for i, c in enumerate(cams)]
        arr = lambda k: np.array([c[k] for c in cams], dtype=np.float64)
        return CameraPath(arr("position"), arr("target"), arr("up"), arr("fov"), arr("near"), arr("far"))
    if "keyframes" not in doc:
        raise InputError(f"{path}: needs a field 'keyframes' or 'cameras'")
    keys = doc["keyframes"]
    if not isinstance(keys, list) or not keys:
        raise InputError(f"{path}: field 'keyframes' must be a non-empty list")
    keys = [_check_camera(k, f"{path}: keyframes[{i}]", defaults) for i, k in enumerate(keys)]
    frames = doc.get("frames", 1200)
    if not isinstance(frames, int) or isinstance(frames, bool) or not 1 <= frames <= MAX_FRAMES:
        raise InputError(f"{path}: field 'frames' must be an integer in 1..{MAX_FRAMES}, got {_short(frames)}")
    return from_keyframes(keys, frames, defaults)


def check_cameras(path: CameraPath, where: str) -> None:
    """Every frame's camera is usable (vectorized over frames): finite, eye apart from the
    target, 0 < near < far, 0 < fov < 180. Interpolated keyframes can fail this between valid
    keys (a spline through the target), so the door checks every frame, not only the keys."""
    eye, tgt = path.position, path.target
    d = np.linalg.norm(tgt - eye, axis=1)
    scale = np.maximum(np.maximum(np.abs(eye).max(axis=1), np.abs(tgt).max(axis=1)), 1.0)
    checks = [
        (~(np.isfinite(eye).all(axis=1) & np.isfinite(tgt).all(axis=1) & np.isfinite(path.up).all(axis=1)),
         "a position, target or up vector is not finite"),
        (~(d > scale * 1e-12), "the eye meets the target (no view direction)"),
        (~(np.linalg.norm(path.up, axis=1) > 0), "the up vector is zero"),
        (~((path.near > 0) & (path.far > path.near)), "near/far are not 0 < near < far"),
        (~((path.fov > 0) & (path.fov < 180)), "fov is not in (0, 180) degrees"),
    ]
    for bad, what in checks:
        if bad.any():
            f = int(np.flatnonzero(bad)[0])
            raise InputError(f"{where}: frame {f} of {len(path)}: {what}")


# ---------------------------------------------------------------- generators

def _frame_of(scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Scene bounds, up axis, the two ground axes and the diagonal."""
    lo, hi = scene.bounds
    up = np.asarray(scene.meta.get("up", [0, 0, 1]), dtype=np.float64)
    return lo, hi, up, float(np.linalg.norm(hi - lo))


def walkthrough(scene, frames: int = 1200, fov: float = 60.0) -> CameraPath:
    """Fly through the scene, low through its densest parts and high over sparse ones.

    The ground plane is split into 6 x 6 cells weighted by triangles; the path alternates
    between dense and sparse cells (so the screen distribution of load changes strongly over
    time), starting and ending with an overview. Deterministic for a scene.
    """
    lo, hi, up, diag = _frame_of(scene)
    ax = int(np.argmax(np.abs(up)))
    g = [a for a in range(3) if a != ax]
    n = 6
    span = np.maximum(hi - lo, 1e-9)
    cell = np.clip(((scene.centers[:, g] - lo[g]) / span[g] * n).astype(int), 0, n - 1)
    mass = np.zeros((n, n))
    np.add.at(mass, (cell[:, 0], cell[:, 1]), scene.tris.astype(np.float64))
    order = np.argsort(-mass.ravel(), kind="stable")
    dense = order[:3]
    sparse = [c for c in order[::-1] if mass.ravel()[c] >= 0][:3]
    height = span[ax]
    ground = lo[ax]

    def point(c, h):
        p = np.empty(3)
        p[g[0]] = lo[g[0]] + (c // n + 0.5) * span[g[0]] / n
        p[g[1]] = lo[g[1]] + (c % n + 0.5) * span[g[1]] / n
        p[ax] = ground + h
        return p

    eye_low = min(0.08 * height + 1.5, 0.3 * height)
    overview_a = lo.copy()
    overview_a[ax] = ground + 0.6 * height + 0.15 * diag
    overview_a[g[0]] -= 0.15 * span[g[0]]
    overview_b = hi.copy()
    overview_b[ax] = overview_a[ax]
    overview_b[g[1]] += 0.15 * span[g[1]]
    stops = [overview_a]
    for d, s in zip(dense, sparse):
        stops += [point(d, eye_low), point(s, 0.35 * height + 2)]
    stops.append(overview_b)
    pos = np.array(stops)
    # look ahead: towards the next stop, with the last one looking back at the centre
    centre = (lo + hi) / 2
    tgt = np.vstack([pos[1:], centre[None]])
    tgt[:, ax] = np.minimum(tgt[:, ax], ground + 0.2 * height)
    near = max(diag * 1e-4, 1e-4)
    keys = [{"position": p.tolist(), "target": t.tolist()} for p, t in zip(pos, tgt)]
    return from_keyframes(keys, frames, {"fov": fov, "near": near, "far": 3 * diag, "up": up.tolist()})


def orbit(scene, frames: int = 300, fov: float = 60.0, elevation_deg: float = 30.0) -> CameraPath:
    """A circle around the scene that keeps its whole bounding sphere in view."""
    lo, hi, up, diag = _frame_of(scene)
    ax = int(np.argmax(np.abs(up)))
    g = [a for a in range(3) if a != ax]
    centre = (lo + hi) / 2
    radius = diag / 2
    dist = radius / np.sin(np.radians(fov) / 2) * 1.05
    ang = np.linspace(0, 2 * np.pi, frames, endpoint=False)
    el = np.radians(elevation_deg)
    pos = np.tile(centre, (frames, 1))
    pos[:, g[0]] += dist * np.cos(el) * np.cos(ang)
    pos[:, g[1]] += dist * np.cos(el) * np.sin(ang)
    pos[:, ax] += dist * np.sin(el)
    ones = np.ones(frames)
    near = max(dist - radius * 1.01, diag * 1e-4)
    return CameraPath(pos, np.tile(centre, (frames, 1)), np.tile(up, (frames, 1)), fov * ones,
                      near * ones, (dist + radius * 1.01) * ones)
