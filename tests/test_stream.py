"""A running simulation's steps through ADIOS2, in one process: a step's variables as a mesh (every
refusal one line naming the step and the variable), and the reader that keeps each step as the next
file of a series, from a BP5 file written here by the example simulation's code (skipped, naming why,
only where the adios2 wheel cannot be imported)."""

import contextlib
import os
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
    time.sleep(0.3)
    assert spool.count == 1  # the steps after the first wait for the frame loop
    made, sent = [], -1
    spool.attach(lambda k, mesh, path, write: bytearray(f"{k} {len(mesh.points)} {path.name}".encode()))
    t = time.monotonic()
    while not (spool.ended and sent == 4) and time.monotonic() - t < 30:
        got = spool.next_made(sent)  # a file's steps: each in turn, none passed over
        if got is not None:
            sent = got[0]
            made.append(got[1].decode())
        time.sleep(0.02)
    assert spool.ended and spool.count == 5 and spool.error is None and said == []
    assert made == [f"{k} 144 step_{k:06d}.vtu" for k in range(1, 5)]
    series = find_series(str(tmp_path / "steps" / "step_*.vtu"))
    assert [p.name for p in series.paths] == [f"step_{k:06d}.vtu" for k in range(5)]
    last = meshio.read(series.paths[-1])
    assert last.points.shape == (144, 3) and sorted(last.point_data) == ["temperature"]
    assert last.points[:, 2].max() > 0  # the plate warmed: its height is the temperature


