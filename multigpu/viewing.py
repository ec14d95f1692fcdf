"""The walkthrough's stereo and viewer settings, read and checked at the door: the wall's size
in metres, the head pose file, and what a mode, a separation and a head must be (``config.py``
declares the flags; ``core/eyes.py`` and ``core/stereo.py`` compute with them)."""

from __future__ import annotations

import numpy as np

from multigpu.errors import InputError

#: a wall's pixel pitch where neither --screen-size nor the wall file's screen_m or bezel gives its size (mm)
DEFAULT_PITCH_MM = 0.5


def read_size_m(text: str) -> tuple[float, float]:
    """``--screen-size W,H`` in metres."""
    from multigpu.readers import read_numbers

    return read_numbers(text, 2, "W,H (the wall's width and height in metres)")


def read_tracker(text: str) -> tuple[str, int]:
    """``--head-tracker [ADDRESS:]PORT``: where rank 0 listens for head poses over UDP (127.0.0.1
    unless an address is given: a tracker on another PC needs the address to listen on, e.g. 0.0.0.0)."""
    address, _, port = str(text).rpartition(":")
    if not port.strip().isdigit() or not 0 < int(port) <= 65535:
        raise InputError(f"must look like [ADDRESS:]PORT with a port 1..65535, got '{text}'")
    return address.strip("[]") or "127.0.0.1", int(port)


#: the largest head pose file read (bytes): a pose a frame for days of frames
MOST_POSE_FILE = 1 << 28


def read_poses(path: str) -> tuple:
    """A head pose file (docs/USAGE.md, "A stereo wall"): JSON, a list (or ``{"poses": [...]}``)
    with a pose per frame, each [x, y, z] or [x, y, z, yaw, pitch, roll] (metres, degrees)."""
    import json

    from multigpu.core.doors import Refusal, parse_json
    from multigpu.core.eyes import pose_of

    try:
        with open(path, "rb") as fh:
            doc = parse_json(fh.read(MOST_POSE_FILE + 1), MOST_POSE_FILE)
    except OSError as exc:
        raise InputError(f"--head-poses {path}: {exc.__class__.__name__}: {exc}") from None
    if isinstance(doc, Refusal):
        raise InputError(f"--head-poses {path}: {doc}")
    rows = doc.get("poses") if isinstance(doc, dict) else doc  # an object may carry a "comment" too
    if not isinstance(rows, list) or not rows:
        raise InputError(f"--head-poses {path}: must be a non-empty list of poses (or {{\"poses\": [...]}})")
    out = []
    for i, row in enumerate(rows):  # the file's poses, read once at the door
        pose = pose_of(row)
        if isinstance(pose, str):
            raise InputError(f"--head-poses {path}: pose {i} {pose}, got {json.dumps(row)[:80]}")
        out.append(pose)
    return tuple(out)


