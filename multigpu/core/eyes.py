"""The wall as it stands in the room, and the viewer in front of it: each eye's off-axis frustum
through the wall (Kooima, "Generalized Perspective Projection", as a CAVE forms it).

The room is in metres: x to the right along the wall, y up, z out of the wall towards the
viewer, its origin the wall's centre. The wall (every tile and bezel) is one ``screen`` of
``(W, H)`` metres in the plane z = 0. The walkthrough's camera stands where the viewer's head
stands by default: on the wall's axis at the distance where the wall spans the camera's field
of view, so a head at home with no eye separation sees what the mono camera sees. A head moved
by some metres moves the eye by as many metres times ``world_per_metre`` in the scene, along the
camera's own axes; the frustum of an eye at room position ``e`` is the pyramid from ``e``
through the wall's four corners, its view along the camera's axes (the wall's normal). Pure
numpy, float64.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from multigpu.core.camera import Camera, frame_matrices, frustum

#: the eye separation a stereo wall takes unless told (metres: an adult's interpupillary distance)
EYE_SEPARATION = 0.064


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
class Viewer:
    """Who looks at a ``screen`` = (W, H) metres wall: the eye separation (metres), the head's
    pose when no per-frame pose is given (None: at home, see the module), the scene units a
    metre of head motion moves the eye, and whether the eyes trade places."""

    screen: tuple[float, float]
    separation: float = EYE_SEPARATION
    head: Pose | None = None
    world_per_metre: float = 1.0
    swap: bool = False

    def home(self, camera: Camera) -> np.ndarray:
        """Where the camera stands in the room: on the axis, the wall spanning its vertical fov."""
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


def eye_frame(camera: Camera, viewer: Viewer, eye: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(view, proj, light) of the eye at room position ``eye``: the camera's axes moved to the
    eye, and the off-axis frustum from it through the wall's corners (the camera's near and far)."""
    view, _, light = frame_matrices(camera, (1, 1))
    W, H = viewer.screen
    q = (eye - viewer.home(camera)) * viewer.world_per_metre  # the eye in the camera's view space
    move = np.eye(4)
    move[:3, 3] = -q
    d = float(eye[2])  # the eye's distance to the wall's plane (the door keeps it > 0)
    k = camera.near / d
    proj = frustum((-W / 2 - eye[0]) * k, (W / 2 - eye[0]) * k, (-H / 2 - eye[1]) * k, (H / 2 - eye[1]) * k,
                   camera.near, camera.far)
    return move @ view, proj, light


def eye_frames(camera: Camera, viewer: Viewer, pose: Pose | None, count: int) -> list:
    """Every eye's (view, proj, light) for a frame: ``count`` 1 (a tracked mono wall) or 2."""
    return [eye_frame(camera, viewer, e) for e in viewer.eyes(camera, pose, count)]


def head_problem(pose: Pose, viewer: Viewer) -> str | None:
    """Why a head cannot look at the wall from ``pose`` (None: it can): an eye on or behind the
    wall's plane has no frustum through it."""
    z = float(pose.position[2])
    lowest = z - abs(float(pose.right()[2])) * viewer.separation / 2.0
    if not (math.isfinite(z) and all(math.isfinite(float(v)) for v in pose.position)):
        return "a head position must be finite"
    if lowest <= 0:
        return (f"a viewer at z = {z:g} m has an eye behind the screen or inside its plane "
                "(z is metres out of the wall, towards the viewer)")
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
            return f"unknown key '{sorted(extra)[0]}' (known: position, yaw, pitch, roll, t)"
        at = row.get("position")
        if not isinstance(at, list):
            return "position must be [x, y, z]"
        row = [*at, *(row.get(k, 0.0) for k in ("yaw", "pitch", "roll"))]
        if len(row) != 6:
            return "position must be [x, y, z]"
    ok = (isinstance(row, list) and len(row) in (3, 6)
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in row))
    if not ok:
        return "must be [x, y, z] or [x, y, z, yaw, pitch, roll] (finite numbers)"
    return Pose(tuple(float(v) for v in row[:3]), *(float(v) for v in row[3:]))
