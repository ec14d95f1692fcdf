"""Scenes that move, in one process: the maps, the posed bounds (against the moved vertices), the
compiled kernel against its numpy reference, the swarm's flight and the machinery."""

import dataclasses

import numpy as np
import pytest

from multigpu.core import jit
from multigpu.core.bounds import BoxProjector
from multigpu.core.camera import look_at, perspective
from multigpu.core.motion import FRAME_SECONDS, Posed, moved_boxes, rotations, scene_time, shader_rows, stretch
from multigpu.core.triangles import triangle_objects
from multigpu.errors import InputError
from multigpu.scene.models import SceneSpec
from multigpu.scene.moves import Machinery, motion_of, moves
from multigpu.scene.parts import with_parts
from multigpu.scene.plant import generate_plant
from multigpu.scene.swarm import CYCLE_S, GATHER_S, LEG_S, SIDE, Swarm, generate_swarm

needs_numba = pytest.mark.skipif(not jit.available(), reason="numba is not installed")


@pytest.fixture(scope="module")
def swarm():
    return generate_swarm(20_000, seed=3)


@pytest.fixture(scope="module")
def plant():
    return with_parts(generate_plant(20_000, seed=1), 32)  # big objects cut into parts


def moved_vertices(scene, A, b, body):
    """(T, 3, 3) every triangle's corners moved by its object's body's map (float64, world), and
    (T,) each triangle's object."""
    tri, obj = triangle_objects(scene)
    local = scene.vertices[:, :3].astype(np.float64)[tri]  # (T, 3, 3)
    Ao, bo = A[body[obj]], b[body[obj]]
    return np.einsum("tij,tvj->tvi", Ao, local) + bo[:, None, :] + scene.origin, obj


