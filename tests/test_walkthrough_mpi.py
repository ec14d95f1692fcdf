"""The parallel renderer under mpiexec (1 to 4 ranks, each run under a hard timeout)."""

import csv
import json

import numpy as np
import pytest
from mpirun import SMALL, read_png, run_mpi

from multigpu.records.report import COLUMNS

pytestmark = pytest.mark.mpi
W, H = 120, 96
FRAMES = 5
BG = np.array([20, 23, 31])


def walk(tmp_path, name, grid, extra=(), n=None):
    rows, cols = grid
    out = tmp_path / name
    args = ["walkthrough", *SMALL, "--frames", str(FRAMES), "--grid", f"{rows}x{cols}",
            "--tile", f"{W // cols}x{H // rows}", "--mosaic-every", "1", "--no-overlay", "--out", str(out), *extra]
    res = run_mpi(n or rows * cols, args)
    assert res.returncode == 0, res.stderr[-3000:]
    return out


def frames_of(out):
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(FRAMES)]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The one-rank render of the full display."""
    return frames_of(walk(tmp_path_factory.mktemp("ref"), "ref", (1, 1)))


@pytest.mark.parametrize("grid", [(1, 2), (2, 1), (1, 3), (2, 2)])
def test_composite_equals_one_rank_render(tmp_path, reference, grid):
    out = walk(tmp_path, "k", grid)
    for f, (got, ref) in enumerate(zip(frames_of(out), reference)):
        assert got.shape == (H, W, 3)
        assert (got == ref).all(), f"frame {f}: {(got != ref).any(axis=2).sum()} pixels differ"


def test_far_from_origin_and_offaxis_runs_match_the_reference(tmp_path, reference):
    """--offset 1e8 moves scene and path: the wall looks the same; offaxis stays within its bound."""
    far = walk(tmp_path, "far", (2, 2), ["--offset", "1e8,-1e8,1e6"])
    for f, (got, ref) in enumerate(zip(frames_of(far), reference)):
        assert (got != ref).any(axis=2).sum() <= 0.0005 * W * H, f"frame {f}"
    s = json.loads((far / "summary.json").read_text())
    assert s["config"]["offset"] == [1e8, -1e8, 1e6] and s["config"]["subfrustum"] == "scissor"
    off = walk(tmp_path, "offaxis", (1, 2), ["--subfrustum", "offaxis"])
    for f, (got, ref) in enumerate(zip(frames_of(off), reference)):
        assert (got != ref).any(axis=2).sum() <= 0.005 * W * H, f"frame {f}"
    assert json.loads((off / "summary.json").read_text())["config"]["subfrustum"] == "offaxis"


def test_broadcast_partition_equals_redundant(tmp_path, reference):
    """--partition broadcast (rank 0 plans, MPI_Bcast) gives the same regions, loads and images."""
    outs = {m: walk(tmp_path, m, (2, 2), ["--partition", m, "--balance", "strips"]) for m in ("redundant", "broadcast")}
    for got, ref in zip(frames_of(outs["broadcast"]), reference):
        assert (got == ref).all()
    cols = ("frame", "rank", "triangles", "x0", "y0", "x1", "y1", "objects")
    rows = {}
    for m, out in outs.items():
        with open(out / "timings.csv") as fh:
            rows[m] = sorted(tuple(r[c] for c in cols) for r in csv.DictReader(fh))
    assert rows["broadcast"] == rows["redundant"]
    assert json.loads((outs["broadcast"] / "summary.json").read_text())["config"]["partition"] == "broadcast"


@pytest.mark.parametrize("extra", [["--balance", "cross"], ["--decomposition", "db"]])
def test_shared_window_and_messages_compose_the_same(tmp_path, reference, extra):
    """One node: --exchange auto (the default) and shared go through a shared window,
    --exchange messages sends messages. All compose the one-rank render (colour pieces and
    depth-merged ones)."""
    for mode, used in (("auto", "shared"), ("shared", "shared"), ("messages", "messages")):
        out = walk(tmp_path, f"x_{mode}", (2, 2), ["--exchange", mode, *extra])
        for got, ref in zip(frames_of(out), reference):
            assert (got == ref).all()
        doc = json.loads((out / "summary.json").read_text())
        assert doc["config"]["exchange"] == used and "exchange_why" not in doc["config"]
        assert doc["bytes_sent_per_frame"] > 0


def test_broadcast_partition_carries_pieces(tmp_path, reference):
    """cross under --partition broadcast: rank 0's pieces reach every rank, and the
    wall still equals the one-rank render."""
    out = walk(tmp_path, "bcast_cross", (2, 2), ["--partition", "broadcast", "--balance", "cross"])
    for got, ref in zip(frames_of(out), reference):
        assert (got == ref).all()
    with open(out / "timings.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert all(float(r["pieces"]) >= 1 for r in rows if int(r["frame"]) > 0)
    assert json.loads((out / "summary.json").read_text())["decomposition"]["strategy"]["name"] == "cross"


def test_none_and_strips_give_same_images_and_schema(tmp_path, reference):
    out = walk(tmp_path, "none", (2, 2), ["--balance", "none"])
    for got, ref in zip(frames_of(out), reference):
        assert (got == ref).all()
    with open(out / "timings.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0].keys()) == COLUMNS
    assert len(rows) == FRAMES * 4
    assert {(int(r["frame"]), int(r["rank"])) for r in rows} == {(f, k) for f in range(FRAMES) for k in range(4)}
    for r in rows:  # no exchange without balancing: every region is its own tile
        assert int(r["bytes_sent"]) == 0
        assert (int(r["x1"]) - int(r["x0"]), int(r["y1"]) - int(r["y0"])) == (W // 2, H // 2)
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is True and s["frames"] == FRAMES and s["ranks"] == 4
    for key in ("load_balancing_ms", "rendering_ms", "synchronization_ms", "frame_exchange_ms", "display_ms"):
        # the summary's means are the CSV's (rounded to its 4 decimals), and the rendering took time
        assert s["wall"][key] == pytest.approx(np.mean([float(r[key]) for r in rows]), abs=1e-4)
    assert s["wall"]["rendering_ms"] > 0
    for r in rows:  # the balancing CPU is its four phases, each timed (learn, project, choose, plan)
        parts = [float(r[c]) for c in ("learning_cpu_ms", "projection_cpu_ms", "choosing_cpu_ms", "planning_cpu_ms")]
        assert min(parts) >= 0 and float(r["projection_cpu_ms"]) > 0 and float(r["planning_cpu_ms"]) > 0
        assert sum(parts) == pytest.approx(float(r["load_balancing_cpu_ms"]), abs=3e-4)  # 4 decimals each
    cpu = s["cpu"]
    phases = ("learning_cpu_ms", "projection_cpu_ms", "choosing_cpu_ms", "planning_cpu_ms")
    assert sum(cpu[c] for c in phases) == pytest.approx(cpu["load_balancing_cpu_ms"], rel=1e-3)
    per = {f: [r for r in rows if int(r["frame"]) == f] for f in range(FRAMES)}
    tris = [[int(r["triangles"]) for r in per[f]] for f in range(FRAMES)]
    drawn = [t for t in tris if sum(t) > 0]
    assert s["imbalance_triangles"] == pytest.approx(np.mean([max(t) / np.mean(t) for t in drawn]), rel=1e-9)
    assert s["fps"] == pytest.approx(1000 / np.mean([float(r["frame_ms"]) for r in rows]), rel=1e-3)


def test_strips_regions_tile_display_and_exchange_bytes(tmp_path):
    out = walk(tmp_path, "strips", (2, 2), ["--balance", "strips"])
    with open(out / "timings.csv") as fh:
        rows = list(csv.DictReader(fh))
    for f in range(FRAMES):
        cover = np.zeros((H, W), int)
        for r in rows:
            if int(r["frame"]) == f:
                cover[int(r["y0"]):int(r["y1"]), int(r["x0"]):int(r["x1"])] += 1
        assert (cover == 1).all()
    assert sum(int(r["bytes_sent"]) for r in rows) > 0


def test_rank_count_mismatch_is_a_clear_error(tmp_path):
    args = ["walkthrough", *SMALL, "--grid", "2x2", "--frames", "2", "--out", str(tmp_path / "x")]
    res = run_mpi(3, args, timeout=60)
    assert res.returncode != 0
    assert "--grid 2x2 needs 4 ranks but the job has 3" in res.stderr
    assert res.stderr.count("needs 4 ranks") == 1 and "Traceback" not in res.stderr


def test_empty_region_renders_background(tmp_path):
    # look at the plant from far away, low: the top row of tiles sees only sky
    path = tmp_path / "sky.json"
    path.write_text(json.dumps({"version": 1, "cameras": [
        {"position": [100, -900, 5], "target": [100, 60, 200], "fov": 30, "near": 1, "far": 3000}] * 3}))
    for balance in ("none", "strips"):
        out = tmp_path / balance
        res = run_mpi(4, ["walkthrough", *SMALL, "--path", str(path), "--grid", "2x2", "--tile", "60x48",
                          "--balance", balance, "--mosaic-every", "1", "--no-overlay", "--out", str(out)])
        assert res.returncode == 0, res.stderr[-2000:]
        with open(out / "timings.csv") as fh:
            rows = list(csv.DictReader(fh))
        if balance == "none":
            assert any(int(r["objects"]) == 0 for r in rows)
        img = read_png(out / "mosaic" / "frame_00000.png")
        assert (img[:20] == BG).all()


def test_shipped_model_composite_equals_one_rank(tmp_path):
    """models/pump.glb (glTF, +Y up, clustered for the wall) on 4 ranks equals 1 rank."""
    from mpirun import ROOT

    def run(n, grid, name):
        out = tmp_path / name
        res = run_mpi(n, ["walkthrough", "--model", str(ROOT / "models" / "pump.glb"), "--no-progress",
                          "--frames", "4", "--grid", grid, "--tile", f"{W // int(grid[2])}x{H // int(grid[0])}",
                          "--mosaic-every", "1", "--no-overlay", "--cluster", "256", "--out", str(out)])
        assert res.returncode == 0, res.stderr[-3000:]
        return out

    one, four = run(1, "1x1", "one"), run(4, "2x2", "four")
    for f in range(4):
        a, b = (read_png(o / "mosaic" / f"frame_{f:05d}.png") for o in (one, four))
        assert (a == b).all() and (a != BG).any(axis=2).mean() > 0.05, f"frame {f}"
    s = json.loads((four / "summary.json").read_text())
    assert s["config"]["scene"]["up"] == "+y" and s["config"]["scene"]["objects_from"]["split"] == "nodes"
    assert s["empty_frames"] == 0


def test_launch_script_runs_the_job(tmp_path):
    """launch/walkthrough as the README gives it (venv, MPI detection, rank count from --grid)."""
    import os
    import signal
    import subprocess

    from mpirun import ROOT

    out = tmp_path / "o"
    proc = subprocess.Popen([str(ROOT / "launch" / "walkthrough"), "--grid", "1x2", "--triangles", "20000",
                             "--frames", "3", "--no-progress", "--out", str(out)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout: {stdout[-2000:]}\nstderr: {stderr[-3000:]}"
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] and s["frames"] == 3 and s["ranks"] == 2


def test_noise_floor_bench_measures_identical_work_on_every_rank():
    """bench floor's MPI side: every rank renders the same work (any scene flags and generated
    path); the figures are sane."""
    from multigpu.studies.floor import run

    got = run(scenes={"two plants": ["--triangles", "20000", "--copies", "2", "--path-kind", "orbit"]}, ranks=2,
              frames=8, timeout=240)[0]
    assert got["scene"] == "two plants" and got["ranks"] == 2 and got["frames"] == 3
    assert got["render_ms_mean"] > 0
    assert 1.0 <= got["imbalance_floor"] < 2.0 and got["noise_cv"] >= 0.0
    assert (got["tile"], got["display"]) == (256, 512)
    small = run(scenes={"plant": ["--triangles", "20000"]}, ranks=2, frames=8, timeout=240, tile=32, display=128)[0]
    assert (small["tile"], small["display"]) == (32, 128) and small["render_ms_mean"] > 0