@contextlib.contextmanager
def slow_live_spool(tmp_path, seconds: float):
    """The example simulation streaming live (SST, a step every 0.05 s), read by a spool whose
    making of each step takes ``seconds`` (no GIL held) and sets the event yielded beside it; the
    simulation ended by its process group after."""
    import signal
    import subprocess
    import threading

    from multigpu.rank.spool import Spool

    sim = subprocess.Popen([sys.executable, str(ROOT / "examples" / "simulation" / "heat.py"), "--name",
                            str(tmp_path / "heat"), "--steps", "400", "--size", "8", "--every", "0.05"],
                           cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        for _ in range(200):
            if (tmp_path / "heat.sst").exists() or sim.poll() is not None:
                break
            time.sleep(0.05)
        spool = Spool(f"adios2:{tmp_path / 'heat'}", tmp_path / "steps", 20.0, say=lambda *a, **k: None)
        spool.first()
        making = threading.Event()

        def make(k, mesh, path, write):
            making.set()
            time.sleep(seconds)
            return bytearray(str(k).encode())

        spool.attach(make)
        yield spool, making
        spool.close()
    finally:
        if sim.poll() is None:
            os.killpg(sim.pid, signal.SIGKILL)
        sim.communicate(timeout=30)


def test_rank_0_waits_for_a_live_step_being_made_only_as_long_as_it_says(tmp_path):
    """A live stream's step in the making: ``next_made`` without a wait says none yet; with one, it
    returns the step as soon as the keeper made it (the caller's GIL free meanwhile); a file's
    steps never hold the frame loop."""
    adios2_or_skip()
    with slow_live_spool(tmp_path, 0.4) as (spool, making):
        assert making.wait(20)
        assert spool.next_made(0) is None  # being made: not there yet, and no wait asked
        t = time.monotonic()
        got = spool.next_made(0, wait=5.0)
        waited = time.monotonic() - t
        assert got is not None and int(got[1].decode()) == got[0] >= 1 and waited < 1.0, (got, waited)
        spool.engine = "BP5"  # (a file's steps: the wait asked for is not taken)
        making.clear()
        assert making.wait(20)  # a step being made (0.4 s): those before it made
        after = got[0]
        while (done := spool.next_made(after)) is not None:
            after = done[0]
        t = time.monotonic()
        assert spool.next_made(after, wait=5.0) is None and time.monotonic() - t < 0.2


def test_a_live_steps_file_is_written_after_the_frames_that_show_it(tmp_path, monkeypatch):
    """A live step's file: not while the frame that sends it and the next are drawn, once two more
    frames asked (its writing kept out of the frame that shows it); a step sent just before the spool
    closes has its file when ``close`` returns."""
    adios2_or_skip()
    from multigpu.rank import spool as spool_module
    from multigpu.rank.spool import NAME

    monkeypatch.setattr(spool_module, "FILE_WAIT", 60.0)  # (only the frames asking write it here)
    with slow_live_spool(tmp_path, 0.5) as (spool, making):
        assert making.wait(20)
        k, _ = spool.next_made(0, wait=5.0)  # made while this frame asked: sent now
        file = tmp_path / "steps" / NAME.format(k)
        time.sleep(0.3)
        assert not file.exists()
        spool.next_made(k)  # the frame after it: drawn without its file's writing
        time.sleep(0.3)
        assert not file.exists()
        spool.next_made(k)
        t = time.monotonic()
        while not file.exists() and time.monotonic() - t < 20:
            time.sleep(0.02)
        assert file.exists()
        making.clear()
        assert making.wait(20)
        last, _ = spool.next_made(k, wait=5.0)
        spool.close()
        assert (tmp_path / "steps" / NAME.format(last)).exists()


def test_a_stream_that_cannot_be_opened_or_sends_nothing_is_one_line(tmp_path):
    adios2_or_skip()
    from multigpu.rank.spool import Spool

    spool = Spool(f"adios2:{tmp_path / 'none.bp'}", tmp_path / "steps", 1.0, say=lambda *a, **k: None)
    with pytest.raises(InputError) as got:
        spool.first()
    assert str(got.value).startswith(f"--model adios2:{tmp_path / 'none.bp'}: ") and "\n" not in str(got.value)


# -- the door, fuzzed: whatever a stream's step holds, one line or a surface


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_any_step_is_a_surface_or_one_line(tmp_path_factory):
    """A step's variables of any names, kinds, shapes and values (NaN, infinities, negative or huge
    indices, empty arrays, complex numbers, fields of no column): ``step_mesh`` refuses it in one line naming the step,
    or gives a mesh that the wall's loader turns into a surface or refuses in one line (never
    another exception: the stream's reader says the line and the wall holds its last step)."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from hypothesis.extra import numpy as hnp

    from multigpu.scene.simulation import load
    from multigpu.scene.stream_mesh import step_mesh

    where = tmp_path_factory.mktemp("fuzz")
    names = st.sampled_from(["time", "temperature", "velocity", "v", "quad"])  # fields mostly; a cell kind
    kinds = st.sampled_from([np.float64, np.float32, np.int64, np.int32, np.uint8, np.bool_, np.complex64])
    arrays = kinds.flatmap(lambda k: hnp.arrays(k, hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=6)))
    floats = st.floats(allow_nan=True, allow_infinity=True, width=64)

    fuzz = int(os.environ.get("MULTIGPU_FUZZ", "200"))  # examples (more: MULTIGPU_FUZZ=2000)

    @settings(max_examples=fuzz, deadline=None, suppress_health_check=list(HealthCheck))
    @given(data=st.data(), extra=st.dictionaries(names, arrays, max_size=3))
    def check(data, extra):
        n = data.draw(st.integers(0, 8), "points")
        values = {"points": data.draw(hnp.arrays(np.float64, (n, data.draw(st.sampled_from([3, 2, 4]))),
                                                 elements=st.one_of(st.floats(-5, 5), floats)))}
        if data.draw(st.booleans()):  # a step's cells, mostly in range
            values["triangle"] = data.draw(hnp.arrays(np.int64, (data.draw(st.integers(0, 6)), 3),
                                                      elements=st.integers(-1, max(n, 1))))
        if data.draw(st.booleans()):  # a field of one value a point, of any kind
            values["temperature"] = data.draw(hnp.arrays(data.draw(kinds), (n,)))
        values.update(extra)
        try:
            mesh, _, notes = step_mesh(values, 3, "adios2:sim")
        except InputError as exc:
            assert "\n" not in str(exc) and "adios2:sim: step 3" in str(exc)
            return
        assert all("\n" not in n for n in notes)
        import meshio

        path = where / "step.vtu"
        meshio.write(path, mesh, binary=True)
        try:
            load(path, next(iter(mesh.point_data), None))
        except InputError as exc:  # what the door let through is read back (a field of no column was not)
            assert "\n" not in str(exc) and "cannot read as" not in str(exc), str(exc)

    check()
