"""The wall as it stands in the room, and the viewer in front of it: each eye's off-axis frustum
through the wall (Kooima, "Generalized Perspective Projection", as a CAVE forms it).

The room is in metres: x to the right along the wall, y up, z out of the wall towards the
viewer, its origin the wall's centre. The wall (every tile and bezel) is one ``screen`` of
``(W, H)`` metres in the plane z = 0. The walkthrough's camera stands where the viewer's head
stands by default: on the wall's axis at the distance where the wall spans the camera's field
of view, so a head at home with no eye separation sees what the mono camera sees. A wall file
may place each display in the room by its corners instead (a CAVE's walls at any angle,
``screens_of``); the camera then stands at the room's origin. A head moved by some metres moves
the eye by as many metres times ``world_per_metre`` in the scene, along the camera's own axes;
the frustum of an eye at room position ``e`` is the pyramid from ``e`` through a screen's
corners, its view turned to the screen's normal. Pure numpy, float64."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from multigpu.core.camera import Camera, frame_matrices, frustum
from multigpu.core.doors import is_number

#: the eye separation a stereo wall takes unless told (metres: an adult's interpupillary distance)
EYE_SEPARATION = 0.064
#: the largest coordinate (metres) or angle (degrees) a pose may give: a room, not an orbit
MOST_POSE = 1e6
#: the largest parallax a wall of no given size shows, as a share of its width (``focused``): beyond
#: about 3 % a viewer cannot fuse the eyes' pictures
PARALLAX = 0.03
#: the nearest sampled point taken a little nearer still: a vertex between the samples may be
NEAR_MARGIN = 0.9
#: the scene's vertices ``focused`` samples at most (a stereo frame's one matrix product)
FOCUS_SAMPLES = 8192


@dataclass(frozen=True)
class Pose:
    """A head in the room: its position (metres) and orientation (degrees: yaw about y, then
    pitch about x, then roll about z; all 0 looks at the wall with the eyes level)."""

    position: tuple[float, float, float]
    yaw: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0

    def right(self) -> np.ndarray:
        """The head's right-hand direction: where the right eye sits from the left."""
        y, p, r = (math.radians(a) for a in (self.yaw, self.pitch, self.roll))
        cy, sy, cp, sp, cr, sr = math.cos(y), math.sin(y), math.cos(p), math.sin(p), math.cos(r), math.sin(r)
        ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
        rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
        return (ry @ rx @ rz)[:, 0]


@dataclass(frozen=True)
class Screen:
    """Some of the wall's tiles (their labels) in one plane, and the rectangle they span in the
    room: its lower-left, lower-right and upper-left corners (metres)."""

    tiles: tuple[int, ...]
    corners: tuple  # (pa, pb, pc), each an (x, y, z) tuple of floats (hashable: ``_frame_of`` keys on it)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The screen's right, up and normal unit vectors (the normal towards the viewer)."""
        return _frame_of(self.corners)[:3]


@functools.lru_cache(maxsize=256)
def _frame_of(corners: tuple) -> tuple[np.ndarray, ...]:
    """A screen's basis and corner arrays, made once per screen (every frame's eyes look through
    the same few screens): read-only."""
    pa, pb, pc = (np.asarray(p, dtype=np.float64) for p in corners)
    vr, vu = (pb - pa) / np.linalg.norm(pb - pa), (pc - pa) / np.linalg.norm(pc - pa)
    vn = np.cross(vr, vu)
    out = (vr, vu, vn / np.linalg.norm(vn), pa, pb, pc)
    for a in out:
        a.flags.writeable = False
    return out


@dataclass(frozen=True)
class Viewer:
    """Who looks at a ``screen`` = (W, H) metres wall: the eye separation (metres), the head's
    pose when no per-frame pose is given (None: at home, see the module), the scene units a
    metre of head motion moves the eye, and whether the eyes trade places. ``screens``: where the
    wall file places its displays in the room (``screens_of``); none: one flat wall of ``screen``,
    centred on the room's origin in the plane z = 0."""

    screen: tuple[float, float]
    separation: float = EYE_SEPARATION
    head: Pose | None = None
    world_per_metre: float = 1.0
    swap: bool = False
    screens: tuple[Screen, ...] = ()

    def planes(self, tiles: int) -> tuple[Screen, ...]:
        """The screens the eyes look through: the file's, or the one flat wall of all ``tiles``."""
        if self.screens:
            return self.screens
        W, H = self.screen
        return (Screen(tuple(range(tiles)), ((-W / 2, -H / 2, 0.0), (W / 2, -H / 2, 0.0), (-W / 2, H / 2, 0.0))),)

    def home(self, camera: Camera) -> np.ndarray:
        """Where the camera stands in the room: with the displays' corners, the room's origin;
        else on the wall's axis, where the wall spans the camera's vertical fov."""
        if self.screens:
            return np.zeros(3)
        return np.array([0.0, 0.0, self.screen[1] / 2.0 / math.tan(math.radians(camera.fov) / 2.0)])

    def eyes(self, camera: Camera, pose: Pose | None, count: int) -> np.ndarray:
        """(count, 3) room positions of the eyes (one: the head's centre; two: left, right)."""
        pose = pose or self.head
        centre = self.home(camera) if pose is None else np.asarray(pose.position, dtype=np.float64)
        if count == 1:
            return centre[None]
        half = (pose.right() if pose is not None else np.array([1.0, 0.0, 0.0])) * (self.separation / 2.0)
        out = np.stack([centre - half, centre + half])
        return out[::-1] if self.swap else out


