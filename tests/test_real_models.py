"""Models as users bring them: any scale, their own up axis, one big mesh, truncated files,
and the model shipped in models/ (issue: real models)."""

from pathlib import Path

import numpy as np
import pytest
import trimesh

from multigpu.cli import main as cli
from multigpu.core.camera import frame_matrices
from multigpu.core.projectors import make_projector
from multigpu.errors import InputError
from multigpu.records.report import COLUMNS, table
from multigpu.records.tally import summarize
from multigpu.scene.models import SceneSpec, axis_name, load_scene
from multigpu.scene.paths import orbit, walkthrough

ROOT = Path(__file__).resolve().parents[1]
PUMP = ROOT / "models" / "pump.glb"
T = trimesh.transformations


def city(scale: float) -> trimesh.Trimesh:
    """Wide and flat, Z up: blocks on a big ground slab (one mesh, many components)."""
    rng = np.random.default_rng(1)
    parts = [trimesh.creation.box([100, 100, 0.5], T.translation_matrix([50, 50, -0.25]))]
    for i in range(10):
        for j in range(10):
            h = rng.uniform(2, 20)
            parts.append(trimesh.creation.box([5, 5, h], T.translation_matrix([i * 10 + 5, j * 10 + 5, h / 2])))
    m = trimesh.util.concatenate(parts)
    m.apply_scale(scale)
    return m


def engine(scale: float) -> trimesh.Scene:
    """Compact assembly of parts (a scene graph)."""
    rng = np.random.default_rng(2)
    sc = trimesh.Scene()
    for k in range(24):
        c = trimesh.creation.cylinder(radius=rng.uniform(0.05, 0.15), height=rng.uniform(0.2, 0.6), sections=24)
        c.apply_translation(rng.uniform(-0.4, 0.4, 3))
        c.apply_scale(scale)
        sc.add_geometry(c, node_name=f"part{k}")
    return sc


def statue(scale: float) -> trimesh.Trimesh:
    """One closed mesh, tall along Y (a scanned figure, Y up)."""
    m = trimesh.creation.icosphere(subdivisions=4)
    m.vertices *= [0.6, 1.0, 0.45]
    m.apply_scale(scale)
    return m


MAKERS = {"city.obj": city, "engine.glb": engine, "statue.ply": statue}


def _write(tmp_path, name, scale):
    f = tmp_path / f"{scale:g}-{name}"
    MAKERS[name](scale).export(f)
    return f


def visible_share(scene, path, size=(320, 240)):
    """Per frame: share of the scene's triangles whose bounds are in view."""
    project = make_projector(scene, "box")
    out = []
    for f in range(len(path)):
        view, proj, _ = frame_matrices(path.camera(f), size)
        r = project(view, proj)
        with np.errstate(invalid="ignore"):
            ok = (r[:, 2] >= 0) & (r[:, 0] <= 1) & (r[:, 3] >= 0) & (r[:, 1] <= 1)
        out.append(scene.tris[ok].sum() / scene.tris.sum())
    return np.array(out)


@pytest.mark.parametrize("name", list(MAKERS))
def test_generated_paths_see_the_scene_at_every_scale(tmp_path, name):
    near = {}
    for scale in (1e-3, 1.0, 1e4):
        scene, _ = load_scene(SceneSpec(model=str(_write(tmp_path, name, scale))), use_cache=False)
        diag = float(np.linalg.norm(scene.bounds[1] - scene.bounds[0]))
        for kind, make in (("walkthrough", walkthrough), ("orbit", orbit)):
            path = make(scene, frames=90)
            share = visible_share(scene, path)
            assert (share > 0).all(), f"{name} x{scale:g} {kind}: frames {np.flatnonzero(share == 0)} see nothing"
            assert (path.far > path.near).all() and (path.far <= 10 * diag).all()
            near.setdefault(kind, []).append(path.near[0] / diag)
    for kind, ratios in near.items():  # near/far fitted to the scene: the same at every scale
        assert np.allclose(ratios, ratios[0], rtol=1e-6), (kind, ratios)


def test_wide_walkthrough_stays_above_the_ground(tmp_path):
    scene, _ = load_scene(SceneSpec(model=str(_write(tmp_path, "city.obj", 1e-3))), use_cache=False)
    lo, hi = scene.bounds
    path = walkthrough(scene, frames=300)
    assert axis_name(scene.meta["up"]) == "+z"
    assert (path.position[:, 2] > lo[2]).all()


