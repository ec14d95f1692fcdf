"""glTF animation in one process: the running pump's channels played as the specification says
(LINEAR with slerp, STEP, CUBICSPLINE, a hierarchy of pivots, each animation looped), ``--animation``,
bounds that hold the moved vertices, and bad files refused in one line naming the field."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from multigpu.core.motion import Posed
from multigpu.core.triangles import triangle_objects
from multigpu.errors import InputError
from multigpu.scene.files import load_model
from multigpu.scene.gltf_motion import GltfMotion, slerp
from multigpu.scene.models import SceneSpec
from multigpu.scene.moves import motion_of, moves

ROOT = Path(__file__).resolve().parents[1]
PUMP = ROOT / "models" / "pump-running.glb"
SAMPLES = Path("/usr/share/assimp/models/glTF2")


@pytest.fixture(scope="module")
def pump():
    return load_model(PUMP)


def node_names(scene):
    import pygltflib

    doc = pygltflib.GLTF2().load(str(PUMP))
    return [doc.nodes[k].name for k in scene.meta["gltf"]["nodes"]]


def body_map(scene, motion, name, t):
    """(4, 4) the world map of the first object hanging from node ``name`` at time ``t``."""
    i = node_names(scene).index(name)
    A, b = motion.at(t)
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = A[motion.bodies[i]], b[motion.bodies[i]]
    o = np.eye(4)
    o[:3, 3] = scene.origin
    return o @ M @ np.linalg.inv(o)  # local coordinates about the origin to world


def turn(axis, degrees, about):
    from multigpu.scene.gltf_motion import trs

    q = np.r_[np.sin(np.radians(degrees) / 2) * np.asarray(axis, float), np.cos(np.radians(degrees) / 2)]
    R = trs(np.zeros((1, 3)), q[None], np.ones((1, 3)))[0]
    T = np.eye(4)
    T[:3, 3] = about
    return T @ R @ np.linalg.inv(T)


def test_the_pump_records_its_nodes_and_animations(pump):
    g = pump.meta["gltf"]
    assert g["animations"] == ["run", "lift"] and len(g["nodes"]) == pump.n_objects
    names = node_names(pump)
    assert names.count("gauge") == 1 and "fin_0" in names and not pump.meta["warnings"]


@pytest.mark.parametrize("t,degrees", [(0.0, 0.0), (0.125, 45.0), (0.25, 90.0), (0.4, 144.0), (1.1, 396.0)])
def test_linear_rotations_slerp_about_their_pivot(pump, t, degrees):
    """The fins' cage turns about the motor's axis through its pivot: keys every 90 degrees,
    slerp between them (constant angular speed)."""
    got = body_map(pump, GltfMotion(pump), "fin_3", t)
    assert np.allclose(got, turn([1, 0, 0], degrees, [-0.45, 0.3, 0.0]), atol=1e-9)


@pytest.mark.parametrize("t,degrees", [(0.0, 0), (0.49, 0), (0.5, 45), (0.99, 45), (1.2, 90), (1.7, 135), (1.99, 135)])
def test_step_holds_each_key_until_the_next(pump, t, degrees):
    got = body_map(pump, GltfMotion(pump), "flange_1_bolt_2", t)
    assert np.allclose(got, turn([0, 1, 0], degrees, [0.28, 0.97, 0.0]), atol=1e-9)


def test_cubicspline_scale_is_hermite_with_tangents_times_the_interval(pump):
    m = GltfMotion(pump)
    pivot = np.array([0.28, 0.86, 0.09])
    for t in (0.0, 0.3, 0.5, 1.0, 1.6):
        k = int(t >= 1.0)
        s = t - k  # keys at 0, 1, 2 s: values 1, 1.4, 1; tangents 0
        v0, v1 = (1.0, 1.4) if k == 0 else (1.4, 1.0)
        h = (2 * s**3 - 3 * s**2 + 1) * v0 + (-2 * s**3 + 3 * s**2) * v1
        want = np.eye(4)
        want[:3, :3] *= h
        want[:3, 3] = pivot - h * pivot
        assert np.allclose(body_map(pump, m, "gauge", t), want, atol=1e-9), t


def test_linear_translation_and_each_animation_loops_over_its_length(pump):
    m = GltfMotion(pump)
    for t, y in ((0.0, 0.0), (0.5, 0.06), (1.0, 0.12), (1.5, 0.06), (2.5, 0.06), (4.25, 0.03)):
        got = body_map(pump, m, "pipe_2", t)
        assert np.allclose(got[:3, 3], [0, y, 0], atol=1e-9) and np.allclose(got[:3, :3], np.eye(3)), t
    assert np.allclose(body_map(pump, m, "fin_0", 2.3), body_map(pump, m, "fin_0", 0.3), atol=1e-9)


def test_slerp_takes_the_shorter_way_and_keeps_unit_length():
    a = np.array([[0.0, 0, 0, 1]])
    b = -np.array([[0.0, 0, np.sin(0.5), np.cos(0.5)]])  # the same turn, the other sign
    mid = slerp(a, b, np.array([0.5]))
    assert np.allclose(mid, [[0, 0, np.sin(0.25), np.cos(0.25)]]) and np.isclose(np.linalg.norm(mid), 1)


def test_animation_picks_and_the_still_parts(pump):
    spec = SceneSpec(model=str(PUMP))
    assert moves(pump, spec) and isinstance(motion_of(pump, spec), GltfMotion)
    lift = GltfMotion(pump, "lift")
    names = np.array(node_names(pump))
    moving = lift.moving[lift.bodies]
    assert set(names[moving]) == {f"pipe_{k}" for k in range(6)}
    everything = GltfMotion(pump, "all")
    assert set(names[everything.moving[everything.bodies]]) > set(names[moving])
    assert not moves(pump, dataclasses.replace(spec, animation="none"))
    assert not moves(pump, dataclasses.replace(spec, anim_speed=0.0))
    with pytest.raises(InputError, match=r"--animation 'spin': .*pump-running.glb has no such animation "
                                         r"\(it has: 'run', 'lift'\)"):
        GltfMotion(pump, "spin")


@pytest.mark.parametrize("t", [0.3, 0.9, 1.7])
def test_posed_bounds_hold_the_animated_vertices(pump, t):
    m = GltfMotion(pump)
    posed = Posed(pump, m).at(t)
    A, b = m.at(t)
    tri, obj = triangle_objects(pump)
    local = pump.vertices[:, :3].astype(np.float64)[tri]
    world = np.einsum("tij,tvj->tvi", A[m.bodies[obj]], local) + b[m.bodies[obj]][:, None, :] + pump.origin
    lo, hi = posed.bmin_bmax()
    tol = 1e-6
    assert (world >= lo[obj][:, None] - tol).all() and (world <= hi[obj][:, None] + tol).all()


def broken(tmp_path, change) -> Path:
    """The running pump with ``change(doc)`` applied, as a .glb of its own."""
    import pygltflib

    doc = pygltflib.GLTF2().load(str(PUMP))
    change(doc)
    out = tmp_path / "broken.glb"
    doc.save_binary(str(out))
    return out


def set_times(doc, values):
    """The first sampler's input keys rewritten in place (its accessor's bytes)."""
    import pygltflib  # noqa: F401

    acc = doc.accessors[doc.animations[0].samplers[0].input]
    view = doc.bufferViews[acc.bufferView]
    blob = bytearray(doc.binary_blob())
    arr = np.frombuffer(bytes(blob[view.byteOffset:view.byteOffset + view.byteLength]), dtype=np.float32).copy()
    arr[:len(values)] = values
    blob[view.byteOffset:view.byteOffset + view.byteLength] = arr.tobytes()
    doc.set_binary_blob(bytes(blob))


@pytest.mark.parametrize("change,field", [
    (lambda d: setattr(d.animations[0].channels[0].target, "node", 999), r"channels\[0\]\.target\.node: targets"),
    (lambda d: set_times(d, [0.0, 0.5, 0.4]), r"animations\[0\]\.samplers\[0\]\.input: keyframe times must"),
    (lambda d: set_times(d, [0.0, np.nan]), r"animations\[0\]\.samplers\[0\]\.input"),
    (lambda d: set_times(d, [0.0, np.inf]), r"animations\[0\]\.samplers\[0\]\.input"),
    (lambda d: setattr(d.accessors[d.animations[0].samplers[0].output], "count", 10**6), r"accessors\[\d+\]: reads"),
    (lambda d: setattr(d.animations[1].samplers[0], "output", 10**4), r"accessors\[10000\]: no such accessor"),
    (lambda d: setattr(d.animations[0].samplers[0], "interpolation", "BOUNCY"), r"interpolation: 'BOUNCY'"),
], ids=["missing-node", "times-decrease", "times-nan", "times-inf", "accessor-range", "no-accessor", "mode"])
def test_bad_animations_are_refused_in_one_line_naming_the_field(tmp_path, change, field):
    path = broken(tmp_path, change)
    with pytest.raises(InputError, match=field) as got:
        scene = load_model(path)
        GltfMotion(scene)
    assert "\n" not in str(got.value) and str(path) in str(got.value)


needs_samples = pytest.mark.skipif(not SAMPLES.is_dir(), reason="Debian's assimp-testmodels is not installed")
MORPH_CUBE = SAMPLES / "glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf"


SKIN = SAMPLES / "simple_skin/simple_skin.gltf"


@needs_samples
@pytest.mark.parametrize("t", [0.0, 0.8, 1.9, 3.3, 5.4])
def test_a_skin_plays_by_its_joints_and_the_bounds_hold_every_pose(t):
    """Khronos' simple_skin: each vertex the weighted mean of its joints' maps (joint world
    matrix times inverse bind matrix), inside the posed bounds at every time."""
    scene = load_model(SKIN)
    assert scene.skin_joints.shape == (len(scene.vertices), 4) and not scene.meta["warnings"]
    m = GltfMotion(scene)
    assert m.moving.all() and m.skinned.all()
    posed = Posed(scene, m).at(t)
    A, b = m.last_palette
    local = scene.vertices[:, :3].astype(np.float64)
    w, j = scene.skin_weights.astype(np.float64), scene.skin_joints.astype(np.int64)
    moved = np.einsum("vk,vkij,vj->vi", w, A[j], local) + np.einsum("vk,vki->vi", w, b[j])
    tri, obj = triangle_objects(scene)
    world = moved[tri] + scene.origin
    lo, hi = posed.bmin_bmax()
    tol = 1e-5 * max(np.abs(local).max(), 1.0)
    assert (world >= lo[obj][:, None] - tol).all() and (world <= hi[obj][:, None] + tol).all()
    if t == 1.9:  # the second joint turned: the strip bends (its top no longer above its foot)
        top = moved[np.argmax(local[:, 1])]
        assert abs(top[0] - local[np.argmax(local[:, 1]), 0]) > 0.1


@needs_samples
def test_a_joint_index_beyond_the_skin_is_refused_in_one_line(tmp_path):
    import shutil

    import pygltflib

    shutil.copy(SKIN, tmp_path / "skin.gltf")
    doc = pygltflib.GLTF2().load(str(tmp_path / "skin.gltf"))
    doc.skins[0].joints = doc.skins[0].joints[:1]  # its vertices lean on joint 1, which is no more
    doc.accessors[4].count = 1
    out = tmp_path / "broken.gltf"
    doc.save(str(out))
    with pytest.raises(InputError, match=r"meshes\[0\]\.primitives\[0\]\.attributes\.JOINTS_0: joint index 1 exceeds "
                                         r"skin 0's 1 joints") as got:
        load_model(out)
    assert "\n" not in str(got.value)


@needs_samples
def test_morph_target_weights_play_as_sampled_and_the_bounds_hold_the_morphed_vertices():
    """Khronos' AnimatedMorphCube: its weights channel sampled LINEAR between its keyframes, every
    vertex moved by the weighted deltas (in world space), inside the posed bounds."""
    import pygltflib

    from multigpu.scene.gltf_motion import accessor

    scene = load_model(MORPH_CUBE)
    assert scene.morph_deltas.shape[1] == 2 and not scene.meta["warnings"]
    m = GltfMotion(scene)
    assert m.moving.all() and m.morph_of.tolist() == [[0, 2]]
    doc = pygltflib.GLTF2().load(str(MORPH_CUBE))
    s = doc.animations[0].samplers[0]
    times, values = accessor(doc, MORPH_CUBE, s.input, {})[:, 0], accessor(doc, MORPH_CUBE, s.output, {})
    values = values.reshape(len(times), 2)
    posed = Posed(scene, m)
    tri, obj = triangle_objects(scene)
    for t in (0.0, 0.37, 1.5, 2.2, times[-1] - 0.01):
        posed.at(t)
        want = np.array([np.interp(t, times, values[:, k]) for k in range(2)])
        assert np.allclose(m.last_weights, want, atol=1e-9), t
        local = scene.vertices[:, :3].astype(np.float64)
        rows = scene.morph_rows
        moved = local.copy()
        has = rows >= 0
        moved[has] += (scene.morph_deltas[rows[has]] * m.last_weights[None, :, None]).sum(axis=1)
        A, b = m.at(t)
        world = moved[tri] @ A[0].T + b[0] + scene.origin
        lo, hi = posed.bmin_bmax()
        tol = 1e-5 * np.abs(local).max()
        assert (world >= lo[obj][:, None] - tol).all() and (world <= hi[obj][:, None] + tol).all(), t
    assert np.ptp(posed.at(0.0).half) != np.ptp(posed.at(2.2).half)  # the box follows the morph


def _morph_broken(tmp_path, change) -> Path:
    import shutil

    import pygltflib

    for f in MORPH_CUBE.parent.iterdir():
        shutil.copy(f, tmp_path / f.name)
    doc = pygltflib.GLTF2().load(str(tmp_path / MORPH_CUBE.name))
    change(doc)
    out = tmp_path / "broken.gltf"
    doc.save(str(out))
    return out


@needs_samples
@pytest.mark.parametrize("change,field", [
    (lambda d: setattr(d.accessors[7], "count", 23), r"meshes\[0\]\.primitives\[0\]\.targets\[1\]\.POSITION: holds 23"),
    (lambda d: setattr(d.accessors[11], "count", 253), r"animations\[0\]\.samplers\[0\]\.output"),
], ids=["target-counts-differ", "weights-count"])
def test_bad_morph_targets_are_refused_in_one_line(tmp_path, change, field):
    path = _morph_broken(tmp_path, change)
    with pytest.raises(InputError, match=field) as got:
        GltfMotion(load_model(path))
    assert "\n" not in str(got.value) and str(path) in str(got.value)
