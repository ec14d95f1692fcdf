"""A simulation's time series in one process: its steps found (a glob in natural order, ParaView's
.pvd), the step a scene time shows, the colour range over every step, each step loaded as its own
cached scene, a later step that cannot be read, and the reader that loads ahead."""

import json
import time

import meshio
import numpy as np
import pytest

from multigpu.errors import InputError
from multigpu.scene.series import after, find_series, is_series, on_the_way, series_range, step_at

N = 12  # grid points a side


def surface(k: int, drop: bool = False) -> meshio.Mesh:
    """Step ``k`` of a deforming surface: a quad grid whose height is a travelling wave, coloured by
    its height (a point field) and its cells' index (a cell field); ``drop``: a third of the cells
    gone (the topology changes)."""
    x, y = np.meshgrid(np.linspace(0, 1, N), np.linspace(0, 1, N))
    z = 0.2 * np.sin(2 * np.pi * (x + 0.25 * k)) * (1 + 0.5 * k)
    idx = np.arange(N * N).reshape(N, N)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    if drop:
        quads = quads[: 2 * len(quads) // 3]
    return meshio.Mesh(np.c_[x.ravel(), y.ravel(), z.ravel()], [("quad", quads)],
                       point_data={"height": z.ravel()}, cell_data={"cell": [np.arange(len(quads), dtype=float)]})


def write_series(where, n: int = 4, drop: int | None = None, pvd: bool = True):
    """``n`` steps as ``step_K.vtu`` (step ``drop`` with fewer cells) and a ``run.pvd`` listing them
    at times 0.5 apart."""
    where.mkdir(parents=True, exist_ok=True)
    for k in range(n):
        meshio.write(where / f"step_{k}.vtu", surface(k, drop == k))
    if pvd:
        sets = "".join(f'<DataSet timestep="{0.5 * k}" part="0" file="step_{k}.vtu"/>' for k in range(n))
        (where / "run.pvd").write_text(f'<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">'
                                       f'<Collection>{sets}</Collection></VTKFile>\n')
    return where


def test_a_glob_names_its_steps_in_natural_order(tmp_path):
    for k in (0, 2, 9, 10, 11):
        meshio.write(tmp_path / f"s_{k}.vtu", surface(0))
    got = find_series(str(tmp_path / "s_*.vtu"))
    assert [p.name for p in got.paths] == ["s_0.vtu", "s_2.vtu", "s_9.vtu", "s_10.vtu", "s_11.vtu"]
    assert got.times == (0.0, 1.0, 2.0, 3.0, 4.0) and got.name == "s_*.vtu"
    assert is_series(str(tmp_path / "s_*.vtu")) and is_series("run.PVD") and not is_series("one.vtu")


def test_a_pvd_keeps_its_timesteps_and_says_what_it_leaves_out(tmp_path):
    write_series(tmp_path, 3, pvd=False)
    (tmp_path / "run.pvd").write_text(
        '<VTKFile type="Collection"><Collection>'
        '<DataSet timestep="2.5" file="step_2.vtu"/><DataSet timestep="0" file="step_0.vtu"/>'
        '<DataSet timestep="1.25" part="0" file="step_1.vtu"/><DataSet timestep="1.25" part="1" file="step_2.vtu"/>'
        '</Collection></VTKFile>')
    got = find_series(str(tmp_path / "run.pvd"))
    assert [p.name for p in got.paths] == ["step_0.vtu", "step_1.vtu", "step_2.vtu"]
    assert got.times == (0.0, 1.25, 2.5) and got.name == "run"
    assert got.warnings == ("1 further parts of steps not drawn (the first DataSet of each timestep is)",)


@pytest.mark.parametrize(("text", "says"), [
    ("<VTKFile><Collection></Collection></VTKFile>", "no VTKFile/Collection/DataSet entries"),
    ("<VTKFile><Collection><DataSet timestep='x' file='a.vtu'/></Collection></VTKFile>", "timestep is not a number"),
    ("<VTKFile><Collection><DataSet timestep='nan' file='a.vtu'/></Collection></VTKFile>", "non-finite timestep"),
    ("<VTKFile><Collection", "not a readable ParaView collection")])
def test_a_bad_pvd_is_one_line(tmp_path, text, says):
    (tmp_path / "bad.pvd").write_text(text)
    with pytest.raises(InputError) as got:
        find_series(str(tmp_path / "bad.pvd"))
    assert says in str(got.value) and "bad.pvd" in str(got.value) and "\n" not in str(got.value)


def test_a_glob_that_matches_nothing_or_a_missing_pvd_is_one_line(tmp_path):
    with pytest.raises(InputError, match="no file matches this series pattern"):
        find_series(str(tmp_path / "none_*.vtu"))
    with pytest.raises(InputError, match="no such file"):
        find_series(str(tmp_path / "gone.pvd"))


def test_the_step_a_scene_time_shows():
    assert [step_at(t, 2.0, 3, "loop") for t in (0, 0.49, 0.5, 1.0, 1.5, 2.9)] == [0, 0, 1, 2, 0, 2]
    assert [step_at(t, 2.0, 3, "hold") for t in (-1, 0, 1.0, 1.5, 99)] == [0, 0, 2, 2, 2]
    assert step_at(1 / 3, 3.0, 5) == 1  # a frame on a step's boundary shows that step, not the one before
    assert after(1, 3) == 2 and after(2, 3, "loop") == 0 and after(2, 3, "hold") is None and after(0, 1) is None


def test_a_step_is_on_the_way_when_it_lies_between_the_shown_and_the_wanted():
    assert on_the_way(0, 2, 3, 5) and on_the_way(0, 3, 3, 5) and not on_the_way(0, 4, 3, 5)
    assert on_the_way(4, 0, 1, 5, "loop") and not on_the_way(4, 2, 1, 5, "loop")  # round the loop
    assert on_the_way(3, 1, 0, 5, "hold") and not on_the_way(3, 3, 0, 5, "hold")  # scrubbed back
    assert not on_the_way(2, 2, 2, 5)


def test_the_colour_range_spans_every_step_and_is_kept(tmp_path):
    series = find_series(str(write_series(tmp_path / "s") / "step_*.vtu"))
    heights = np.concatenate([surface(k).point_data["height"] for k in range(4)])
    lo, hi, left_out = series_range(series, "height", tmp_path / "cache")
    assert (lo, hi) == (heights.min(), heights.max()) and hi > surface(0).point_data["height"].max()
    assert left_out == []
    kept = list((tmp_path / "cache").glob("series-range-*.json"))
    assert len(kept) == 1 and json.loads(kept[0].read_text())["range"] == [lo, hi]
    kept[0].write_text(json.dumps({"range": [-7.0, 7.0]}))  # read back, not recomputed
    assert series_range(series, "height", tmp_path / "cache") == (-7.0, 7.0, [])


def test_a_later_step_without_the_field_is_left_out_of_the_range_and_the_first_is_one_line(tmp_path):
    write_series(tmp_path, 3, pvd=False)
    mesh = surface(2)
    mesh.point_data = {"other": mesh.point_data["height"]}
    meshio.write(tmp_path / "step_2.vtu", mesh)
    series = find_series(str(tmp_path / "step_*.vtu"))
    lo, hi, left_out = series_range(series, "height")
    both = np.concatenate([surface(k).point_data["height"] for k in (0, 1)])
    assert (lo, hi) == (both.min(), both.max())
    assert len(left_out) == 1 and left_out[0].startswith("step 2 of the series: ") and "no field 'height'" in \
        left_out[0] and left_out[0].endswith("(left out of the colour range)")
    meshio.write(tmp_path / "step_0.vtu", mesh)
    with pytest.raises(InputError) as got:
        series_range(series, "height")
    assert str(got.value).startswith("--color-by step 0 of the series: ") and "no field 'height'" in str(got.value)


def test_each_step_loads_as_the_scene_of_its_own_file_coloured_over_the_series(tmp_path, monkeypatch):
    """Step 0 and the step with other cells (2) are their files' scenes; the steps with step 0's cells
    (1, 3) are step 0's layout (its triangles, objects, parts) with their own points, colours, bounds
    and normals (those of their points that no sharp edge splits: as their own build's)."""
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.simulation import colours, lookup

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path / "cache"))
    write_series(tmp_path / "s", 4, drop=2)
    spec = SceneSpec(model=str(tmp_path / "s" / "run.pvd"), color_by="height")
    lo, hi, _ = series_range(find_series(spec.model), "height")
    first, _ = load_scene(SceneSpec(model=spec.model, color_by="height", step=0))
    for k in range(4):
        step, _ = load_scene(SceneSpec(model=spec.model, color_by="height", step=k))
        alone, _ = load_scene(SceneSpec(model=str(tmp_path / "s" / f"step_{k}.vtu"), color_by="height",
                                        color_range=(lo, hi)))
        assert step.meta["series"]["step"] == k and step.meta["series"]["time"] == 0.5 * k
        assert step.meta["series"]["steps"] == 4 and step.name == "run"
        if k in (0, 2):
            assert np.array_equal(step.vertices, alone.vertices) and np.array_equal(step.indices, alone.indices)
            assert np.array_equal(step.vertex_colors, alone.vertex_colors)
            continue
        assert np.array_equal(step.indices, first.indices) and np.array_equal(step.part_count, first.part_count)
        assert np.array_equal(step.sources, first.sources)
        mesh = surface(k)
        point = step.sources[:, 0]
        assert np.allclose(step.world_positions(), mesh.points[point], atol=1e-6)
        assert np.array_equal(step.vertex_colors, colours(mesh.point_data["height"][point], lookup("viridis"), lo, hi))
        assert np.array_equal(step.origin, alone.origin) and np.allclose(step.bounds, alone.bounds, atol=1e-7)
        assert (step.part_bmin <= step.part_bmax).all() and np.isclose(step.part_bmin.min(axis=0), alone.bmin.min(
            axis=0)).all()
        once = lambda s: {p for p, n in zip(*np.unique(s.sources[:, 0], return_counts=True)) if n == 1}
        smooth = np.array(sorted(once(step) & once(alone)))

        def at(scene):  # the normals of the vertices of points ``smooth``
            order = np.argsort(scene.sources[:, 0], kind="stable")
            return scene.vertices[order[np.searchsorted(scene.sources[order, 0], smooth)], 3:]

        assert len(smooth) > 50 and np.allclose(at(step), at(alone), atol=1e-6)
    assert [p.name.split("-")[0] for p in (tmp_path / "cache").glob("*.alone")] == ["step_2"]  # built alone
    two, _ = load_scene(SceneSpec(model=spec.model, step=2))
    assert two.tris.sum() < step.tris.sum()  # the step with fewer cells has fewer triangles
    with pytest.raises(InputError, match="no step 4 .the series has 4."):
        load_scene(SceneSpec(model=spec.model, step=4))


