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

from multigpu.core.camera import Camera
from multigpu.errors import InputError, check_file

DEFAULTS = {"fov": 60.0, "near": 0.1, "far": 1000.0, "up": [0.0, 0.0, 1.0]}
MAX_FRAMES = 10_000_000  # a path longer than this is a typo, not a walkthrough
MAX_COORD = 1e15  # world coordinates beyond this lose all float64 precision below a metre


@dataclass
class CameraPath:
    """Per-frame cameras as arrays: position, target, up (F, 3); fov, near, far (F,); ``times``
    (F,): a moving scene's time at each frame where the file gives one (a steered run's
    recording), else None (the frame's own: ``core.motion.scene_time``); ``steps`` (F,): the
    step of a series each frame showed where the file gives it (a recorded run: its replay shows
    the same steps, late ones included), else None."""

    position: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov: np.ndarray
    near: np.ndarray
    far: np.ndarray
    times: np.ndarray | None = None
    steps: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.position.shape[0])

    def camera(self, i: int) -> Camera:
        return Camera(tuple(self.position[i]), tuple(self.target[i]), tuple(self.up[i]),
                      float(self.fov[i]), float(self.near[i]), float(self.far[i]))

    def translated(self, offset) -> "CameraPath":
        """The same path moved by ``offset`` world units."""
        off = np.asarray(offset, dtype=np.float64).reshape(3)
        return CameraPath(self.position + off, self.target + off, self.up, self.fov, self.near, self.far, self.times,
                          self.steps)

    def to_json(self) -> dict:
        cams = [{"position": self.position[i].tolist(), "target": self.target[i].tolist(),
                 "up": self.up[i].tolist(), "fov": float(self.fov[i]), "near": float(self.near[i]),
                 "far": float(self.far[i])} for i in range(len(self))]
        return {"version": 1, "cameras": cams}

    def save(self, path: Path) -> None:
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            tmp.write_text(json.dumps(self.to_json()))
            tmp.replace(path)
        finally:
            tmp.unlink(missing_ok=True)  # written whole or not at all