def test_compact_model_gets_an_overview_then_its_parts(tmp_path):
    scene, _ = load_scene(SceneSpec(model=str(_write(tmp_path, "engine.glb", 1.0))), use_cache=False)
    path = walkthrough(scene, frames=100)
    share = visible_share(scene, path)
    assert (share[:40] == 1.0).all()  # overview: the whole model in view
    centre = scene.bounds.mean(axis=0)
    radius = np.linalg.norm(scene.bounds[1] - scene.bounds[0]) / 2
    dist = np.linalg.norm(path.position - centre, axis=1)
    assert (dist > radius).all()  # never inside the model
    assert dist[40:].min() < 0.7 * dist[:40].min()  # then closer looks at the parts


@pytest.mark.parametrize("name,flags,up,source", [
    ("engine.glb", {}, "+y", "glTF convention"),
    ("statue.ply", {}, "+y", "PLY convention"),
    ("city.obj", {}, "+z", "flat scene"),
    ("statue.ply", {"up": "-z"}, "-z", "--up"),
])
def test_up_axis(tmp_path, name, flags, up, source):
    scene, _ = load_scene(SceneSpec(model=str(_write(tmp_path, name, 1.0)), **flags), use_cache=False)
    assert axis_name(scene.meta["up"]) == up and source in scene.meta["up_source"]


def test_stl_is_z_up_by_convention(tmp_path):
    f = tmp_path / "part.stl"
    statue(1.0).export(f)
    scene, _ = load_scene(SceneSpec(model=str(f)), use_cache=False)
    assert axis_name(scene.meta["up"]) == "+z" and "STL convention" in scene.meta["up_source"]


def test_bad_up_flag():
    with pytest.raises(InputError, match="up must be one of"):
        SceneSpec(up="w")


def test_scene_info_prints_up_and_split(tmp_path, capsys):
    f = _write(tmp_path, "statue.ply", 1.0)
    assert cli(["scene", "info", str(f), "--no-cache", "--grid", "2x2"]) == 0
    out = capsys.readouterr().out
    assert "up         +y (PLY convention (Y up))" in out
    assert "split      components: 1 objects as modelled ->" in out and "cut into clusters for 4 ranks" in out