def test_the_reader_loads_what_is_asked_and_names_a_step_it_cannot_read(tmp_path, monkeypatch):
    from multigpu.rank.series import Reader
    from multigpu.scene.models import SceneSpec

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path / "cache"))
    write_series(tmp_path / "s", 3)
    (tmp_path / "s" / "step_1.vtu").write_bytes(b"<VTKFile>cut short")
    said = []
    reader = Reader(SceneSpec(model=str(tmp_path / "s" / "step_*.vtu"), color_by="height"), 3,
                    lambda k, why: said.append((k, why)))
    try:
        for k in (2, 1, 0):
            reader.ask(k)
            t = time.monotonic()
            while reader.newest != k and k not in reader.bad and time.monotonic() - t < 60:
                time.sleep(0.01)
        assert reader.newest == 0 and sorted(reader.loaded) == [0, 2] and list(reader.bad) == [1]
        assert len(said) == 1 and said[0][0] == 1 and "step_1.vtu" in said[0][1]
        scene, shared, (draws, maps) = reader.take(2)
        assert scene.meta["series"]["step"] == 2 and shared is not None and shared.is_file()
        assert draws.total >= 3 * scene.n_triangles and sorted(maps) == ["colors", "indices", "objects", "vertices"]
        reader.keep(set())  # the newest stays: a row may say it
        assert list(reader.loaded) == [0]
        reader.ask(2)  # asked again once let go: loaded again
        t = time.monotonic()
        while reader.newest != 2 and time.monotonic() - t < 60:
            time.sleep(0.01)
        assert reader.newest == 2
    finally:
        reader.close()


