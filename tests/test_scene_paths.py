"""Plant generator, model loading (every format, both splits), cache, camera paths, bad input."""

import json

import numpy as np
import pytest
import trimesh

from multigpu.errors import InputError
from multigpu.scene.layout import Scene
from multigpu.scene.models import SceneSpec, load_model, load_scene
from multigpu.scene.paths import catmull_rom, load_path, orbit, walkthrough
from multigpu.scene.plant import generate_plant


def test_plant_deterministic_and_scales():
    a, b = generate_plant(30_000, seed=4), generate_plant(30_000, seed=4)
    for k, v in a._arrays().items():
        assert np.array_equal(v, getattr(b, k)), k
    big = generate_plant(300_000, seed=4)
    assert 5 < big.n_triangles / a.n_triangles < 15
    tris = big.tris
    assert tris.max() > 50 * np.median(tris)  # heavy tail
    two = generate_plant(60_000, copies=2)
    assert two.bounds[1, 0] - two.bounds[0, 0] > 1.8 * (a.bounds[1, 0] - a.bounds[0, 0])
    # layout: each object's index range lies in the index buffer, its indices within the vertices
    assert (big.first_index + big.index_count <= big.indices.size).all() and (big.index_count % 3 == 0).all()
    assert (np.diff(big.first_index) == big.index_count[:-1]).all()  # contiguous, in object order
    assert (big.indices.astype(np.int64) + np.repeat(big.base_vertex, big.index_count)).max() < big.vertices.shape[0]


def _mesh():
    parts = [trimesh.creation.box().apply_translation([i * 3.0, 0, 0]) for i in range(4)]
    return trimesh.util.concatenate(parts + [trimesh.creation.icosphere().apply_translation([0, 5, 0])])


@pytest.mark.parametrize("ext", ["obj", "ply", "stl", "off", "glb"])
def test_loader_round_trip(tmp_path, ext):
    p = tmp_path / f"m.{ext}"
    _mesh().export(p)
    s = load_model(p, "components", merge_below=0)
    assert s.n_objects == 5 and s.n_triangles == 4 * 12 + 1280
    assert sorted(s.tris.tolist()) == [12, 12, 12, 12, 1280]
    assert np.allclose(np.linalg.norm(s.vertices[:, 3:], axis=1), 1, atol=1e-4)
    assert np.allclose(s.bounds, _mesh().bounds, atol=1e-6)
    g = load_model(p, "grid:2")
    assert g.n_triangles == s.n_triangles and g.n_objects >= 2


def test_scene_graph_one_object_per_node(tmp_path):
    sc = trimesh.Scene()
    for i in range(3):
        sc.add_geometry(trimesh.creation.box(), transform=trimesh.transformations.translation_matrix([i * 2.0, 0, 0]))
    p = tmp_path / "s.glb"
    sc.export(p)
    s = load_model(p)
    assert s.n_objects == 3
    assert sorted(s.bmin[:, 0].round(3).tolist()) == [-0.5, 1.5, 3.5]


def test_cache_hit_returns_identical_arrays(tmp_path, monkeypatch):
    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path))
    a, ia = load_scene(SceneSpec(triangles=20_000, seed=1))
    b, ib = load_scene(SceneSpec(triangles=20_000, seed=1))
    assert not ia["cached"] and ib["cached"]
    for k, v in a._arrays().items():
        assert np.array_equal(v, getattr(b, k))
    from multigpu.scene.layout import MAPPED, Scene

    copy = Scene.load(ib["cache"], mapped=False)
    for s in (a, b):  # the builder's scene too: reloaded mapped from the file it saved
        for k in MAPPED:  # the bulk is a read-only map of the cache file, equal to a copy of it
            v = getattr(s, k)
            if v is None:  # vertex colours, textures: the plant has none
                assert getattr(copy, k) is None and k in Scene.PER_VERTEX
                continue
            assert isinstance(v, np.memmap) and not v.flags.writeable and np.array_equal(v, getattr(copy, k))


def test_a_scene_without_geometry_unmaps_the_cache_file(tmp_path, monkeypatch):
    """What the frame loop keeps after the GL upload: bounds, ranges and colours, and no map of
    the cache file's vertex and index buffers (their pages leave the rank)."""
    import gc

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path))
    load_scene(SceneSpec(triangles=20_000, seed=2))
    scene, info = load_scene(SceneSpec(triangles=20_000, seed=2))

    def maps_cache() -> bool:
        with open("/proc/self/maps") as fh:
            return any(str(info["cache"]) in line for line in fh)

    assert maps_cache()
    bare = scene.without_geometry()
    del scene
    gc.collect()
    assert not maps_cache()
    whole = Scene.load(info["cache"], mapped=False)
    assert bare.vertices.shape == (0, 6) and bare.indices.size == 0 and bare.n_triangles == whole.n_triangles
    for k in ("first_index", "index_count", "base_vertex", "bmin", "bmax", "centers", "radii", "colors", "origin"):
        assert np.array_equal(getattr(bare, k), getattr(whole, k))
    assert bare.meta == whole.meta and bare.name == whole.name