@pytest.mark.parametrize("ranks", [4, 9, 16])
def test_single_mesh_is_cut_for_the_wall(tmp_path, ranks):
    f = _write(tmp_path, "statue.ply", 1.0)
    scene, _ = load_scene(SceneSpec(model=str(f), ranks=ranks), use_cache=False)
    tris = scene.tris
    assert scene.meta["objects"]["modelled"] == 1
    assert tris.max() / tris.sum() <= 1 / (4 * ranks) + 1e-9 or tris.max() <= 64
    assert scene.n_objects >= min(8 * ranks, tris.sum() // 64)
    whole, _ = load_scene(SceneSpec(model=str(f), ranks=ranks, cluster=0), use_cache=False)
    assert whole.n_objects == 1 and whole.meta["objects"]["cluster"] == 0


def test_balanced_scene_is_kept_as_modelled(tmp_path):
    scene, _ = load_scene(SceneSpec(triangles=20000, ranks=4))
    assert scene.meta["objects"]["cluster"] == 0 and "kept as modelled" in scene.meta["objects"]["why"]


def test_explicit_grid_split_applies_to_scene_graphs(tmp_path):
    f = _write(tmp_path, "engine.glb", 1.0)
    nodes, _ = load_scene(SceneSpec(model=str(f), cluster=0), use_cache=False)
    grid, _ = load_scene(SceneSpec(model=str(f), split="grid:2", cluster=0), use_cache=False)
    assert nodes.n_objects == 24 and nodes.meta["objects"]["split"] == "nodes"
    assert grid.meta["objects"]["split"] == "grid:2" and 1 <= grid.n_objects <= 8
    assert grid.n_triangles == nodes.n_triangles


@pytest.mark.parametrize("encoding", ["ascii", "binary_little_endian"])
def test_truncated_ply_is_refused(tmp_path, encoding):
    m = statue(1.0)
    full = tmp_path / "full.ply"
    full.write_bytes(trimesh.exchange.ply.export_ply(m, encoding=encoding.split("_")[0]))
    data = full.read_bytes()
    cut = tmp_path / "cut.ply"
    cut.write_bytes(data[:int(len(data) * 0.6)])
    load_scene(SceneSpec(model=str(full)), use_cache=False)  # the whole file loads
    with pytest.raises(InputError, match=r"cut.ply: .*the header promises \d+ vertices and \d+ faces"):
        load_scene(SceneSpec(model=str(cut)), use_cache=False)


def test_truncated_binary_stl_is_refused(tmp_path):
    full = tmp_path / "full.stl"
    full.write_bytes(trimesh.exchange.stl.export_stl(statue(1.0)))
    cut = tmp_path / "cut.stl"
    cut.write_bytes(full.read_bytes()[:5000])
    with pytest.raises(InputError, match=r"cut.stl: not a complete binary STL: its header promises 5120 triangles"):
        load_scene(SceneSpec(model=str(cut)), use_cache=False)


def test_imbalance_leaves_out_frames_that_drew_nothing():
    rows = np.zeros((3 * 2, len(COLUMNS)))
    col = {c: i for i, c in enumerate(COLUMNS)}
    rows[:, col["frame"]] = np.repeat([0, 1, 2], 2)
    rows[:, col["rank"]] = np.tile([0, 1], 3)
    rows[:, col["triangles"]] = [10, 10, 0, 0, 30, 10]  # frame 1 drew nothing
    rows[:, col["rendering_cpu_ms"]] = [1, 1, 0.1, 0.1, 3, 1]
    rows[:, col["frame_ms"]] = 5.0
    s = summarize(rows, 2)
    assert s["empty_frames"] == 1
    assert s["imbalance_triangles"] == pytest.approx((1.0 + 1.5) / 2)
    assert s["imbalance_triangles"] >= 1.0 and s["imbalance_render_cpu"] >= 1.0


def test_balancing_share_is_the_mean_ranks_balancing_and_cull_over_the_emulated_frame():
    rows = np.zeros((2 * 2, len(COLUMNS)))
    col = {c: i for i, c in enumerate(COLUMNS)}
    rows[:, col["frame"]] = np.repeat([0, 1], 2)
    rows[:, col["rank"]] = np.tile([0, 1], 2)
    rows[:, col["triangles"]] = 10
    rows[:, col["load_balancing_cpu_ms"]] = [0.2, 0.4, 0.2, 0.4]  # mean 0.3
    rows[:, col["culling_cpu_ms"]] = 0.1
    rows[:, col["rendering_cpu_ms"]] = [5.0, 7.6, 9.0, 2.0]  # slowest rank's CPU: 8.0 and 9.2 ms
    rows[:, col["frame_ms"]] = 10.0
    s = summarize(rows, 2)
    assert s["emulated_frame_ms"] == pytest.approx(8.6)
    assert s["balancing_share"] == pytest.approx(0.4 / 8.6)
    assert "balancing and culling 4.7 % of it" in table(s)


def test_the_shipped_pump_model():
    scene, _ = load_scene(SceneSpec(model=str(PUMP), ranks=4), use_cache=False)
    assert axis_name(scene.meta["up"]) == "+y" and scene.meta["objects"]["split"] == "nodes"
    assert scene.meta["objects"]["modelled"] == 53 and scene.n_objects > 53  # the casing is cut for 4 ranks
    assert (visible_share(scene, walkthrough(scene, frames=120)) > 0).all()


def test_big_walls_cut_big_objects_small_walls_keep_them():
    from multigpu.scene.cluster import auto_cluster

    tris = np.r_[np.full(2000, 30), np.full(20, 2000)]  # balanced: largest 0.04 % ... 2 %
    assert auto_cluster(tris, 4)[0] == 0
    size, why = auto_cluster(tris, 16)
    assert size == max(64, -(-int(tris.sum()) // (64 * 16))) and "16-rank wall" in why


def test_scan_is_one_closed_surface_cut_into_about_a_hundred_parts(tmp_path, capsys):
    """`multigpu scene scan`: the scanned-style model of the payoff study (issue 24): one
    watertight, outward-wound mesh of even triangles (+Y up, as PLY scans are), which
    `--split grid:8` cuts into ~100 parts that a 2x2 wall keeps as modelled."""
    from multigpu.scene.scan import scan_mesh

    verts, faces = scan_mesh(30_000, seed=3)
    mesh = trimesh.Trimesh(verts, faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0  # closed, wound outward
    assert abs(len(faces) - 30_000) / 30_000 < 0.05
    assert mesh.area_faces.max() / mesh.area_faces.min() < 8  # even triangles, as a scanner's
    path = tmp_path / "scan.ply"
    assert cli(["scene", "scan", str(path), "--triangles", "30000", "--seed", "3"]) == 0
    scene, _ = load_scene(SceneSpec(model=str(path), split="grid:8"), use_cache=False)
    assert scene.n_triangles == len(faces) and axis_name(scene.meta["up"]) == "+y"
    assert 60 <= scene.n_objects <= 200
    assert scene.tris.max() / scene.n_triangles < 0.05  # few large objects, none dominant


@pytest.mark.parametrize("argv, needle", [(["x.obj"], "*.ply"), (["missing/x.ply"], "does not exist"),
                                          (["x.ply", "--triangles", "3"], "--triangles")])
def test_scan_flags_are_refused_in_one_line(tmp_path, capsys, argv, needle):
    argv = [str(tmp_path / argv[0]), *argv[1:]]
    assert cli(["scene", "scan", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
    assert not list(tmp_path.iterdir())  # nothing written