def test_scene_info_names_the_steps_and_the_series_range(tmp_path, capsys, monkeypatch):
    from multigpu.cli import main as cli

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path / "cache"))
    write_series(tmp_path / "s", 3)
    heights = np.concatenate([surface(k).point_data["height"] for k in range(3)])
    assert cli(["scene", "info", str(tmp_path / "s" / "run.pvd"), "--color-by", "height"]) == 0
    out = capsys.readouterr().out
    assert f"series     3 steps (pvd {tmp_path / 's' / 'run.pvd'}), times 0 .. 1; step 0 below (step_0.vtu .. " \
           "step_2.vtu)" in out
    assert f"colour by  height (per point), viridis over {heights.min():.6g} .. {heights.max():.6g}" in out


def test_a_negative_first_number_is_a_flag_value_not_a_flag():
    from multigpu.flags import joined_negatives

    got = joined_negatives(["walkthrough", "--range", "-1,1", "--offset", "-5,0,0", "--anim-speed", "-2", "-h"])
    assert got == ["walkthrough", "--range=-1,1", "--offset=-5,0,0", "--anim-speed", "-2", "-h"]


def test_an_xdmf_time_series_plays_its_steps_at_their_times(tmp_path, monkeypatch):
    """One ``.xdmf`` file (its data in HDF5) whose grid is a temporal collection, as meshio's
    TimeSeriesWriter (and FEniCS, ParaView) write it: a series of its steps at their own times, each
    step the scene of that step's data alone; unpacked once (a second look reads the cache)."""
    from multigpu.scene.models import SceneSpec, load_scene

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)  # meshio's writer puts the HDF5 file in the working directory
    steps = [surface(k) for k in range(3)]
    with meshio.xdmf.TimeSeriesWriter(str(tmp_path / "run.xdmf")) as w:
        w.write_points_cells(steps[0].points, steps[0].cells)
        for k, m in enumerate(steps):  # the same grid, each step's heights as a field
            w.write_data(0.25 * k, point_data={"height": m.point_data["height"]})
    meshio.write(tmp_path / "plain.xdmf", steps[0])  # one mesh, no time: not a series
    assert is_series(str(tmp_path / "run.xdmf")) and not is_series(str(tmp_path / "plain.xdmf"))
    got = find_series(str(tmp_path / "run.xdmf"))
    assert len(got) == 3 and got.times == (0.0, 0.25, 0.5) and got.name == "run"
    made = [p.stat().st_mtime_ns for p in got.paths]
    assert [p.stat().st_mtime_ns for p in find_series(str(tmp_path / "run.xdmf")).paths] == made  # the cache's
    lo, hi, _ = series_range(got, "height")
    assert lo == pytest.approx(min(m.point_data["height"].min() for m in steps))
    for k in range(3):
        step, _ = load_scene(SceneSpec(model=str(tmp_path / "run.xdmf"), color_by="height", step=k))
        meshio.write(tmp_path / f"alone_{k}.vtu", meshio.Mesh(steps[0].points, steps[0].cells,
                                                              point_data={"height": steps[k].point_data["height"]}))
        alone, _ = load_scene(SceneSpec(model=str(tmp_path / f"alone_{k}.vtu"), color_by="height",
                                        color_range=(lo, hi)))
        assert step.meta["series"]["time"] == 0.25 * k
        assert np.array_equal(step.vertex_colors, alone.vertex_colors)
    (tmp_path / "broken.xdmf").write_text((tmp_path / "run.xdmf").read_text().replace("run.h5", "gone.h5"))
    with pytest.raises(InputError, match="broken.xdmf: not a readable XDMF time series") as err:
        find_series(str(tmp_path / "broken.xdmf"))
    assert "\n" not in str(err.value)


