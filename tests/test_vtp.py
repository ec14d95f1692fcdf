"""VTK XML PolyData (``.vtp``), which meshio does not read: files ParaView wrote in each of its
encodings read alike (points, polygons, fields), lines left out and said, a step series of them,
and a file that is no PolyData, or cut short, refused in one line naming it."""

from pathlib import Path

import numpy as np
import pytest

from multigpu.errors import InputError
from multigpu.scene.simulation import load, read

DATA = Path(__file__).resolve().parent / "data" / "vtp"


def test_every_encoding_paraview_writes_reads_the_same_surface():
    meshes = {name: read(DATA / f"small_{name}.vtp") for name in ("default", "binary", "ascii")}
    want = meshes["binary"]
    assert want.points.shape == (34, 3) and [(c.type, len(c.data)) for c in want.cells] == [("polygon", 64)]
    for name, m in meshes.items():
        assert np.allclose(m.points, want.points, atol=1e-6), name
        assert np.array_equal(m.cells[0].data, want.cells[0].data), name
        assert np.allclose(m.point_data["Elevation"], want.point_data["Elevation"], atol=1e-6), name
    surface, meta = load(DATA / "small_default.vtp", "Elevation")
    assert len(surface.faces) == 64 and meta["color_by"]["where"] == "point" and not meta["warnings"]
    assert {f["name"] for f in meta["fields"]} >= {"Elevation", "Normals"}


def test_lines_are_left_out_and_said():
    surface, meta = load(DATA / "mixed.vtp")
    assert len(surface.faces) == 64 and meta["warnings"] == ["1 lines left out (not surfaces)"]


def test_a_series_of_vtp_steps_plays(tmp_path, monkeypatch):
    from multigpu.scene.models import SceneSpec, load_scene

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path / "cache"))
    for k, name in enumerate(("default", "binary")):
        (tmp_path / f"step_{k}.vtp").write_bytes((DATA / f"small_{name}.vtp").read_bytes())
    scene, _ = load_scene(SceneSpec(model=str(tmp_path / "step_*.vtp"), color_by="Elevation", step=1))
    assert scene.meta["series"]["steps"] == 2 and scene.tris.sum() == 64


@pytest.mark.parametrize("content,says", [
    (b'<?xml version="1.0"?><VTKFile type="UnstructuredGrid"><UnstructuredGrid/></VTKFile>',
     "not a VTK XML PolyData file"),
    (None, "cannot read as VTP"),
])
def test_a_file_that_is_no_polydata_or_cut_short_is_one_line(tmp_path, content, says):
    bad = tmp_path / "bad.vtp"
    bad.write_bytes(content if content is not None else (DATA / "small_ascii.vtp").read_bytes()[:3000])
    with pytest.raises(InputError) as got:
        read(bad)
    assert says in str(got.value) and "bad.vtp" in str(got.value) and "\n" not in str(got.value), str(got.value)