def catmull_rom(points: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Uniform Catmull-Rom spline through ``points`` (K, D) at parameters ``t`` in [0, K-1]."""
    k = points.shape[0]
    if k == 1:
        return np.repeat(points, t.size, axis=0)
    ext = np.concatenate([2 * points[:1] - points[1:2], points, 2 * points[-1:] - points[-2:-1]])
    i = np.clip(np.floor(t).astype(int), 0, k - 2)
    u = (t - i)[:, None]
    p0, p1, p2, p3 = ext[i], ext[i + 1], ext[i + 2], ext[i + 3]
    a, b = 2 * p0 - 5 * p1 + 4 * p2 - p3, -p0 + 3 * p1 - 3 * p2 + p3
    return 0.5 * ((2 * p1) + (-p0 + p2) * u + a * u**2 + b * u**3)


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
    eye, tgt = np.array(out["position"]), np.array(out["target"])
    if not np.linalg.norm(tgt - eye) > 1e-12 * max(np.abs(eye).max(), np.abs(tgt).max(), 1.0):  # as check_cameras
        raise InputError(f"{where}: position and target coincide")
    return out


def load_path(path: str | Path) -> CameraPath:
    """Read and validate a path file; every problem is one InputError naming file and field."""
    path = check_file(path, "path", "path file")
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
        times = [c.get("time") for c in doc["cameras"]]
        if any(t is not None for t in times):  # a scene's time per frame: every camera's, finite
            times = [_number(t, f"{path}: cameras[{i}].time", -1e15, 1e15) for i, t in enumerate(times)]
        steps = [c.get("step") for c in doc["cameras"]]
        if any(k is not None for k in steps):  # a series' step per frame: every camera's, a whole number
            steps = [_number(k, f"{path}: cameras[{i}].step", -1, 1e9) // 1 for i, k in enumerate(steps)]
        return CameraPath(arr("position"), arr("target"), arr("up"), arr("fov"), arr("near"), arr("far"),
                          None if times[0] is None else np.asarray(times, dtype=np.float64),
                          None if steps[0] is None else np.asarray(steps, dtype=np.int64))
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


#: the plant's ground diagonal in its own units (metres): the walkthrough's eye heights were
#: tuned on it, and scale with a scene's ground diagonal from there
REFERENCE_GROUND = 233.0
#: a scene whose ground is less than this many times its height is compact (an engine, a statue)
COMPACT = 2.0
#: a wide scene's flight heights are fractions of its height, but at least this fraction of its
#: ground: a flat scene would otherwise be flown through edge on, the eye in its plane
FLAT = 0.02


def walkthrough(scene, frames: int = 1200, fov: float = 60.0) -> CameraPath:
    """A camera path that sees the scene in every frame, at any scale (every length is a
    fraction of the scene's size).

    A scene whose meta holds a ``route`` (keyframes: the city's streets) is driven along it.
    Wide scenes (a plant, a city, a track): fly through, low through the densest of 6 x 6
    ground cells and high over sparse ones (so the screen distribution of load changes
    strongly over time), starting and ending with an overview. Compact scenes (ground under
    ``COMPACT`` times the height): an overview circle, then close looks at the densest parts
    from outside the bounding sphere. Deterministic for a scene; the up axis is the scene's
    ``meta['up']`` (its sign included).
    """
    lo, hi, up, diag = _frame_of(scene)
    if scene.meta.get("route"):  # a scene that knows a real-looking route (the city's streets)
        keys = scene.meta["route"]
        path = from_keyframes(keys, frames, {"fov": fov, "near": diag * 1e-4, "far": 3 * diag, "up": up.tolist()})
        return look_at_something(path, scene)
    ax = int(np.argmax(np.abs(up)))
    g = [a for a in range(3) if a != ax]
    span = np.maximum(hi - lo, 1e-300)
    ground_span = float(np.hypot(span[g[0]], span[g[1]]))
    if ground_span < COMPACT * span[ax]:
        return _compact_path(scene, frames, fov)
    sign = 1.0 if up[ax] >= 0 else -1.0
    n = 6
    cell = np.clip(((scene.centers[:, g] - lo[g]) / span[g] * n).astype(int), 0, n - 1)
    flat = cell[:, 0] * n + cell[:, 1]
    w = scene.tris.astype(np.float64)
    mass = np.bincount(flat, weights=w, minlength=n * n)
    # where each cell's content is (triangle-weighted object centres): stops look at content
    content = np.stack([np.bincount(flat, weights=w * scene.centers[:, a], minlength=n * n) for a in range(3)], 1)
    content /= np.maximum(mass, 1e-300)[:, None]
    order = np.argsort(-mass, kind="stable")
    dense = order[:3]
    sparse = [c for c in order[::-1] if mass[c] > 0][:3]
    height = max(span[ax], FLAT * ground_span)  # a flat scene (a floor plan, a terrain) is flown above
    ground = lo[ax] if sign > 0 else hi[ax]  # the floor seen from the up side
    unit = ground_span / REFERENCE_GROUND  # one plant metre in scene units

    def point(c, h):
        p = content[c].copy()
        p[ax] = ground + sign * h
        return p

    eye_low = min(0.08 * height + 1.5 * unit, 0.3 * height)
    overview_a = lo.copy()
    overview_a[ax] = ground + sign * (0.6 * height + 0.15 * diag)
    overview_a[g[0]] -= 0.15 * span[g[0]]
    overview_b = hi.copy()
    overview_b[ax] = overview_a[ax]
    overview_b[g[1]] += 0.15 * span[g[1]]
    stops, looks = [overview_a], []
    for d, s_ in zip(dense, sparse):
        stops += [point(d, eye_low), point(s_, 0.35 * height + 2 * unit)]
        looks += [d, s_]
    stops.append(overview_b)
    pos = np.array(stops)
    # look ahead: at the content of the next stop's cell, the last stop back at the centre
    centre = (lo + hi) / 2
    tgt = np.vstack([content[looks], centre[None]]) if looks else centre[None].repeat(len(pos), 0)
    tgt[:, ax] = ground + sign * np.clip(sign * (tgt[:, ax] - ground), 0.0, 0.2 * height)
    keys = [{"position": p.tolist(), "target": t.tolist()} for p, t in zip(pos, tgt)]
    path = from_keyframes(keys, frames, {"fov": fov, "near": diag * 1e-4, "far": 3 * diag, "up": up.tolist()})
    # the spline may overshoot between low stops: keep the eye above half the low eye height
    floor = ground + sign * 0.5 * eye_low
    path.position[:, ax] = floor + sign * np.maximum(sign * (path.position[:, ax] - floor), 0.0)
    return look_at_something(path, scene)


#: generated paths check visibility against at most this many (the largest) objects
CHECK_OBJECTS = 4096


def look_at_something(path: CameraPath, scene, aspect: float = 1.0) -> CameraPath:
    """Turn every frame that would see none of the scene's largest objects towards the object
    nearest its eye, so a generated path never shows an empty screen (at most ``CHECK_OBJECTS``
    bounds projected a frame, every frame in one compiled call: big scenes and long paths alike)."""
    from multigpu.core.bounds import BoxProjector
    from multigpu.core.camera import frame_matrices

    keep = np.argsort(-scene.tris, kind="stable")[:CHECK_OBJECTS]
    project = BoxProjector(scene.bmin[keep], scene.bmax[keep])
    size = (max(int(round(256 * aspect)), 1), 256)
    seen = project.frames_seen(path.position, path.target, path.up, path.fov, path.near, path.far, size)
    for f in np.flatnonzero(seen < 1):  # the frames that see nothing (or whose camera the check refused)
        view, proj, _ = frame_matrices(path.camera(f), size)  # (a refused camera: its error, raised here)
        r = project(view, proj)
        with np.errstate(invalid="ignore"):
            if ((r[:, 2] >= 0) & (r[:, 0] <= 1) & (r[:, 3] >= 0) & (r[:, 1] <= 1)).any():
                continue
        d = np.linalg.norm(scene.centers - path.position[f], axis=1) - scene.radii
        ahead = d > path.near[f] * 2  # objects not already at the eye
        near = int(np.argmin(np.where(ahead, d, np.inf)) if ahead.any() else np.argmin(d))
        path.target[f] = scene.centers[near]
    return _apart(path, scene)


def _apart(path: CameraPath, scene) -> CameraPath:
    """Every frame's target apart from its position (a stop whose eye sits on what it looks at:
    a flat, tiny or one-object scene, a short path that lands on its keyframes): such a frame
    looks at the scene's centre instead, or along a ground axis where the eye is there too."""
    lo, hi, up, diag = _frame_of(scene)
    scale = diag + np.abs(path.position).max(axis=1)
    gap = np.linalg.norm(path.target - path.position, axis=1)
    close = ~(gap > 1e-9 * scale)  # NaN too
    if close.any():
        centre = (lo + hi) / 2
        ax = int(np.argmax(np.abs(up)))
        along = np.eye(3)[(ax + 1) % 3] * max(diag, 1e-300)  # a ground axis, for an eye at the centre
        to_centre = centre - path.position[close]
        far_enough = np.linalg.norm(to_centre, axis=1) > 1e-9 * scale[close]
        path.target[close] = np.where(far_enough[:, None], centre, path.position[close] + along)
    return path


def _compact_path(scene, frames: int, fov: float) -> CameraPath:
    """Overview circle (first 40 %), then close looks at the densest parts (3-D cells of the
    bounding box, by triangles) from 1.3 bounding radii, eye always outside the bounding
    sphere, so no frame is inside the model and every frame looks at it."""
    lo, hi, up, diag = _frame_of(scene)
    ax = int(np.argmax(np.abs(up)))
    g = [a for a in range(3) if a != ax]
    centre = (lo + hi) / 2
    radius = max(diag / 2, 1e-300)
    far_d = radius / np.sin(np.radians(fov) / 2) * 1.05  # the whole sphere in view
    n_over = max(1, int(round(frames * 0.4)))
    ang = np.linspace(0, 2 * np.pi, n_over, endpoint=False)
    el = np.radians(25.0)
    over = np.tile(centre, (n_over, 1))
    over[:, g[0]] += far_d * np.cos(el) * np.cos(ang)
    over[:, g[1]] += far_d * np.cos(el) * np.sin(ang)
    over[:, ax] += np.sign(up[ax]) * far_d * np.sin(el)
    # the densest 3-D cells, looked at from outside along the ray from the centre
    n = 4
    span = np.maximum(hi - lo, 1e-300)
    cell = np.clip(((scene.centers - lo) / span * n).astype(int), 0, n - 1)
    flat = (cell[:, 0] * n + cell[:, 1]) * n + cell[:, 2]
    mass = np.bincount(flat, weights=scene.tris.astype(np.float64), minlength=n ** 3)
    cells = np.argsort(-mass, kind="stable")[:4]
    cells = cells[mass[cells] > 0]
    idx = np.stack([cells // (n * n), (cells // n) % n, cells % n], axis=1)
    looks = lo + (idx + 0.5) * span / n
    rng = looks - centre
    rng[:, ax] = np.abs(rng[:, ax]) * np.sign(up[ax]) + 0.3 * radius * np.sign(up[ax])  # from above the part
    dirs = rng / np.maximum(np.linalg.norm(rng, axis=1, keepdims=True), 1e-300)
    eyes = centre + dirs * 1.3 * radius
    keys = [{"position": over[-1].tolist(), "target": centre.tolist()}]
    keys += [{"position": e.tolist(), "target": t.tolist()} for e, t in zip(eyes, looks)]
    keys.append({"position": over[0].tolist(), "target": centre.tolist()})
    near = 0.02 * radius
    close = from_keyframes(keys, frames - n_over, {"fov": fov, "near": near, "far": far_d + 2 * radius,
                                                   "up": up.tolist()}) if frames > n_over else None
    # the spline between outside stops can cut inside the sphere: push eyes back out
    if close is not None:
        off = close.position - centre
        dist = np.linalg.norm(off, axis=1, keepdims=True)
        close.position = centre + off * np.maximum(1.0, 1.15 * radius / np.maximum(dist, 1e-300))
    ones = np.ones(n_over)
    overview = CameraPath(over, np.tile(centre, (n_over, 1)), np.tile(up, (n_over, 1)), fov * ones, near * ones,
                          (far_d + 2 * radius) * ones)
    if close is None:
        return look_at_something(overview, scene)
    return look_at_something(CameraPath(*(np.concatenate([getattr(overview, k), getattr(close, k)]) for k in
                                          ("position", "target", "up", "fov", "near", "far"))), scene)


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
    pos[:, ax] += np.sign(up[ax]) * dist * np.sin(el)
    ones = np.ones(frames)
    near = max(dist - radius * 1.01, diag * 1e-4)
    return CameraPath(pos, np.tile(centre, (frames, 1)), np.tile(up, (frames, 1)), fov * ones,
                      near * ones, (dist + radius * 1.01) * ones)


#: the generated paths, and their frame counts when none is asked for
def still(scene, frames: int = 300, fov: float = 60.0) -> CameraPath:
    """The camera held where the walkthrough starts: a scene's own motion watched and measured alone."""
    first = walkthrough(scene, fov=fov)  # its default length: the same first camera as the walkthrough
    return CameraPath(*(np.repeat(a[:1], frames, axis=0) for a in (first.position, first.target, first.up,
                                                                   first.fov, first.near, first.far)))


GENERATORS = {"walkthrough": walkthrough, "orbit": orbit, "still": still}
DEFAULT_FRAMES = {"walkthrough": 1200, "orbit": 300, "still": 300}


def generate(kind: str, scene, frames: int | None = None, fov: float = 60.0) -> CameraPath:
    """A generated camera path of ``kind`` (walkthrough | orbit) for ``scene``."""
    if kind not in GENERATORS:
        raise InputError.of("path_kind", f"must be one of {', '.join(GENERATORS)}, got '{kind}'")
    if frames is not None and not 1 <= frames <= MAX_FRAMES:
        raise InputError.of("frames", f"must be in 1..{MAX_FRAMES}, got {frames}")
    return GENERATORS[kind](scene, frames=frames or DEFAULT_FRAMES[kind], fov=fov)