@pytest.mark.parametrize("content,needle", [
    (None, "model file not found"), (b"\x00\x01garbage", "cannot read as PLY"),
    (b"", "cannot read as PLY (ValueError: Not a ply file!)")])
def test_bad_model_files(tmp_path, content, needle):
    p = tmp_path / "bad.ply"
    if content is not None:
        p.write_bytes(content)
    with pytest.raises(InputError) as e:
        load_scene(SceneSpec(model=str(p)), use_cache=False)
    assert "bad.ply" in str(e.value) and needle in str(e.value)


def test_unsupported_extension_and_nonfinite(tmp_path):
    p = tmp_path / "m.xyz"
    p.write_text("1 2 3")
    with pytest.raises(InputError, match="unsupported extension"):
        load_scene(SceneSpec(model=str(p)))
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 0], [5, 5, 5], [6, 5, 5], [5, 6, 5.0]])
    f = np.array([[0, 1, 2], [3, 1, 2], [4, 5, 6], [4, 4, 5]])
    q = tmp_path / "n.ply"
    trimesh.Trimesh(v, f, process=False).export(q)
    s = load_model(q, merge_below=0)
    assert s.n_triangles == 2
    assert any("non-finite" in w for w in s.meta["warnings"]) and any("degenerate" in w for w in s.meta["warnings"])


def test_path_interpolation_continuity():
    pts = np.array([[0, 0, 0], [1, 2, 0], [3, 3, 1], [4, 0, 2.0]])
    t = np.linspace(0, 3, 3001)
    c = catmull_rom(pts, t)
    assert np.allclose(c[::1000], pts)
    step = np.linalg.norm(np.diff(c, axis=0), axis=1)
    assert step.max() < 5 * np.median(step)  # no jumps
    vel = np.diff(c, axis=0)
    assert np.abs(np.diff(vel, axis=0)).max() < 1e-3  # C1: velocity changes smoothly


def test_generated_paths_and_round_trip(tmp_path):
    scene = generate_plant(20_000)
    w = walkthrough(scene, frames=1200)
    assert len(w) == 1200 and np.isfinite(w.position).all()
    o = orbit(scene, frames=90)
    d = np.linalg.norm(o.position - o.target, axis=1)
    assert np.allclose(d, d[0])
    p = tmp_path / "p.json"
    w.save(p)
    back = load_path(p)
    assert np.allclose(back.position, w.position) and np.allclose(back.fov, w.fov)


@pytest.mark.parametrize("doc,needle", [
    ({"keyframes": [{"target": [0, 0, 0]}]}, "keyframes[0] is missing the field 'position'"),
    ({"keyframes": [{"position": [0, 0], "target": [1, 1, 1]}]}, "keyframes[0].position must be a list of 3"),
    ({"keyframes": [{"position": [0, 0, 0], "target": [1, 1, 1], "fov": "wide"}]}, "keyframes[0].fov"),
    ({"cameras": []}, "'cameras' must be a non-empty list"),
    ({"frames": -3, "keyframes": [{"position": [0, 0, 0], "target": [1, 1, 1]}]}, "'frames'"),
    ({"foo": 1}, "needs a field 'keyframes' or 'cameras'"),
])
def test_bad_path_files(tmp_path, doc, needle):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(InputError) as e:
        load_path(p)
    assert "bad.json" in str(e.value) and needle in str(e.value)
    p.write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        load_path(p)


def test_models_and_clusters_built_a_block_of_faces_at_a_time_are_the_same(tmp_path, monkeypatch):
    """Loading a model (components merged, degenerate faces dropped, grid split, scene-graph
    nodes) and cutting objects into clusters go a block of faces at a time: blocks that cut
    objects anywhere give the very arrays of one whole-array pass."""
    import multigpu.scene.blocks as blocks
    from multigpu.scene.cluster import split_objects

    rng = np.random.default_rng(0)
    parts = [trimesh.creation.icosphere(subdivisions=4)]
    for _ in range(12):
        b = trimesh.creation.box(extents=rng.uniform(0.1, 1, 3))
        b.apply_translation(rng.uniform(-5, 5, 3))
        parts.append(b)
    for _ in range(40):  # parts under merge_below: merged by grid cell
        t = trimesh.creation.icosphere(subdivisions=0, radius=0.05)
        t.apply_translation(rng.uniform(3, 3.5, 3))
        parts.append(t)
    m = trimesh.util.concatenate(parts)
    trimesh.Trimesh(m.vertices, np.vstack([m.faces, [[0, 0, 1]]]), process=False).export(tmp_path / "m.ply")
    graph = trimesh.Scene()
    for i, p in enumerate(parts[:10]):
        graph.add_geometry(p, transform=trimesh.transformations.translation_matrix([i * 0.1, 0, 0]))
    graph.export(tmp_path / "m.glb")
    cases = [("m.ply", "auto"), ("m.ply", "grid:8"), ("m.glb", "auto"), ("m.glb", "grid:4")]

    def build():
        scenes = [load_model(tmp_path / f, split=split) for f, split in cases]
        return scenes + [split_objects(scenes[0], 37), split_objects(generate_plant(triangles=20_000, seed=1), 16)]

    whole = build()
    monkeypatch.setattr(blocks, "FACE_BLOCK", 997)
    for a, b in zip(whole, build()):
        assert a.meta == b.meta
        for k, v in a._arrays().items():
            np.testing.assert_array_equal(v, getattr(b, k), err_msg=k)
    assert whole[0].meta["warnings"] == ["dropped 1 degenerate faces"] and whole[0].n_objects < len(parts)