def test_rotations_are_rotations_and_the_kernel_makes_the_same_numbers():
    rng = np.random.default_rng(0)
    axis = rng.normal(size=(500, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(-50, 50, 500)
    R = rotations(axis, angle, compiled=False)
    assert np.allclose(np.einsum("nki,nkj->nij", R, R), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(np.einsum("nij,nj->ni", R, axis), axis)  # the axis stays
    if jit.available():
        assert np.array_equal(rotations(axis, angle, compiled=True), R)


def test_stretch_bounds_the_largest_singular_value():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(300, 3, 3))
    R = rotations(np.tile([0.0, 0.0, 1.0], (300, 1)), rng.uniform(0, 6, 300))
    scaled = R * rng.uniform(0.1, 5, (300, 1, 3))  # a rotation times a scale: columns orthogonal
    for M in (A, scaled):
        top = np.linalg.svd(M, compute_uv=False)[:, 0]
        assert (stretch(M) >= top * (1 - 1e-12)).all()
    assert np.allclose(stretch(scaled), np.linalg.svd(scaled, compute_uv=False)[:, 0])  # exact there


def test_moved_boxes_hold_their_moved_corners():
    rng = np.random.default_rng(2)
    c, h = rng.normal(size=(200, 3)), rng.uniform(0, 2, (200, 3))
    A, b = rng.normal(size=(200, 3, 3)), rng.normal(size=(200, 3))
    mc, mh = moved_boxes(c, h, A, b)
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, 8).T
    corners = c[:, None, :] + signs[None] * h[:, None, :]
    moved = np.einsum("nij,nvj->nvi", A, corners) + b[:, None, :]
    assert (np.abs(moved - mc[:, None, :]) <= mh[:, None, :] * (1 + 1e-12) + 1e-12).all()
    # the box is the tightest: each face is reached by a corner
    assert np.allclose(np.abs(moved - mc[:, None, :]).max(axis=1), mh)


def test_shader_rows_are_the_maps():
    A, b = np.arange(18.0).reshape(2, 3, 3), np.array([[10.0, 11, 12], [13, 14, 15]])
    rows = shader_rows(A, b).reshape(2, 3, 4)
    assert rows.dtype == np.float32 and np.array_equal(rows[:, :, :3], A) and np.array_equal(rows[:, :, 3], b)


@pytest.mark.parametrize("which", ["swarm", "plant"])
@pytest.mark.parametrize("t", [0.0, 1.3, 4.0, 9.7])
def test_posed_bounds_hold_every_moved_vertex(swarm, plant, which, t):
    """The boxes, spheres and parts the balancer, the levels and the culler read contain every
    vertex where the GPU puts it."""
    scene = swarm if which == "swarm" else plant
    motion = Swarm(scene) if which == "swarm" else Machinery(scene, 0.5, seed=4)
    posed = Posed(scene, motion, compiled=False).at(t)
    A, b = motion.at(t)
    world, obj = moved_vertices(scene, A, b, motion.bodies)
    lo, hi = posed.bmin_bmax()
    tol = 8 * np.finfo(np.float32).eps * np.abs(scene.vertices[:, :3]).max()  # float32 vertices, float64 bounds
    assert (world >= lo[obj][:, None, :] - tol).all() and (world <= hi[obj][:, None, :] + tol).all()
    d = np.linalg.norm(world - posed.centers[obj][:, None, :], axis=2)
    assert (d <= posed.radii[obj][:, None] * (1 + 1e-9) + tol).all()
    if which == "plant":  # every part's box holds its triangles
        start = scene.part_start
        assert posed.parts is not None and int(start[-1]) > scene.n_objects
        part_of = np.empty(len(obj), dtype=np.int64)  # triangles follow their object's parts in index order
        order = np.argsort(scene.first_index, kind="stable")
        at = 0
        for o in order:  # objects (a test)
            for p in range(start[o], start[o + 1]):
                n = int(scene.part_count[p]) // 3
                part_of[at:at + n] = p
                at += n
        pc, ph = posed.part_center.T, posed.part_half.T
        assert (world >= (pc - ph)[part_of][:, None, :] - tol).all()
        assert (world <= (pc + ph)[part_of][:, None, :] + tol).all()


@needs_numba
@pytest.mark.parametrize("which", ["swarm", "plant"])
def test_the_compiled_pose_makes_the_references_numbers(swarm, plant, which):
    scene = swarm if which == "swarm" else plant
    motion = Swarm(scene) if which == "swarm" else Machinery(scene, 0.3, seed=2)
    a, b = Posed(scene, motion, compiled=True), Posed(scene, motion, compiled=False)
    for t in (0.0, 0.7, 5.5, -2.0):
        a.at(t), b.at(t)
        for name in ("center", "half", "centers", "radii", "rows", *(("part_center", "part_half") if b.parts else ())):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name


@pytest.mark.parametrize("compiled", [False, True] if jit.available() else [False])
def test_a_swarm_posed_a_span_at_a_time_is_posed_whole(swarm, monkeypatch, compiled):
    """Posing the swarm's bodies a span at a time (no rank holds every map) gives the numbers of
    posing them all at once."""
    import multigpu.core.motion as motion_module

    monkeypatch.setattr(motion_module, "SPAN", 300)
    flight = Swarm(swarm)

    class Whole:  # the same flight, offered whole only
        bodies, moving, at = flight.bodies, None, flight.at

    spanned, whole = Posed(swarm, flight, compiled=compiled), Posed(swarm, Whole(), compiled=compiled)
    assert spanned.spanned and not whole.spanned and spanned.spans() == [(0, 300), (300, 600), (600, 900),
                                                                         (900, 1000)]
    assert spanned.c0 is None and len(spanned.rows) == 300  # rest bounds from the scene's arrays, rows a span's
    rows = np.zeros_like(whole.rows)

    def sink(got, lo):
        rows[lo:lo + len(got)] = got

    for t in (0.0, 2.5, 7.1):
        spanned.at(t, sink), whole.at(t)
        for name in ("center", "half", "centers", "radii"):
            assert np.array_equal(getattr(spanned, name), getattr(whole, name)), name
        assert np.array_equal(rows, whole.rows)


def test_a_projector_of_moved_boxes_gives_the_rects_of_the_moved_boxes(swarm):
    posed = Posed(swarm, Swarm(swarm)).at(3.0)
    view, proj = look_at([0, -160, 40], [0, 0, 0], [0, 0, 1]), perspective(50, 1.3, 0.5, 500)
    lo, hi = posed.bmin_bmax()
    for compiled in ([False, True] if jit.available() else [False]):
        moved = BoxProjector(swarm.bmin, swarm.bmax, compiled=compiled)
        moved.place(posed.center, posed.half)
        fresh = BoxProjector(lo, hi, compiled=compiled, plain=1)
        assert np.array_equal(moved(view, proj), fresh(view, proj), equal_nan=True)


def test_the_swarm_rests_at_time_0_gathers_and_stays_in_its_cube(swarm):
    motion = Swarm(swarm)
    A, b = motion.at(0.0)
    assert np.array_equal(A, np.broadcast_to(np.eye(3), A.shape)) and not b.any()
    home = motion.home() + swarm.origin
    spread = lambda p: np.linalg.norm(p - p.mean(axis=0), axis=1).mean()  # noqa: E731
    posed = Posed(swarm, motion)
    gathered = posed.at(GATHER_S + 0.6).centers
    assert spread(gathered) < 0.3 * spread(home)  # the load crowds into a small part of the screen
    # and the flock moves across the cube: its centre at the tour's corners, a leg apart
    corners = [posed.at(t).centers.mean(axis=0) for t in (LEG_S * 1.1, LEG_S * 2.1, LEG_S * 3.1)]
    assert min(np.linalg.norm(a - b) for a, b in zip(corners, corners[1:])) > 0.4 * SIDE
    assert spread(posed.at(CYCLE_S - 0.2).centers) == pytest.approx(spread(home), rel=0.05)  # home again
    for t in np.linspace(0, 2 * CYCLE_S, 41):
        lo, hi = posed.at(t).bmin_bmax()
        assert lo.min() >= -SIDE / 2 + swarm.origin.min() - 1e-9 and hi.max() <= SIDE / 2 + swarm.origin.max() + 1e-9
    assert swarm.n_objects == 1000 and swarm.n_triangles == 20_000


def test_machinery_moves_its_share_of_bodies_each_with_one_map(plant):
    from multigpu.scene.cluster import split_objects

    cut = split_objects(plant, 40)  # clusters of one modelled object: one body
    motion = Machinery(cut, 0.2, seed=5)
    assert motion.bodies.max() + 1 == plant.n_objects < cut.n_objects
    assert motion.moving.sum() == round(0.2 * plant.n_objects)
    A, b = motion.at(0.0)
    assert np.allclose(A, np.eye(3)) and np.allclose(b, 0)
    A, b = (a.copy() for a in motion.at(2.5))  # the motion's own arrays: valid until its next call
    still = ~motion.moving
    assert np.allclose(A[still], np.eye(3)) and np.allclose(b[still], 0)
    assert (np.abs(A[motion.moving] - np.eye(3)).max(axis=(1, 2)) + np.abs(b[motion.moving]).max(axis=1) > 0).all()
    posed = Posed(cut, motion).at(2.5)
    rest = Posed(cut, motion).at(0.0)
    fixed = still[motion.bodies]
    assert np.array_equal(posed.center[:, fixed], rest.center[:, fixed])  # the others keep their rest boxes
    assert posed.n_moving == int((~fixed).sum())
    again = Machinery(cut, 0.2, seed=5)  # every rank picks the same bodies and the same motions
    assert np.array_equal(again.moving, motion.moving) and np.array_equal(again.at(2.5)[1], b)


def test_scene_time_is_the_frames_and_what_moves_is_known_from_the_spec(swarm, plant):
    assert scene_time(30) == pytest.approx(1.0) and scene_time(45, 2.0) == pytest.approx(90 * FRAME_SECONDS)
    assert scene_time(12, -1.0) == -scene_time(12)
    spec = SceneSpec()
    assert moves(swarm, spec) and isinstance(motion_of(swarm, spec), Swarm)
    assert not moves(plant, spec) and motion_of(plant, spec) is None
    spec = dataclasses.replace(spec, moving=0.2)
    assert moves(plant, spec) and isinstance(motion_of(plant, spec), Machinery)


@pytest.mark.parametrize("field,value,words", [("moving", 1.5, "must be in 0..1"), ("moving", float("nan"), "0..1"),
                                               ("anim_speed", float("inf"), "-1000..1000"),
                                               ("anim_speed", float("nan"), "-1000..1000")])
def test_motion_flags_are_checked_at_the_door(field, value, words):
    with pytest.raises(InputError, match=words):
        SceneSpec(**{field: value})


def test_the_scene_clock_is_the_paths_time_until_steered_then_holds_jumps_and_runs_on():
    from multigpu.core.motion import SceneClock

    clock = SceneClock(speed=1.5)
    assert all(clock.at(f) == scene_time(f, 1.5) for f in range(0, 400, 7))  # bit for bit: a replay's time
    held = clock.at(400, toggles=1)  # paused at frame 400
    assert held == scene_time(400, 1.5) and clock.paused
    assert clock.at(410) == held and clock.at(500) == held  # it stands
    assert clock.at(501, set_to=3.0) == 3.0 and clock.at(520) == 3.0  # a jump, still paused
    assert clock.at(521, scrub=-1.0) == 2.0
    assert clock.at(530, toggles=1) == 2.0 and not clock.paused  # played on from where it stood
    assert clock.at(560) == pytest.approx(2.0 + scene_time(30, 1.5))
    assert clock.at(561, pause=True) == clock.at(600) and clock.paused  # the page's pause: no toggle
    assert clock.at(601, pause=False) == clock.at(601) and not clock.paused


def test_the_keys_pause_and_scrub_the_scene():
    import glfw

    from multigpu.display.controls import SCRUB_SHIFT, Controls

    c = Controls(glfw)
    for key, mods in ((glfw.KEY_T, 0), (glfw.KEY_RIGHT_BRACKET, 0), (glfw.KEY_RIGHT_BRACKET, glfw.MOD_SHIFT),
                      (glfw.KEY_LEFT_BRACKET, 0)):
        c.on_key(None, key, 0, glfw.PRESS, mods)
    got = c.take()
    assert got.scene_pause == 1 and got.scrub == SCRUB_SHIFT and c.take().scene_pause == 0


def test_the_draw_groups_and_the_order_sort_last_ranges_follow_agree():
    """Where some objects stand still the renderer draws groups in turn (at rest, moving; the wide
    ones last): every object in exactly one group, and ``pass_order`` lists them in that order,
    so db's and hybrid's ranges keep the lower rank's fragment where a one-rank render keeps its."""
    from multigpu.core.drawlist import pass_groups, pass_order

    rng = np.random.default_rng(9)
    wide, movers = rng.random(200) < 0.2, rng.random(200) < 0.3
    order = rng.permutation(200)
    groups = pass_groups(wide, movers)
    assert np.array_equal(np.sum([g for g, _ in groups], axis=0), np.ones(200))
    assert [p for _, p in groups] == [0, 1, 0, 1]
    got = pass_order(order, wide, movers)
    assert sorted(got) == list(range(200))
    rank = np.empty(200, dtype=np.int64)
    rank[got] = np.arange(200)
    for i, (g, _) in enumerate(groups):  # each group after the last, in draw order within
        members = order[g[order]]
        assert (np.diff(rank[members]) == 1).all()
        if i:
            assert rank[members].min() > rank[order[groups[i - 1][0][order]]].max()
    assert pass_groups(wide, None) is None and pass_groups(wide, np.ones(200, bool)) is None
    assert np.array_equal(pass_order(order, wide, None), order)


@needs_numba
def test_the_compiled_flight_makes_the_references_maps(swarm):
    fast, slow = Swarm(swarm, compiled=True), Swarm(swarm, compiled=False)
    for t in (0.0, 0.3, 1.7, 5.2, 13.1, -1.0):
        for got, want in zip(fast.at(t), slow.at(t)):
            assert np.array_equal(got, want), t


@needs_numba
def test_the_compiled_machinery_makes_the_references_maps(plant):
    fast, slow = Machinery(plant, 0.3, seed=5, compiled=True), Machinery(plant, 0.3, seed=5, compiled=False)
    assert fast.which.size > 10
    for t in (0.0, 0.4, 2.9, 17.3, -3.0):
        for got, want in zip(fast.at(t), slow.at(t)):
            assert np.array_equal(got, want), t
