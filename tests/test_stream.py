"""A running simulation's steps through ADIOS2, in one process: a step's variables as a mesh (every
refusal one line naming the step and the variable), and the reader that keeps each step as the next
file of a series, from a BP5 file written here by the example simulation's code (skipped, naming why,
only where the adios2 wheel cannot be imported)."""

import sys
import time
from pathlib import Path

import numpy as np
import pytest

from multigpu.errors import InputError
from multigpu.scene.stream_mesh import step_mesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples" / "simulation"))


def values(n: int = 4) -> dict:
    """One step of the example's plate: points, quads, a point and a cell field, the time."""
    from heat import plate

    xy, quads = plate(n)
    points = np.c_[xy[0].ravel(), xy[1].ravel(), np.zeros(n * n)]
    return {"points": points, "quad": quads, "temperature": np.linspace(0, 1, n * n),
            "source": np.arange(len(quads), dtype=float), "time": np.array([2.5])}


def test_a_step_is_a_mesh_with_its_fields_and_time():
    mesh, t, notes = step_mesh(values(), 3, "adios2:heat")
    assert t == 2.5 and notes == []
    assert mesh.points.shape == (16, 3) and mesh.cells[0].type == "quad" and len(mesh.cells[0].data) == 9
    assert list(mesh.point_data) == ["temperature"] and list(mesh.cell_data) == ["source"]


def test_a_variable_that_fits_nothing_is_named_and_left_out():
    v = {**values(), "stray": np.zeros(5), "table": np.zeros((2, 2, 2))}
    mesh, _, notes = step_mesh(v, 3, "adios2:heat")
    assert "stray" not in mesh.point_data and "stray" not in mesh.cell_data and len(notes) == 2
    assert notes[0] == ("adios2:heat: step 3: variable 'stray' of 5 rows fits neither the 16 points nor the 9 "
                        "cells: left out")
    assert "variable 'table'" in notes[1] and "is no field" in notes[1]


@pytest.mark.parametrize(("change", "says"), [
    (lambda v: v.pop("points"), "no 'points' variable (the step has: quad, source, temperature, time)"),
    (lambda v: v.pop("quad"), "no cell variable (triangle, quad, tetra, hexahedron, wedge, pyramid; the step has:"),
    (lambda v: v.update(points=np.zeros((16, 4))), "'points' must be (P, 3) or (P, 2) numbers, got shape (16, 4)"),
    (lambda v: v.update(quad=v["quad"].astype(float)), "'quad' must be (n, 4) integer point indices"),
    (lambda v: v.update(quad=v["quad"] + 10), "'quad' uses point 25, but the step has 16 points"),
    (lambda v: v.update(triangle=np.array([[0, 1, -1]])), "'triangle' uses point -1"),
])
def test_a_step_the_wall_cannot_use_is_one_line(change, says):
    v = values()
    change(v)
    with pytest.raises(InputError) as got:
        step_mesh(v, 7, "adios2:heat")
    text = str(got.value)
    assert text.startswith("--model adios2:heat: step 7: ") and says in text and "\n" not in text


def adios2_or_skip():
    try:
        import adios2  # noqa: F401
    except ImportError as exc:
        pytest.skip(f"the adios2 wheel cannot be imported here ({exc})")


def test_the_reader_keeps_each_step_of_a_bp5_file_as_a_series_file(tmp_path):
    adios2_or_skip()
    import heat
    import meshio

    from multigpu.rank.spool import Spool
    from multigpu.scene.series import find_series

    heat.main(["--file", str(tmp_path / "run.bp"), "--steps", "5", "--size", "12", "--every", "0"])
    said = []
    spool = Spool(f"adios2:{tmp_path / 'run.bp'}", tmp_path / "steps", 20.0, say=lambda *a, **k: said.append(a[0]))
    spool.first()
    t = time.monotonic()
    while not spool.ended and time.monotonic() - t < 30:
        time.sleep(0.02)
    assert spool.ended and spool.count == 5 and spool.error is None and said == []
    series = find_series(str(tmp_path / "steps" / "step_*.vtu"))
    assert [p.name for p in series.paths] == [f"step_{k:06d}.vtu" for k in range(5)]
    last = meshio.read(series.paths[-1])
    assert last.points.shape == (144, 3) and sorted(last.point_data) == ["temperature"]
    assert last.points[:, 2].max() > 0  # the plate warmed: its height is the temperature


def test_a_stream_that_cannot_be_opened_or_sends_nothing_is_one_line(tmp_path):
    adios2_or_skip()
    from multigpu.rank.spool import Spool

    spool = Spool(f"adios2:{tmp_path / 'none.bp'}", tmp_path / "steps", 1.0, say=lambda *a, **k: None)
    with pytest.raises(InputError) as got:
        spool.first()
    assert str(got.value).startswith(f"--model adios2:{tmp_path / 'none.bp'}: ") and "\n" not in str(got.value)