def focused(viewer: Viewer, camera: Camera, centre, points: np.ndarray, size: tuple[int, int]) -> Viewer:
    """``viewer`` for a wall whose size in the room nobody gave (the default pixel pitch, no head,
    no tracker): the zero-parallax plane at the scene's focus, as ParaView puts it at its focal
    point, and the eyes as far apart as keeps every visible point's parallax within ``PARALLAX``
    of the wall's width (never farther apart than ``viewer``'s). ``points``: (M, 4) float32
    homogeneous samples of the scene's vertices about ``centre``, whose nearest one in the
    camera's frustum (``size``: the canvas) bounds the depth. The screen stands at the scene
    centre's depth, or at twice the nearest point's where that is nearer: a point at depth z is
    s (1 - focus / z) metres apart on the screen, so from half the focus to infinity within s."""
    pos = np.asarray(camera.position, dtype=np.float64)
    ahead = np.asarray(camera.target, dtype=np.float64) - pos
    ahead /= max(float(np.linalg.norm(ahead)), 1e-300)
    view, proj, _ = frame_matrices(camera, size)
    move = np.eye(4)
    move[:3, 3] = centre  # ``points`` are about the centre, in float32: the product in float32 too
    clip = points @ (proj @ view @ move).astype(np.float32).T  # a few thousand points: one matrix product
    w = clip[:, 3]
    seen = (w > 0) & (np.abs(clip[:, 0]) <= w) & (np.abs(clip[:, 1]) <= w) & (np.abs(clip[:, 2]) <= w)
    nearest = NEAR_MARGIN * float(w[seen].min()) if seen.any() else np.inf
    focus = max(float((np.asarray(centre, dtype=np.float64) - pos) @ ahead), 2.0 * camera.near)
    focus = min(focus, 2.0 * nearest) if np.isfinite(nearest) else focus
    separation = PARALLAX * viewer.screen[0] / max(1.0, focus / max(nearest, 1e-300) - 1.0)
    return replace(viewer, separation=min(viewer.separation, separation),
                   world_per_metre=focus / float(viewer.home(camera)[2]))


def eye_frame(camera: Camera, viewer: Viewer, eye: np.ndarray, screen: Screen, axes=None) -> tuple:
    """(view, proj, light) of the eye at room position ``eye`` through ``screen``: the camera's
    axes moved to the eye and turned to the screen's, and the off-axis frustum from the eye
    through the screen's corners (the camera's near and far). ``axes``: the camera's (view,
    light), where the caller has them (one frame's eyes and screens share them)."""
    view, light = axes or frame_matrices(camera, (1, 1))[::2]
    q = (eye - viewer.home(camera)) * viewer.world_per_metre  # the eye in the camera's view space
    move = np.eye(4)
    move[:3, 3] = -q
    vr, vu, vn, pa, pb, pc = _frame_of(screen.corners)
    va, vb, vc = pa - eye, pb - eye, pc - eye
    d = -float(va @ vn)  # the eye's distance to the screen's plane (the door keeps it > 0)
    k = camera.near / d
    proj = frustum(float(vr @ va) * k, float(vr @ vb) * k, float(vu @ va) * k, float(vu @ vc) * k, camera.near,
                   camera.far)
    turn = np.eye(4)
    turn[:3, :3] = np.stack([vr, vu, vn])
    return turn @ move @ view, proj, light


def eye_frames(camera: Camera, viewer: Viewer, pose: Pose | None, count: int, tiles: int = 1) -> list:
    """Every eye's (view, proj, light) through every screen, ``[eye][screen]``, for a frame:
    ``count`` 1 (a tracked mono wall) or 2; ``tiles``: the wall's (for its one flat screen)."""
    planes, axes = viewer.planes(tiles), frame_matrices(camera, (1, 1))[::2]
    return [[eye_frame(camera, viewer, e, sc, axes) for sc in planes] for e in viewer.eyes(camera, pose, count)]