def test_compiled_components_equal_scipys():
    """Union-find (compiled) and scipy's sparse graph give the same face labels: the same
    partition, numbered in the same order of lowest vertex (so scenes are identical)."""
    from multigpu.core import jit
    from multigpu.scene.labels import component_labels

    if not jit.available():
        pytest.skip("numba is not installed: only scipy's reference runs")
    rng = np.random.default_rng(5)
    for n_verts, n_faces in ((3, 1), (50, 10), (400, 300), (5000, 2000), (2000, 6000)):
        verts = rng.normal(size=(n_verts, 3))
        verts[rng.integers(0, n_verts, n_verts // 5)] = verts[0]  # duplicated positions are one vertex
        faces = rng.integers(0, n_verts, size=(n_faces, 3))
        want = component_labels(faces, verts, compiled=False)
        got = component_labels(faces, verts, compiled=True)
        assert np.array_equal(np.unique(want, return_inverse=True)[1], np.unique(got, return_inverse=True)[1])
    m = trimesh.util.concatenate([trimesh.creation.icosphere(1).apply_translation([3 * i, 0, 0]) for i in range(4)])
    got = component_labels(np.asarray(m.faces), np.asarray(m.vertices), compiled=True)
    assert len(np.unique(got)) == 4 and (np.diff(got) >= 0).all()  # four spheres, in file order


def test_a_scene_s_objects_alone_keep_their_ranges_and_bounds_and_share_the_buffers():
    """``Scene.objects(idx)``: those objects, in that order (``bench frame`` plans a few of a
    scene's objects); a bad index is one clear error."""
    scene = generate_plant(20_000, seed=3)
    idx = np.array([5, 0, scene.n_objects - 1])
    few = scene.objects(idx)
    assert few.n_objects == 3
    for k in ("first_index", "index_count", "base_vertex", "bmin", "bmax", "centers", "radii", "colors"):
        assert np.array_equal(getattr(few, k), getattr(scene, k)[idx]), k
    assert few.vertices is scene.vertices and few.indices is scene.indices
    assert few.n_triangles == int(scene.tris[idx].sum())
    for bad in ([scene.n_objects], [-1], [[0, 1]]):
        with pytest.raises(InputError, match="object indices"):
            scene.objects(bad)


#: small valid models of the shapes that broke generated paths: tiny, flat, nearly a line, far
#: from the origin, standing in a vertical plane, one triangle
ODD_MODELS = {
    "tiny": ([[0, 0, 0], [1e-6, 0, 0], [0, 1e-6, 0]], [[0, 1, 2]]),
    "flat": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 3, 2]]),
    "sliver": ([[0, 0, 0], [1, 0, 0], [2, 0, 1e-7]], [[0, 1, 2]]),
    "far": ([[1e7, 1e7, 1e7], [1e7 + 1, 1e7, 1e7], [1e7, 1e7 + 1, 1e7]], [[0, 1, 2]]),
    "vertical": ([[0, 0, 0], [0, 0, 1], [0, 1, 0]], [[0, 1, 2]]),
    "two-apart": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [50, 0, 0], [51, 0, 0], [50, 1, 0]], [[0, 1, 2], [3, 4, 5]]),
}


@pytest.mark.parametrize("name", sorted(ODD_MODELS))
def test_generated_paths_are_valid_for_every_model_that_loads(tmp_path, name):
    """Every frame of every generated path, at short and long lengths, is a camera (its position
    apart from its target, finite matrices) for small, flat and degenerate-size models."""
    from multigpu.core.camera import frame_matrices
    from multigpu.scene.paths import GENERATORS, generate

    verts, faces = ODD_MODELS[name]
    model = tmp_path / f"{name}.ply"
    trimesh.Trimesh(np.array(verts, dtype=np.float64), faces, process=False).export(model)
    scene, _ = load_scene(SceneSpec(model=str(model)))
    for kind in GENERATORS:
        for frames in (1, 2, 3, 4, 5, 7, 13, 40):
            path = generate(kind, scene, frames)
            for f in range(len(path)):  # frames, not objects
                view, proj, light = frame_matrices(path.camera(f), (64, 64))
                assert np.isfinite(view).all() and np.isfinite(proj).all(), (kind, frames, f)


def test_a_still_path_holds_the_camera_where_the_walkthrough_starts():
    """``--path-kind still``: a scene's own motion watched from one place."""
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import generate

    scene = load_scene(SceneSpec(triangles=2_000))[0]
    walk, held = generate("walkthrough", scene), generate("still", scene, 7)
    assert len(held) == 7 and all(held.camera(f) == walk.camera(0) for f in range(7))
    assert len(generate("still", scene)) == 300