def check_viewer(cfg) -> None:
    """Stereo and the viewer at the door: a mode the presenters can show, packing that fits
    the tile, an eye separation narrower than the wall, every head pose in front of it."""
    from multigpu.core.eyes import Pose, head_problem
    from multigpu.core.stereo import UNSHOWN

    if cfg.stereo in UNSHOWN:
        raise InputError.of("stereo", f"{cfg.stereo}: {UNSHOWN[cfg.stereo]}")
    tw, th = cfg.tile
    from multigpu.core.stereo import splits

    if cfg.eyes in ("split", "own"):
        why = splits(cfg.stereo, cfg.grid, cfg.decomposition, cfg.partition, own=cfg.eyes == "own")
        if why:
            raise InputError.of("eyes", why)
        if cfg.eyes == "own" and cfg.dark:
            raise InputError.of("eyes", "own: a wall without some of its PCs (--dark-tiles) draws both eyes a rank")
    if cfg.stereo == "side-by-side" and tw % 2:
        raise InputError.of("tile", f"{tw}x{th}: side-by-side stereo needs an even tile width (each eye half)")
    if cfg.stereo == "top-bottom" and th % 2:
        raise InputError.of("tile", f"{tw}x{th}: top-bottom stereo needs an even tile height (each eye half)")
    if cfg.screen_m is None:
        object.__setattr__(cfg, "screen_m", tuple(v * DEFAULT_PITCH_MM / 1000.0 for v in cfg.canvas.size))
        # nothing physical given: the wall's size is a guess, so the eyes converge on the scene instead
        # (a copy of the config keeps it: its screen_m is set by then)
        unscaled = (cfg.head is None and not cfg.head_poses and cfg.head_tracker is None and not cfg.corners
                    and cfg.world_per_metre == 1.0)
        object.__setattr__(cfg, "focus", cfg.focus or (unscaled and cfg.stereo != "mono"))
    if cfg.head_poses and not cfg.poses:
        object.__setattr__(cfg, "poses", read_poses(cfg.head_poses))
    if cfg.corners and (len(cfg.corners) != cfg.ranks or any(c is None for c in cfg.corners)):
        raise InputError.of("wall", "corners_m: every tile of the grid needs its display's corners "
                            f"({sum(c is not None for c in cfg.corners)} of {cfg.ranks} have them)")
    viewer = cfg.viewer
    if viewer is None:
        return
    if cfg.stereo != "mono":  # the narrowest screen the eyes look through
        wide = (min(float(np.linalg.norm(np.subtract(sc.corners[1], sc.corners[0]))) for sc in viewer.screens)
                if viewer.screens else cfg.screen_m[0])
        if cfg.eye_separation >= wide:
            raise InputError.of("eye_separation", f"{cfg.eye_separation:g} m is as wide as the wall or wider "
                                f"({wide:g} m: " + ("its corners_m)" if viewer.screens else "--screen-size)"))
    if cfg.head is not None:
        why = head_problem(Pose(cfg.head), viewer, cfg.ranks)
        if why:
            raise InputError.of("head", f"{','.join(f'{v:g}' for v in cfg.head)}: {why}")
    elif viewer.screens and not cfg.poses:  # the viewer stands at the room's origin (Viewer.home)
        why = head_problem(Pose((0.0, 0.0, 0.0)), viewer, cfg.ranks)
        if why:
            raise InputError.of("wall", f"corners_m: the viewer stands at the room's origin unless a head is given, "
                                f"and there {why.removeprefix('a viewer at (0, 0, 0) has ')} (give --head X,Y,Z "
                                "or the wall file's stereo.head_m)")
    for i, pose in enumerate(cfg.poses):  # the file's poses, once at the door
        why = head_problem(pose, viewer, cfg.ranks)
        if why:
            raise InputError(f"--head-poses {cfg.head_poses}: pose {i}: {why}")


def splits_by_eye(cfg) -> bool:
    """Whether a wall's ranks split by eye (``--eyes``: split, or auto where the wall can;
    ``core/stereo.splits``). Not with dark tiles (a restart without a PC that is gone): the live
    tiles need not halve, so every rank then draws both eyes of its region."""
    from multigpu.core.stereo import splits

    if cfg.eyes == "own":  # a rank for each eye of each tile (checked at the door)
        return True
    return (cfg.eyes != "joint" and not cfg.dark
            and splits(cfg.stereo, cfg.grid, cfg.decomposition, cfg.partition) is None)


def viewer_of(cfg):
    """Who looks at the wall (``core/eyes.Viewer``), where a run places one: stereo, a head or
    head poses; None: the camera's own frustum, as always."""
    if cfg.stereo == "mono" and cfg.head is None and not cfg.poses and cfg.head_tracker is None and not cfg.corners:
        return None
    from multigpu.core.eyes import Pose, Viewer

    screens = ()
    if cfg.corners:  # the wall file placed its displays in the room
        from multigpu.core.eyes import screens_of

        screens = screens_of(dict(enumerate(cfg.corners)), cfg.canvas.tiles())
    return Viewer(cfg.screen_m, cfg.eye_separation if cfg.stereo != "mono" else 0.0,
                  None if cfg.head is None else Pose(cfg.head), cfg.world_per_metre, cfg.swap_eyes, screens)