def head_problem(pose: Pose, viewer: Viewer, tiles: int = 1) -> str | None:
    """Why a head cannot look at the wall from ``pose`` (None: it can): an eye on or behind a
    screen's plane has no frustum through it."""
    if not all(math.isfinite(float(v)) for v in pose.position):
        return "a head position must be finite"
    half = pose.right() * viewer.separation / 2.0
    centre = np.asarray(pose.position, dtype=np.float64)
    for sc in viewer.planes(tiles):  # a few screens
        vr, vu, vn = sc.basis()
        near = min(float((e - np.asarray(sc.corners[0])) @ vn) for e in (centre - half, centre + half))
        if near <= 0:
            where = "z = {:g} m".format(centre[2]) if not viewer.screens else "({})".format(
                ", ".join(f"{v:g}" for v in centre))
            return (f"a viewer at {where} has an eye behind the screen or inside its plane"
                    + (" (z is metres out of the wall, towards the viewer)" if not viewer.screens else
                       f" (the screen of tiles {', '.join(map(str, sc.tiles))})"))
    return None


def screens_of(corners: dict, tile_rects: np.ndarray, tolerance: float = 0.002) -> tuple[Screen, ...]:
    """The wall's screens from each tile's room corners (``corners[k]``: lower-left, lower-right,
    upper-left) and canvas rects: tiles in one plane that sit as the canvas places them (within
    ``tolerance`` metres) share one screen, so one frustum per eye draws them all; any other tile
    is a screen of its own."""
    out, left = [], sorted(corners)
    while left:  # tiles, a few dozen at most
        k = left.pop(0)
        pa, pb, pc = (np.asarray(p, dtype=np.float64) for p in corners[k])
        x0, y0, x1, y1 = (float(v) for v in tile_rects[k])
        ux, uy = (pb - pa) / (x1 - x0), (pc - pa) / (y1 - y0)  # metres per canvas pixel along x and y
        at = lambda x, y: pa + (x - x0) * ux + (y - y0) * uy  # noqa: E731  canvas pixel -> room
        group = [k]
        for j in list(left):
            a0, b0, a1, b1 = (float(v) for v in tile_rects[j])
            want = (at(a0, b0), at(a1, b0), at(a0, b1))
            if all(np.linalg.norm(np.asarray(p) - w) <= tolerance for p, w in zip(corners[j], want)):
                group.append(j)
                left.remove(j)
        r = np.asarray(tile_rects)[group]
        gx0, gy0, gx1, gy1 = r[:, 0].min(), r[:, 1].min(), r[:, 2].max(), r[:, 3].max()
        out.append(Screen(tuple(group), tuple(tuple(float(v) for v in at(x, y))
                                              for x, y in ((gx0, gy0), (gx1, gy0), (gx0, gy1)))))
    return tuple(out)


def rectangle_problem(corners) -> str | None:
    """Why three corners (lower-left, lower-right, upper-left) do not make a display (None: they do)."""
    pa, pb, pc = (np.asarray(p, dtype=np.float64) for p in corners)
    if not all(is_number(float(v), -MOST_POSE, MOST_POSE) for p in (pa, pb, pc) for v in p):
        return f"every coordinate must be a finite number of metres within +-{MOST_POSE:g}"
    w, h = np.linalg.norm(pb - pa), np.linalg.norm(pc - pa)
    if not (w > 0 and h > 0):
        return "two corners coincide"
    if abs(float((pb - pa) @ (pc - pa))) > 1e-3 * w * h:
        return "its edges are not at right angles: the corners do not make a rectangle"
    return None


def screen_size(canvas_size: tuple[int, int], pitch_mm: tuple[float, float]) -> tuple[float, float]:
    """The wall's (W, H) in metres from its canvas pixels (bezels included) and pixel pitch."""
    return canvas_size[0] * pitch_mm[0] / 1000.0, canvas_size[1] * pitch_mm[1] / 1000.0


def pose_of(row) -> Pose | str:
    """A pose from a file's row or a tracker's message (parsed JSON): ``[x, y, z]``, ``[x, y, z,
    yaw, pitch, roll]`` or ``{"position": [x, y, z], "yaw": .., "pitch": .., "roll": ..}``
    (orientation optional), metres and degrees; else why not (a string)."""
    if isinstance(row, dict):
        extra = set(row) - {"position", "yaw", "pitch", "roll", "t"}
        if extra:
            return f"unknown key {sorted(extra)[0][:20]!r} (known: position, yaw, pitch, roll, t)"
        at = row.get("position")
        if not isinstance(at, list):
            return "position must be [x, y, z]"
        row = [*at, *(row.get(k, 0.0) for k in ("yaw", "pitch", "roll"))]
        if len(row) != 6:
            return "position must be [x, y, z]"
    ok = (isinstance(row, list) and len(row) in (3, 6)
          and all(is_number(v, -MOST_POSE, MOST_POSE) for v in row))
    if not ok:
        return f"must be [x, y, z] or [x, y, z, yaw, pitch, roll] (numbers within +-{MOST_POSE:g})"
    return Pose(tuple(float(v) for v in row[:3]), *(float(v) for v in row[3:]))