def test_a_step_coloured_by_a_cell_field_takes_each_vertexs_cell(tmp_path, monkeypatch):
    """Coloured by a cell field (each triangle's vertices its own): a step with the first step's
    cells colours each vertex by its cell's value of this step, as its own build does."""
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.simulation import colours, lookup

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path / "cache"))
    where = write_series(tmp_path / "s", 2)
    mesh = surface(1)
    mesh.cell_data["cell"] = [np.arange(len(mesh.cells[0].data), dtype=float)[::-1].copy()]  # other values
    meshio.write(where / "step_1.vtu", mesh)
    step, _ = load_scene(SceneSpec(model=str(where / "run.pvd"), color_by="cell", color_range=(0.0, 150.0), step=1))
    alone, _ = load_scene(SceneSpec(model=str(where / "step_1.vtu"), color_by="cell", color_range=(0.0, 150.0)))
    first, _ = load_scene(SceneSpec(model=str(where / "run.pvd"), color_by="cell", color_range=(0.0, 150.0), step=0))
    assert np.array_equal(step.indices, first.indices) and (step.sources[:, 1] >= 0).all()
    assert not list((tmp_path / "cache").glob("*.alone"))  # made from the first step, not built alone
    want = colours(mesh.cell_data["cell"][0][step.sources[:, 1]], lookup("viridis"), 0.0, 150.0)
    assert np.array_equal(step.vertex_colors, want) and np.array_equal(step.vertex_colors, alone.vertex_colors)
    assert not np.array_equal(step.vertex_colors, first.vertex_colors)
