"""Stereo walls and the viewer, in one process: where both eyes' parts go (``core/stereo.py``),
each eye's off-axis frustum against an independent generalized perspective projection
(``core/eyes.py``), bad input at the door, and the whole pipeline as threads (``threadcomm``):
each eye's mosaic is one rank's render of that eye bit for bit, and the packed mosaic is the
packing of those, for every decomposition, with bezels, frames in flight, render scale and
levels of detail."""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from mpirun import read_png
from threadcomm import run_ranks

from multigpu.config import WalkConfig
from multigpu.core.camera import Camera
from multigpu.core.canvas import Canvas
from multigpu.core.eyes import Pose, Viewer, eye_frames
from multigpu.core.stereo import Stereo
from multigpu.core.work import Work, pieces_tile_display, transfers
from multigpu.errors import InputError
from multigpu.rank import walkthrough
from multigpu.scene.models import SceneSpec

FRAMES = 3
SCREEN = (1.2, 0.96)  # metres: a centimetre a pixel of the 120x96 canvases here
MODES = ("side-by-side", "top-bottom", "anaglyph", "passive")


class _Job:
    signum = None
    in_frames = False
    thread_cpu = 0.0


# -- where the eyes' parts go


def _screen_work(canvas: Canvas) -> Work:
    """Two ranks' strips of the eye canvas: left and right halves."""
    W, H = canvas.size
    rects = (np.array([[0, 0, W // 2 + 3, H]]), np.array([[W // 2 + 3, 0, W, H]]))
    return Work(rects, (np.ones((1, 5), bool), np.ones((1, 5), bool)), np.array([5, 5]))


@pytest.mark.parametrize("mode", MODES)
def test_both_eyes_parts_tile_the_composed_wall_once(mode):
    st = Stereo(mode, Canvas((1, 2), (40, 30)))
    work = _screen_work(st.eye)
    composed, picks = st.compose(work)
    assert pieces_tile_display(composed, st.composed.size)
    for k in range(2):  # every part names its eye, its piece and where in that piece it starts
        for (eye, piece, x, y), (x0, y0, x1, y1) in zip(picks[k], composed.rects[k].tolist()):
            ex0, ey0 = work.rects[k][piece][:2] + np.array([x, y])
            tile = int(np.searchsorted(st.composed.tiles()[:, 2], x0, side="right"))
            cx0 = st.composed.tiles()[tile][0] + eye * st.eye_tile[0]
            assert x0 - cx0 == ex0 - st.eye.tiles()[tile][0] and y0 == ey0  # same place in the eye's tile
    plan = transfers(composed, st.composed.tiles())
    assert {p.receiver for p in plan} == {0, 1}


def test_a_hybrids_regions_stay_first_once_composed():
    st = Stereo("side-by-side", Canvas((1, 2), (40, 30)))
    W, H = st.eye.size
    work = Work((np.array([[0, 0, W // 2, H], [0, 0, W, H]]), np.array([[W // 2, 0, W, H], [0, 0, W, H]])),
                (np.ones((2, 3), bool),) * 2, np.array([1, 1]), True, None, (1, 1))
    composed, picks = st.compose(work)
    for k in range(2):
        front = composed.front[k]
        assert front == 2 and all(p[1] == 0 for p in picks[k][:front]) and all(p[1] == 1 for p in picks[k][front:])


def test_packing_each_mode():
    rng = np.random.default_rng(1)
    for mode in MODES:
        st = Stereo(mode, Canvas((1, 1), (8, 6)))
        ew, eh = st.eye_tile
        left, right = rng.integers(0, 255, (eh, ew, 3), np.uint8), rng.integers(0, 255, (eh, ew, 3), np.uint8)
        got = st.pack(np.concatenate([left, right], axis=1))
        assert got.shape == (6, 8 * st.outputs, 3)
        if mode == "passive":  # two outputs: the left eye's, then the right eye's, each the whole tile
            assert st.outputs == 2 and (got[:, :8] == left).all() and (got[:, 8:] == right).all()
        elif mode == "side-by-side":
            assert (got[:, :4] == left).all() and (got[:, 4:] == right).all()
        elif mode == "top-bottom":  # bottom row first: the left eye on top
            assert (got[3:] == left).all() and (got[:3] == right).all()
        else:
            assert (got[..., 0] == left[..., 0]).all() and (got[..., 1:] == right[..., 1:]).all()


# -- each eye's frustum


def _kooima(pa, pb, pc, pe, near, far):
    """Kooima's generalized perspective projection, written from the paper: screen corners
    lower-left ``pa``, lower-right ``pb``, upper-left ``pc``, eye ``pe`` (world); P @ M^T @ T."""
    vr = (pb - pa) / np.linalg.norm(pb - pa)
    vu = (pc - pa) / np.linalg.norm(pc - pa)
    vn = np.cross(vr, vu)
    vn /= np.linalg.norm(vn)
    va, vb, vc = pa - pe, pb - pe, pc - pe
    d = -va @ vn
    lo, r = (vr @ va) * near / d, (vr @ vb) * near / d
    b, t = (vu @ va) * near / d, (vu @ vc) * near / d
    P = np.array([[2 * near / (r - lo), 0, (r + lo) / (r - lo), 0], [0, 2 * near / (t - b), (t + b) / (t - b), 0],
                  [0, 0, -(far + near) / (far - near), -2 * far * near / (far - near)], [0, 0, -1, 0]])
    M = np.eye(4)
    M[:3, :3] = np.stack([vr, vu, vn])
    T = np.eye(4)
    T[:3, 3] = -pe
    return P @ M @ T


def _axes(camera: Camera):
    """The camera's position and its forward, right and up unit vectors (world)."""
    c = np.asarray(camera.position, float)
    f = np.asarray(camera.target, float) - c
    f /= np.linalg.norm(f)
    s = np.cross(f, camera.up)
    s /= np.linalg.norm(s)
    return c, f, s, np.cross(s, f)


def _world_wall(camera: Camera, viewer: Viewer):
    """The wall's corners in the world: in front of the camera, on its axes, at the distance
    where its height spans the camera's fov (scaled by world_per_metre)."""
    c, f, s, u = _axes(camera)
    W, H = viewer.screen
    k = viewer.world_per_metre
    d = H / 2 / math.tan(math.radians(camera.fov) / 2)
    centre = c + f * d * k
    room = lambda p: centre + k * (p[0] * s + p[1] * u + p[2] * -f)  # noqa: E731  room metres -> world
    return room, [room(np.array(p)) for p in ((-W / 2, -H / 2, 0), (W / 2, -H / 2, 0), (-W / 2, H / 2, 0))]


@pytest.mark.parametrize("pose", [Pose((0.3, -0.2, 1.5)), Pose((-0.5, 0.4, 0.7), yaw=20, pitch=-10, roll=15),
                                  Pose((0.0, 0.0, 3.0), roll=90)])
@pytest.mark.parametrize("scale", [1.0, 7.5])
def test_each_eye_sees_through_the_wall_as_the_generalized_projection_says(pose, scale):
    camera = Camera((3.0, -2.0, 1.5), (0.0, 1.0, 0.7), (0, 0, 1), 50.0, 0.05, 80.0)
    viewer = Viewer((2.0, 1.2), 0.07, None, scale)
    room, (pa, pb, pc) = _world_wall(camera, viewer)
    frames = [screens[0] for screens in eye_frames(camera, viewer, pose, 2)]
    eyes = viewer.eyes(camera, pose, 2)
    assert np.allclose(np.linalg.norm(eyes[1] - eyes[0]), 0.07)
    for (view, proj, _), eye in zip(frames, eyes):
        want = _kooima(pa, pb, pc, room(eye), camera.near, camera.far)
        got = proj @ view
        assert np.allclose(got, want, rtol=1e-9, atol=1e-9)
    # a point on the wall lands where it is on the wall for either eye: the wall is the window
    on_wall = room(np.array([0.25 * viewer.screen[0], -0.1 * viewer.screen[1], 0.0]))
    for view, proj, _ in frames:
        clip = proj @ view @ np.append(on_wall, 1.0)
        assert np.allclose(clip[:2] / clip[3], [0.5, -0.2])


def test_a_head_at_home_with_no_separation_sees_what_the_camera_sees():
    camera = Camera((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), fov=60.0)
    viewer = Viewer((1.6, 0.9), 0.0)
    from multigpu.core.camera import frame_matrices

    view, proj, light = frame_matrices(camera, (1600, 900))
    for (v, p, li), in eye_frames(camera, viewer, None, 2):
        assert np.allclose(v, view) and np.allclose(p, proj, rtol=1e-12, atol=1e-12) and np.allclose(li, light)


# -- bad input at the door


@pytest.mark.parametrize("fields,words", [
    ({"stereo": "quad"}, "--stereo quad: frame-sequential stereo needs a quad-buffered GL visual"),
    ({"stereo": "side-by-side", "tile": (61, 48)}, "--tile 61x48: side-by-side stereo needs an even tile width"),
    ({"stereo": "top-bottom", "tile": (60, 47)}, "--tile 60x47: top-bottom stereo needs an even tile height"),
    ({"stereo": "anaglyph", "eye_separation": -0.01}, "--eye-separation must be >= 0 metres"),
    ({"stereo": "anaglyph", "eye_separation": 2.0}, "--eye-separation 2 m is as wide as the wall or wider"),
    ({"stereo": "anaglyph", "head": (0.0, 0.0, 0.0)}, "--head 0,0,0: a viewer at z = 0 m has an eye behind"),
    ({"head": (0.1, 0.2, -1.0)}, "--head 0.1,0.2,-1: a viewer at z = -1 m"),
    ({"stereo": "fourway"}, "--stereo must be one of mono, side-by-side, top-bottom, anaglyph, passive, quad"),
    ({"eyes": "split"}, "--eyes split needs a stereo wall (--stereo), got --stereo mono"),
    ({"stereo": "anaglyph", "eyes": "split", "decomposition": "db"}, "--eyes split works with --decomposition screen"),
    ({"stereo": "anaglyph", "eyes": "split", "grid": (3, 3)}, "--eyes split needs an even number of columns"),
    ({"stereo": "anaglyph", "eyes": "split", "partition": "broadcast"}, "--eyes split plans every rank's partition"),
    ({"stereo": "anaglyph", "eyes": "both"}, "--eyes must be one of auto, joint, split, own"),
    ({"stereo": "anaglyph", "eyes": "own"}, "--eyes own (a rank for each eye of each tile) drives a passive wall's"),
    ({"stereo": "passive", "eyes": "own", "decomposition": "hybrid"}, "--eyes own works with --decomposition screen"),
    ({"stereo": "passive", "eyes": "own", "dark": (1,)}, "--eyes own: a wall without some of its PCs"),
])
def test_bad_stereo_input_is_one_line_naming_the_flag(fields, words):
    with pytest.raises(InputError) as got:
        WalkConfig(**{"grid": (2, 2), "tile": (60, 48), "screen_m": SCREEN, **fields})
    assert str(got.value).startswith(words) and "\n" not in str(got.value), str(got.value)


@pytest.mark.parametrize("fields,eyes", [({"stereo": "anaglyph"}, "split"),
                                         ({"stereo": "passive", "grid": (2, 1)}, "split"),
                                         ({"stereo": "anaglyph", "decomposition": "db"}, "joint"),
                                         ({"stereo": "side-by-side", "grid": (3, 3)}, "joint"),
                                         ({"stereo": "anaglyph", "partition": "broadcast"}, "joint"), ({}, "joint")])
def test_auto_splits_the_ranks_by_eye_where_the_wall_can(fields, eyes):
    cfg = WalkConfig(**{"grid": (2, 2), "tile": (60, 48), "screen_m": SCREEN, **fields})
    assert cfg.eyes == "auto" and cfg.eyes_split is (eyes == "split")
    assert not dataclasses.replace(cfg, eyes="joint").eyes_split
    assert not dataclasses.replace(cfg, eyes="split" if eyes == "split" else "auto", dark=(1,)).eyes_split  # a restart


@pytest.mark.parametrize("text,words", [
    ("not json", "not JSON"), ("[]", "must be a non-empty list of poses"),
    ("[[0, 0, 1" + "0" * 400 + "]]", "an integer of 401 digits"),  # once OverflowError at the start
    ("[[0, 0, 1, 0, 0, 1e999]]", "out of range"), ("[[0, 0, NaN]]", "NaN is not a number"),
    ("[" * 5000 + "]" * 5000, "nested deeper"), ("[[0, 0, 1e300]]", "pose 0 must be"),
    ("[[0, 0, 1], [0, 1]]", "pose 1 must be [x, y, z] or [x, y, z, yaw, pitch, roll]"),
    ('{"poses": [[0, 0, 1, 0, 0, "x"]]}', "pose 0 must be"),
    ("[[0, 0, 1], [0, 0, -0.5]]", "pose 1: a viewer at z = -0.5 m has an eye behind the screen"),
])
def test_a_bad_head_pose_file_names_the_file_and_the_pose(tmp_path, text, words):
    path = tmp_path / "head.json"
    path.write_text(text)
    with pytest.raises(InputError) as got:
        WalkConfig(tile=(60, 48), screen_m=SCREEN, head_poses=str(path))
    assert str(got.value).startswith(f"--head-poses {path}: ") and words in str(got.value), str(got.value)


def test_a_wall_files_stereo_and_size_reach_the_run(tmp_path):
    from multigpu.cli import build_parser, walk_config

    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": "64x48", "screen_m": [2.4, 0.9],
                                "stereo": {"mode": "anaglyph", "eye_separation_m": 0.05, "head_m": [0.1, 0.0, 2.0],
                                           "swap_eyes": True}}))
    p = build_parser()
    cfg = walk_config(p.parse_args(["walkthrough", "--wall", str(wall)]))
    assert (cfg.stereo, cfg.eye_separation, cfg.head, cfg.swap_eyes, cfg.screen_m) == (
        "anaglyph", 0.05, (0.1, 0.0, 2.0), True, (2.4, 0.9))
    cfg = walk_config(p.parse_args(["walkthrough", "--wall", str(wall), "--stereo", "top-bottom",
                                    "--eye-separation", "0.06"]))
    assert (cfg.stereo, cfg.eye_separation) == ("top-bottom", 0.06)  # the flags win


# -- the pipeline as threads


def _walk(out, grid, tile, mullion=(0, 0), frames=FRAMES, **fields) -> list:
    """Each frame's (display, left, right) mosaics."""
    cfg = WalkConfig(scene=SceneSpec(triangles=20_000), frames=frames, grid=grid, tile=tile, mullion=mullion,
                     mosaic_every=1, overlay=False, progress=False, exchange=fields.pop("exchange", "messages"),
                     out=str(out), timeout=60.0, screen_m=SCREEN, **fields)
    run_ranks(cfg.processes, lambda comm: walkthrough.run(cfg, comm, _Job()))
    eyes = ("left/", "right/") if cfg.stereo != "mono" else ()
    return [[read_png(out / "mosaic" / f"{d}frame_{f:05d}.png") for d in ("", *eyes)] for f in range(frames)]


def _one_rank(base, mode, canvas: Canvas, **fields) -> list:
    """One rank's eyes of ``canvas``'s eye canvas: a 1x1 wall whose one tile packs the whole eye canvas."""
    E = Stereo(mode, canvas).eye
    tile = (E.size[0] * (2 if mode == "side-by-side" else 1), E.size[1] * (2 if mode == "top-bottom" else 1))
    return _walk(base, (1, 1), tile, stereo=mode, **fields)


def _packed(left, right, canvas: Canvas, mode):
    """What the wall's displays show, packed here tile by tile from the eyes' mosaics (top row first);
    passive: the left eyes' outputs beside the right eyes'."""
    if mode == "passive":
        return np.concatenate([left, right], axis=1)
    st = Stereo(mode, canvas)
    R, C = canvas.grid
    out = np.zeros((*canvas.size[::-1], 3), np.uint8)
    ex, ey = st.eye.tiles(), canvas.tiles()
    for k in range(R * C):  # tiles
        (a0, b0, a1, b1), (x0, y0, x1, y1) = ex[k], ey[k]
        EH, H = st.eye.size[1], canvas.size[1]
        L, Rt = left[EH - b1:EH - b0, a0:a1], right[EH - b1:EH - b0, a0:a1]
        tile = (np.concatenate([L, Rt], 1) if mode == "side-by-side" else np.concatenate([L, Rt], 0)
                if mode == "top-bottom" else np.concatenate([Rt[..., :1] * 0 + L[..., :1], Rt[..., 1:]], 2))
        out[H - y1:H - y0, x0:x1] = tile
    return out


@pytest.fixture(scope="module")
def references(tmp_path_factory):
    base = tmp_path_factory.mktemp("one")
    return {mode: _one_rank(base / mode, mode, Canvas((2, 2), (60, 48))) for mode in MODES}


CASES = {
    "side-by-side screen": ("side-by-side", {"balance": "strips", "eyes": "joint"}),
    "side-by-side cross": ("side-by-side", {"balance": "cross"}),
    "side-by-side db": ("side-by-side", {"decomposition": "db"}),
    "side-by-side hybrid latency 3": ("side-by-side", {"decomposition": "hybrid", "latency": 3}),
    "anaglyph screen latency 0": ("anaglyph", {"latency": 0, "eyes": "joint"}),
    "anaglyph db latency 2": ("anaglyph", {"decomposition": "db", "latency": 2}),
    "passive screen latency 1": ("passive", {"latency": 1}),
    "passive hybrid": ("passive", {"decomposition": "hybrid"}),
    "top-bottom bins": ("top-bottom", {"decomposition": "bins", "bin_size": 16}),
    "anaglyph split by eye latency 2": ("anaglyph", {"eyes": "split", "latency": 2}),
    "side-by-side split by eye cross": ("side-by-side", {"eyes": "split", "balance": "cross", "latency": 3}),
    "passive a rank an eye": ("passive", {"eyes": "own"}),
    "passive a rank an eye cross latency 3": ("passive", {"eyes": "own", "balance": "cross", "latency": 3}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_each_eye_composes_one_ranks_render_and_the_wall_shows_their_packing(tmp_path, references, case):
    mode, fields = CASES[case]
    canvas = Canvas((2, 2), (60, 48))
    got = _walk(tmp_path / "w", canvas.grid, canvas.tile, stereo=mode, **fields)
    for f, ((shown, left, right), (_, want_l, want_r)) in enumerate(zip(got, references[mode])):
        for name, a, b in (("left", left, want_l), ("right", right, want_r)):
            assert a.shape == b.shape and (a == b).all(), f"frame {f} {name}: {(a != b).any(axis=2).sum()} px"
        want = _packed(want_l, want_r, canvas, mode)
        assert (shown == want).all(), f"frame {f}: {(shown != want).any(axis=2).sum()} packed px differ"
    s = json.loads((tmp_path / "w" / "summary.json").read_text())
    assert s["config"]["stereo"] == mode and s["config"]["viewer"]["eye_separation_m"] == 0.064
    assert s["config"]["eyes"] == fields.get("eyes", "split" if fields.get("decomposition", "screen") == "screen"
                                             else "joint")


@pytest.mark.parametrize("mode,fields,mullion", [("top-bottom", {"balance": "strips"}, (6, 4)),
                                                 ("side-by-side", {"decomposition": "hybrid", "render_scale": 0.5},
                                                  (6, 4)),
                                                 ("anaglyph", {"lod_error": 2.0, "balance": "cross"}, (6, 4)),
                                                 ("top-bottom", {"eyes": "split", "render_scale": 0.5,
                                                                 "lod_error": 2.0}, (6, 4))])
def test_bezels_render_scale_and_levels_of_detail_in_stereo(tmp_path, mode, fields, mullion):
    canvas = Canvas((2, 2), (60, 48), mullion)
    quality = {k: v for k, v in fields.items() if k in ("render_scale", "lod_error")}
    want = _one_rank(tmp_path / "one", mode, canvas, **quality)
    got = _walk(tmp_path / "w", canvas.grid, canvas.tile, canvas.mullion, stereo=mode, **fields)
    hidden = Stereo(mode, canvas).eye.hidden()
    for f, (g, w) in enumerate(zip(got, want)):
        for e in (1, 2):  # the eyes: the mullions' pixels black, the rest one rank's
            ref = w[e].copy()
            ref[hidden] = 0
            assert (g[e] == ref).all(), f"frame {f} eye {e}: {(g[e] != ref).any(axis=2).sum()} px differ"


def test_no_eye_separation_shows_one_picture_twice_and_the_default_two(tmp_path):
    canvas = Canvas((2, 2), (60, 48))
    same = _walk(tmp_path / "zero", canvas.grid, canvas.tile, stereo="side-by-side", eye_separation=0.0)
    apart = _walk(tmp_path / "apart", canvas.grid, canvas.tile, stereo="side-by-side")
    for f in range(FRAMES):
        for shown, differ in ((same[f][0], False), (apart[f][0], True)):
            halves = [(shown[y:y + 48, x:x + 30], shown[y:y + 48, x + 30:x + 60]) for y in (0, 48) for x in (0, 60)]
            if differ:
                assert sum(int((a != b).any(axis=2).sum()) for a, b in halves) > 100
            else:
                assert all((a == b).all() for a, b in halves), f"frame {f}: the halves of a tile differ"


def test_swapped_eyes_trade_places(tmp_path, references):
    got = _walk(tmp_path / "w", (2, 2), (60, 48), stereo="anaglyph", swap_eyes=True)
    for f, (g, w) in enumerate(zip(got, references["anaglyph"])):
        assert (g[1] == w[2]).all() and (g[2] == w[1]).all()


def test_a_moving_head_changes_the_picture_as_its_frustum_says(tmp_path):
    """Mono, a head pose per frame: each frame's mosaic is a one-rank render through that pose's
    frustum, formed here by the generalized projection (within a few edge pixels: the matrices
    agree to rounding), and frames whose poses differ differ."""
    from multigpu.gpu.render import RegionRenderer, create_context
    from multigpu.rank.walkthrough import load_world

    poses = [[0.0, 0.0, 1.0], [0.4, 0.1, 1.0], [-0.3, -0.2, 0.6, 25.0, 0.0, 0.0]]
    (tmp_path / "head.json").write_text(json.dumps({"poses": poses}))
    got = _walk(tmp_path / "w", (1, 2), (60, 96), head_poses=str(tmp_path / "head.json"))
    cfg = WalkConfig(scene=SceneSpec(triangles=20_000), frames=FRAMES, grid=(1, 2), tile=(60, 96), screen_m=SCREEN,
                     head_poses=str(tmp_path / "head.json"))
    scene, path, _ = load_world(cfg)
    ctx, _ = create_context()
    renderer = RegionRenderer(ctx, scene, cfg.canvas.size, colors=cfg.colors)
    viewer = cfg.viewer
    for f, pose in enumerate(poses):
        camera = path.camera(f)
        room, (pa, pb, pc) = _world_wall(camera, viewer)
        mvp = _kooima(pa, pb, pc, room(np.array(pose[:3])), camera.near, camera.far)
        view, _, light = eye_frames(camera, viewer, None, 1)[0][0]
        rgb = renderer.render(view, mvp @ np.linalg.inv(view), light, (0, 0, 120, 96), None)
        want = rgb[::-1]
        differ = int((got[f][0] != want).any(axis=2).sum())
        assert differ <= 20, f"frame {f}: {differ} pixels differ from the generalized projection's render"
    moved = int((got[1][0] != got[0][0]).any(axis=2).sum())
    assert moved > 500, moved
    renderer.release()
    ctx.release()


def test_a_scaled_pixel_at_a_bezel_shows_what_is_behind_it(tmp_path):
    """A tracked mono wall with bezels at render scale 0.5: a scaled pixel that straddles a tile's
    edge shows an object wholly behind the bezel beside it, as one rank's render does (the
    widening once missed such objects, which have no visible rect: 2 pixels differed)."""
    canvas = Canvas((2, 2), (30, 48), (3, 4))
    want = _walk(tmp_path / "one", (1, 1), canvas.size, render_scale=0.5, head=(0.05, 0.0, 0.9))
    got = _walk(tmp_path / "w", canvas.grid, canvas.tile, canvas.mullion, render_scale=0.5, head=(0.05, 0.0, 0.9))
    for f, (g, w) in enumerate(zip(got, want)):
        ref = w[0].copy()
        ref[canvas.hidden()] = 0
        assert (g[0] == ref).all(), f"frame {f}: {(g[0] != ref).any(axis=2).sum()} px differ"


def test_a_tracked_head_over_udp_moves_every_rank_and_garbage_is_refused_once(tmp_path, capsys):
    """``--head-tracker``: a tracker sends a pose over and over after a datagram of garbage and one
    with an eye behind the wall; the wall goes on, says so once, and its last frame is the one a
    run with that head renders; the summary counts the poses and their motion to photon."""
    import socket
    import threading

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    stop = threading.Event()

    def send():
        out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        out.sendto(b"\xff not a pose", ("127.0.0.1", port))
        out.sendto(b'{"position": [0, 0, -1]}', ("127.0.0.1", port))
        while not stop.is_set():
            out.sendto(b'{"position": [0.2, -0.1, 0.7], "roll": 0}', ("127.0.0.1", port))
            stop.wait(0.002)
        out.close()

    frames = 12
    want = _walk(tmp_path / "fixed", (1, 2), (60, 96), frames=frames, stereo="anaglyph",
                 head=(0.2, -0.1, 0.7))
    sender = None

    import multigpu.rank.head_link as head_link

    listen = head_link.HeadLink.listen

    def listen_then_send(address, p):  # the tracker starts once rank 0 listens
        nonlocal sender
        sock = listen(address, p)
        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        return sock

    head_link.HeadLink.listen = staticmethod(listen_then_send)
    try:
        got = _walk(tmp_path / "tracked", (1, 2), (60, 96), frames=frames, stereo="anaglyph",
                    head_tracker=("127.0.0.1", port))
    finally:
        head_link.HeadLink.listen = staticmethod(listen)
        stop.set()
        if sender is not None:
            sender.join(5)
    err = capsys.readouterr().err
    assert err.count("head tracker: refused a pose") == 1, err
    last = frames - 1
    assert all((g == w).all() for g, w in zip(got[last], want[last])), "the last frame is not the tracked head's"
    s = json.loads((tmp_path / "tracked" / "summary.json").read_text())
    assert s["head_poses_received"] > 0 and s["head_poses_refused"] == 2
    assert s["head_to_photon_ms_median"] > 0


# -- a CAVE: displays placed in the room by their corners

CORNER = (((-1, -1, 1), (-1, -1, -1), (-1, 1, 1)), ((-1, -1, -1), (1, -1, -1), (-1, 1, -1)))  # left, front


def test_tiles_in_one_plane_share_a_screen_and_a_corner_makes_two():
    from multigpu.core.eyes import screens_of

    flat = Canvas((2, 2), (100, 50), (10, 10))  # 1 cm a pixel, bezels included
    at = lambda x, y: (x / 100 - 1.05, y / 100 - 0.55, 0.0)  # noqa: E731
    tiles = flat.tiles()
    corners = {k: (at(x0, y0), at(x1, y0), at(x0, y1)) for k, (x0, y0, x1, y1) in enumerate(tiles)}
    (one,) = screens_of(corners, tiles)
    assert sorted(one.tiles) == [0, 1, 2, 3] and np.allclose(one.corners, [at(0, 0), at(210, 0), at(0, 110)])
    corners[3] = tuple((x, y, z + 0.01) for x, y, z in corners[3])  # a display 1 cm out of the plane
    assert sorted(len(s.tiles) for s in screens_of(corners, tiles)) == [1, 3]
    two = screens_of(dict(enumerate(CORNER)), Canvas((1, 2), (60, 60)).tiles())
    assert [s.tiles for s in two] == [(0,), (1,)]


def test_each_screen_of_a_corner_is_the_generalized_projection():
    camera = Camera((0.0, -4.0, 1.0), (0.0, 0.0, 1.0), (0, 0, 1), 60.0, 0.05, 80.0)
    from multigpu.core.eyes import screens_of

    screens = screens_of(dict(enumerate(CORNER)), Canvas((1, 2), (60, 60)).tiles())
    viewer = Viewer((1.2, 0.6), 0.06, None, 2.0, False, screens)
    pose = Pose((0.2, 0.1, 0.3), yaw=-30)
    frames = eye_frames(camera, viewer, pose, 2, 2)
    c, f, s, u = _axes(camera)
    room = lambda p: c + 2.0 * (p[0] * s + p[1] * u - p[2] * f)  # noqa: E731  the camera stands at the origin
    for eye, per_screen in zip(viewer.eyes(camera, pose, 2), frames):
        for sc, (view, proj, _) in zip(screens, per_screen):
            pa, pb, pc = (room(np.asarray(p, float)) for p in sc.corners)
            assert np.allclose(proj @ view, _kooima(pa, pb, pc, room(eye), camera.near, camera.far), atol=1e-9)


@pytest.mark.parametrize("mode", ["mono", "anaglyph"])
def test_a_cave_corner_draws_each_wall_through_its_own_frustum(tmp_path, mode):
    """Two walls at 90 degrees, a rank each: every eye's mosaic is, screen by screen, a one-rank
    render of the canvas through that screen's frustum."""
    from multigpu.core.eyes import eye_frames as frames_of
    from multigpu.gpu.render import RegionRenderer, create_context
    from multigpu.planner import on_canvas, screen_rects
    from multigpu.rank.walkthrough import load_world

    got = _walk(tmp_path / "w", (1, 2), (60, 60), corners=CORNER, stereo=mode)
    cfg = WalkConfig(scene=SceneSpec(triangles=20_000), frames=FRAMES, grid=(1, 2), tile=(60, 60), screen_m=SCREEN,
                     corners=CORNER, stereo=mode)
    scene, path, _ = load_world(cfg)
    ctx, _ = create_context()
    renderer = RegionRenderer(ctx, scene, cfg.canvas.size, colors=cfg.colors)
    viewer, rects = cfg.viewer, screen_rects(cfg.viewer.planes(2), cfg.canvas)
    try:
        for f in range(FRAMES):
            eyes = frames_of(path.camera(f), viewer, None, 1 if mode == "mono" else 2, 2)
            for e, per_screen in enumerate(eyes):
                want = np.zeros((60, 120, 3), np.uint8)
                for (view, proj, light), rect in zip(per_screen, rects):
                    x0, y0, x1, y1 = rect
                    want[y0:y1, x0:x1] = renderer.render(view, on_canvas(rect, cfg.canvas.size) @ proj, light,
                                                         tuple(rect), None)
                mosaic = got[f][0 if mode == "mono" else 1 + e]
                assert (mosaic == want[::-1]).all(), f"frame {f} eye {e}: {(mosaic != want[::-1]).any(axis=2).sum()}"
    finally:
        renderer.release()
        ctx.release()


@pytest.mark.parametrize("change,words", [
    (lambda d: d["displays"][0].update(corners_m=[[0, 0, 0], [1, 0, 0], [0.5, 1, 0]]),
     "displays[0]: corners_m: its edges are not at right angles: the corners do not make a rectangle"),
    (lambda d: d["displays"][1].pop("corners_m"), "corners_m: give every display's corners or none"),
    (lambda d: d["displays"][0].update(corners_m=[[0, 0, 0], [0, 0, 0], [0, 1, 0]]), "two corners coincide"),
])
def test_a_wall_files_corners_are_checked(tmp_path, change, words):
    from multigpu.wall import load_wall

    doc = {"grid": "1x2", "tile": "60x60", "displays": [{"rank": k, "corners_m": [list(p) for p in CORNER[k]]}
                                                        for k in range(2)]}
    change(doc)
    path = tmp_path / "wall.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as got:
        load_wall(str(path))
    assert words in str(got.value) and str(got.value).startswith(f"--wall {path}: "), str(got.value)


def test_a_head_behind_a_wall_of_the_corner_is_refused():
    with pytest.raises(InputError, match=r"--head -1.2,0,0: a viewer at \(-1.2, 0, 0\) has an eye behind the screen "
                                         r"or inside its plane \(the screen of tiles 0\)"):
        WalkConfig(grid=(1, 2), tile=(60, 60), corners=CORNER, head=(-1.2, 0.0, 0.0))


# -- the head from the keyboard


class _Glfw:
    """What ``display.controls`` asks of glfw: key codes and flags."""

    PRESS, RELEASE, MOD_SHIFT = 1, 0, 1

    def __getattr__(self, name):
        if name.startswith("KEY_"):
            return hash(name) % 100_000
        raise AttributeError(name)


class _Comm:
    def Get_rank(self):
        return 0

    def Get_size(self):
        return 1


def test_head_keys_move_the_viewers_head_and_k_brings_it_home():
    from multigpu.display.controls import Controls
    from multigpu.planner import Planner
    from multigpu.rank.steer import Steering

    g = _Glfw()
    controls = Controls(g)
    steering = Steering(_Comm(), 1.0, ["auto"], 0, controls=controls)
    for key, mods in ((g.KEY_L, 0), (g.KEY_L, 0), (g.KEY_U, g.MOD_SHIFT), (g.KEY_Y, 0)):
        controls.on_key(None, key, 0, g.PRESS, mods)
    assert np.allclose(steering.next().head, (0.1, 0.25, -0.05))
    assert np.allclose(steering.next().head, (0.1, 0.25, -0.05))  # it stays where the keys put it
    cfg = WalkConfig(grid=(1, 2), tile=(60, 96), screen_m=SCREEN, stereo="anaglyph")
    from multigpu.scene.models import load_scene

    planner = Planner(cfg, load_scene(SceneSpec(triangles=2_000))[0], 0)
    camera = Camera((0.0, -5.0, 1.0), (0.0, 0.0, 1.0), fov=50.0)
    planner.head_offset = steering.next().head
    planner.frame(camera)
    home = cfg.viewer.home(camera)
    want = eye_frames(camera, cfg.viewer, Pose(tuple(home + (0.1, 0.25, -0.05))), 2)
    assert all(np.allclose(a[0][1], b[0][1]) for a, b in zip(planner.views, want))
    controls.on_key(None, g.KEY_K, 0, g.PRESS, 0)
    assert steering.next().head == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("mode", MODES)
def test_the_wall_tests_stereo_pattern_marks_each_eye_and_shows_depth(mode):
    from multigpu.display.pattern import DEPTH_COLOURS, stereo_tile_pattern

    st = Stereo(mode, Canvas((2, 2), (240, 160), (8, 8)))
    tile = stereo_tile_pattern(st, 3, 5, ["rank 3"])  # what this mode's display shows, bottom row first
    assert tile.shape == (160, 240 * st.outputs, 3)
    w, h = tile.shape[1], tile.shape[0]
    if mode == "anaglyph":  # red from the left eye's picture, green and blue from the right's (full-size eyes)
        full = stereo_tile_pattern(Stereo("passive", st.canvas), 3, 5, ["rank 3"])
        eye_l, eye_r = full[:, :240], full[:, 240:]
        assert (tile[..., 0] == eye_l[..., 0]).all() and (tile[..., 1:] == eye_r[..., 1:]).all()
        assert not (eye_l == eye_r).all()  # the eyes differ: the channels say which is which
        left, right = eye_l, eye_r
    elif mode == "top-bottom":  # the left eye above: its rows last, bottom row first
        left, right = tile[h // 2:], tile[:h // 2]
    else:  # side by side in one output, or two outputs (passive)
        left, right = tile[:, :w // 2], tile[:, w // 2:]
    assert (left == (0, 255, 0)).all(axis=2).sum() > 50 and not (right == (0, 255, 0)).all(axis=2).any()
    assert (right == (255, 0, 255)).all(axis=2).sum() > 50 and not (left == (255, 0, 255)).all(axis=2).any()
    near, middle = DEPTH_COLOURS[-1], DEPTH_COLOURS[2]
    band = [half[:half.shape[0] // 3] for half in (left, right)]  # the depth marks' rows (bottom row first)
    xs = [np.flatnonzero((half == near).all(axis=2).any(axis=0)) for half in band]
    assert xs[0].min() > xs[1].min()  # the near mark: crossed disparity, the left eye's further right
    mid = [np.flatnonzero((half == middle).all(axis=2).any(axis=0)) for half in band]
    assert mid[0].min() == mid[1].min()  # on the wall's plane: no disparity


def test_the_head_tracker_listens_on_127_0_0_1_unless_told():
    from multigpu.viewing import read_tracker

    assert read_tracker("7700") == ("127.0.0.1", 7700)
    assert read_tracker("0.0.0.0:7700") == ("0.0.0.0", 7700)
    with pytest.raises(InputError, match="a port 1..65535"):
        read_tracker("0")


def test_a_passive_tiles_windows_keep_fullscreen_and_swap_in_one_refresh(monkeypatch):
    """Defect 20: passive stereo dropped the wall file's fullscreen and swapped both eyes' windows
    with vsync one after the other (two refreshes a frame)."""
    import multigpu.display.window as window_module
    from multigpu.display import make_presenter

    calls, made = [], []

    class _Window:
        def __init__(self, rank, size, position, display, where, title=None, vsync=True, fullscreen=False,
                     origin=(0, 0)):
            self.name = "left" if "left" in title else "right"
            self.context, self.display = None, display
            made.append((self.name, vsync, fullscreen, origin))

        def current(self):
            calls.append(("current", self.name))

        def swap(self):
            calls.append(("swap", self.name))
            return 1.0

        def close(self):
            pass

    monkeypatch.setattr(window_module, "Window", _Window)
    p = make_presenter("window", 0, (64, 48), (0, 0), ":0", "test", fullscreen=True, right=(1920, 0))
    assert made == [("left", True, True, (0, 0)), ("right", False, True, (1920, 0))]
    calls.clear()
    p.swap()
    swaps = [c for c in calls if c[0] == "swap"]
    assert swaps == [("swap", "left"), ("swap", "right")] and calls[-1] == ("current", "left")


def _parallax(cfg, spec, frames: int = 40) -> float:
    """The largest parallax of the default walk, as a share of the wall's width: every vertex both
    eyes see, projected through each eye's off-axis frustum, every few frames of the walk."""
    from multigpu.planner import Planner
    from multigpu.scene.models import load_scene
    from multigpu.scene.paths import generate

    scene = load_scene(spec)[0]
    path = generate(cfg.path_kind, scene)
    planner = Planner(cfg, scene, rank=0)
    pts = np.c_[scene.vertices[::7, :3].astype(np.float64) + scene.origin, np.ones(len(scene.vertices[::7]))]
    most = 0.0
    for f in np.linspace(0, len(path) - 1, frames).astype(int):
        planner.frame(path.camera(int(f)), int(f))
        (left,), (right,) = planner.views  # one screen
        ndc = []
        for view, proj, _ in (left, right):
            clip = pts @ (proj @ view).T
            ndc.append((clip[:, :3] / clip[:, 3:], clip[:, 3] > 0))
        (a, in_a), (b, in_b) = ndc
        seen = in_a & in_b & (np.abs(a[:, :3]) <= 1).all(axis=1) & (np.abs(b[:, :3]) <= 1).all(axis=1)
        if seen.any():
            most = max(most, float(np.abs(a[seen, 0] - b[seen, 0]).max()) / 2)  # NDC spans 2 a wall's width
    return most


def test_the_default_anaglyph_can_be_fused_and_a_physical_wall_keeps_its_scale():
    """The default anaglyph of the pump on a 2x2 wall of 320x240 tiles once showed the eyes ~110 px
    apart on a 640 px wall (17 %): with no size, head or scale given, the zero-parallax plane is at
    the scene and the largest parallax of the default walk at most 3 % of the wall's width."""
    from multigpu.scene.models import SceneSpec

    spec = SceneSpec(model=str(Path(__file__).parent.parent / "models" / "pump.glb"))
    cfg = WalkConfig(scene=spec, grid=(2, 2), tile=(320, 240), stereo="anaglyph")
    assert cfg.focus
    got = _parallax(cfg, spec)
    assert 0.005 < got <= 0.03, got  # fusable, and still stereo
    physical = WalkConfig(scene=spec, grid=(2, 2), tile=(320, 240), stereo="anaglyph", screen_m=(0.32, 0.24))
    assert not physical.focus and _parallax(physical, spec) > 0.1  # the room's scale, as given
