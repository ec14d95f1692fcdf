"""``bench peer`` and ``bench timeline``'s plot, in one process where they can be: a missing
ParaView is one clear line; beside ParaView (where it is installed) a short run gives both
sides' figures; a timeline plots to a PNG."""

import json
import shutil

import pytest

from multigpu.errors import InputError


def test_no_paraview_is_one_clear_line(monkeypatch):
    from multigpu.studies import peer

    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(InputError) as e:
        peer.bench_peer("models/pump.glb")
    assert "pvbatch is not installed" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.mpi
def test_beside_paraview_both_sides_measure_the_same_cameras(tmp_path):
    from multigpu.launcher.mpirun import openmpi_on_path
    from multigpu.studies.peer import bench_peer

    if shutil.which("pvbatch") is None or openmpi_on_path() is None or shutil.which("Xvfb") is None:
        pytest.skip("ParaView's pvbatch, Open MPI and Xvfb are needed (Debian: apt install paraview "
                    "python3-paraview openmpi-bin xvfb)")
    rows = bench_peer("models/pump.glb", "auto", (1,), frames=4, size=(128, 96), rounds=1, out=str(tmp_path))
    (row,) = rows
    for side in ("paraview", "multigpu"):
        assert row[side]["wall_ms"] > 0 and row[side]["cpu_ms"] > 0
    assert row["wall_lead"] == pytest.approx(row["paraview"]["wall_ms"] / row["multigpu"]["wall_ms"])
    assert len(json.loads((tmp_path / "cameras.json").read_text())["cameras"]) == 4
    assert json.loads((tmp_path / "peer.json").read_text())["rows"] == rows


def test_a_timeline_plots_every_rank(tmp_path):
    from multigpu.studies.timeline import plot

    doc = {"latency": 1, "ranks": [[{"frame": f, "phases": [["plan", 10.0 * f + r, 10.0 * f + r + 1],
                                                            ["render", 10.0 * f + r + 1, 10.0 * f + r + 6],
                                                            ["display", 10.0 * f + r + 7, 10.0 * f + r + 8]]}
                                    for f in range(3)] for r in range(4)]}
    (tmp_path / "t.json").write_text(json.dumps(doc))
    png = plot({"a run": tmp_path / "t.json"}, tmp_path / "t.png")
    assert png.stat().st_size > 1000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
