"""A running simulation on the wall through ADIOS2: the example's heat plate streamed live (SST) and
recorded (a BP5 file the wall follows); every rank shows the same step at every frame, each frame
equals one rank's render of the step it shows (of its kept series), the kept steps are the series the
run leaves in its outputs, ``--at-end stop`` ends the run with the stream; a stream whose first step
the wall cannot use ends the job in one line (exit 2), a later one is said once. Every job, and the
simulation, runs under a hard timeout and is ended by process id (skipped, naming why, only where
the adios2 wheel cannot be imported)."""

import csv
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpirun import ROOT, read_png, run_mpi

pytestmark = pytest.mark.mpi
HEAT = ROOT / "examples" / "simulation" / "heat.py"
CAMERA = {"position": [0.5, -0.9, 1.1], "target": [0.5, 0.5, 0.05], "up": [0, 0, 1], "fov": 50.0, "near": 0.05,
          "far": 20.0}


@pytest.fixture(autouse=True)
def adios2_here():
    try:
        import adios2  # noqa: F401
    except ImportError as exc:
        pytest.skip(f"the adios2 wheel cannot be imported here ({exc})")


def still(where, frames: int):
    path = where / "still.json"
    path.write_text(json.dumps({"version": 1, "cameras": [CAMERA] * frames}))
    return path


def wall(out, model, path, grid=(1, 2), extra=(), timeout=180, **where):
    args = ["walkthrough", "--model", str(model), "--grid", f"{grid[0]}x{grid[1]}", "--tile", "48x64",
            "--mosaic-every", "1", "--no-overlay", "--no-progress", "--path", str(path), "--out", str(out),
            "--color-by", "temperature", "--range", "0,1", *extra]
    return run_mpi(grid[0] * grid[1], args, timeout=timeout, **where)


def shown(out) -> list[int]:
    """Each frame's step, checked the same on every rank."""
    by_frame: dict[int, set] = {}
    for r in csv.DictReader(open(out / "timings.csv")):
        by_frame.setdefault(int(r["frame"]), set()).add(int(r["step"]))
    assert all(len(s) == 1 for s in by_frame.values()), by_frame
    return [by_frame[f].pop() for f in sorted(by_frame)]


def check_frames(tmp_path, out, steps: list[int], path) -> None:
    """The first frame showing each step (three at most) equals one rank's render of that step of the
    kept series (a recording's step at its one frame)."""
    firsts = {k: steps.index(k) for k in dict.fromkeys(steps)}
    camera = json.loads(Path(path).read_text())["cameras"][0]
    for k in list(firsts)[-3:]:
        ref, at = tmp_path / f"ref{k}", tmp_path / f"at{k}.json"
        at.write_text(json.dumps({"version": 1, "cameras": [{**camera, "step": k}]}))
        res = run_mpi(1, ["walkthrough", "--model", str(out / "steps" / "step_*.vtu"), "--grid", "1x1",
                          "--tile", "96x64", "--frames", "1", "--mosaic-every", "1", "--no-overlay", "--no-progress",
                          "--path", str(at), "--out", str(ref), "--color-by", "temperature", "--range", "0,1"])
        assert res.returncode == 0, res.stderr[-2000:]
        want = read_png(ref / "mosaic" / "frame_00000.png")
        got = read_png(out / "mosaic" / f"frame_{firsts[k]:05d}.png")
        assert (got == want).all(), f"step {k} (frame {firsts[k]}): {(got != want).any(axis=2).sum()} pixels differ"


def test_a_recorded_run_is_followed_to_its_end(tmp_path):
    subprocess.run([sys.executable, str(HEAT), "--file", str(tmp_path / "heat.bp"), "--steps", "12", "--size", "24",
                    "--every", "0"], check=True, timeout=120, cwd=tmp_path)
    path = still(tmp_path, 400)
    out = tmp_path / "o"
    res = wall(out, f"adios2:{tmp_path / 'heat.bp'}", path, (2, 2), ["--at-end", "stop", "--tile", "48x32"])
    assert res.returncode == 0, res.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped_by"] == "the series ended (--at-end stop)", summary.get("stopped_by")
    kept = sorted(p.name for p in (out / "steps").glob("step_*.vtu"))
    assert kept == [f"step_{k:06d}.vtu" for k in range(12)]
    steps = shown(out)
    assert list(dict.fromkeys(steps)) == list(range(steps[0], 12)) and steps[0] <= 1, steps  # each, to the last
    assert "the stream ended after 12 steps" in res.stderr
    check_frames(tmp_path, out, steps, path)


@pytest.mark.parametrize("late", ["hold", "wait"])
def test_a_live_stream_plays_as_it_comes(tmp_path, late):
    """Every rank shows the same step at every frame, forward, each as one rank renders it; never a
    late frame (rank 0 sends each step whole at a frame's start, every rank shows it at that frame),
    and each step shows at the first frame whose row ends after rank 0 kept it."""
    sim = subprocess.Popen([sys.executable, str(HEAT), "--name", str(tmp_path / "heat"), "--steps", "400", "--size",
                            "24", "--every", "0.05"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           start_new_session=True)
    try:
        for _ in range(200):  # the writer's contact file: the stream is there
            if (tmp_path / "heat.sst").exists() or sim.poll() is not None:
                break
            subprocess.run(["sleep", "0.05"], check=True)
        path = still(tmp_path, 150)
        out = tmp_path / "o"
        res = wall(out, f"adios2:{tmp_path / 'heat'}", path, extra=("--late-step", late, "--latency", "1"),
                   timeout=120)
        assert res.returncode == 0, res.stderr[-3000:]
    finally:
        if sim.poll() is None:
            os.killpg(sim.pid, signal.SIGKILL)
        sim.communicate(timeout=30)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] and summary["frames"] == 150
    steps = shown(out)
    assert len(set(steps)) >= 2 and steps == sorted(steps), steps  # it played, forward
    rows = list(csv.DictReader(open(out / "timings.csv")))
    assert all(r["step_late"] == "0" for r in rows)
    named = {}  # the first frame whose row (rank 0's, at its end) says rank 0 had kept the step
    for r in rows:
        if r["rank"] == "0":
            named.setdefault(int(float(r["step_wanted"])), int(r["frame"]))
    firsts = {k: steps.index(k) for k in dict.fromkeys(steps) if k > steps[0]}
    # kept during frame f (its row the first to say so): sent at the start of f + 1 at the latest, or
    # of f + 2 where frame f + 1 had started (--latency 1) before the keeping ended
    assert firsts and all(0 <= f - named[k] <= 2 for k, f in firsts.items() if k in named), (firsts, named)
    check_frames(tmp_path, out, steps, path)


def test_a_live_stream_reaches_a_pc_that_cannot_read_rank_0s_disk(tmp_path):
    """Two simulated PCs, the run's outputs on each PC's own disk (the second sees its own, empty):
    the second PC's ranks get the first step and every later step from rank 0, and
    every frame equals one rank's render of the step it shows."""
    from simhosts import SimHosts

    subprocess.run([sys.executable, str(HEAT), "--file", str(tmp_path / "heat.bp"), "--steps", "8", "--size", "20",
                    "--every", "0"], check=True, timeout=120, cwd=tmp_path)
    out = tmp_path / "o"
    path = still(tmp_path, 40)
    with SimHosts(["a", "b"], tmp_path / "hosts", private={"b": [out]}) as h:
        res = wall(out, f"adios2:{tmp_path / 'heat.bp'}", path, (2, 2), ["--at-end", "stop", "--tile", "48x32"],
                   env=h.env, hosts=[("a", 2), ("b", 2)])
    assert res.returncode == 0, res.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert [r["host"] for r in summary["config"]["ranks"]] == ["a", "a", "b", "b"]
    steps = shown(out)
    assert list(dict.fromkeys(steps)) == list(range(steps[0], 8)) and steps[0] <= 1, steps
    check_frames(tmp_path, out, steps, path)


def write_bp(path, steps):
    """A BP5 file of ``steps``: each a dict of variables."""
    from adios2 import Adios, Stream

    io = Adios().declare_io("t")
    io.set_engine("BP5")
    with Stream(io, str(path), "w") as s:
        for values in steps:
            s.begin_step()
            for name, v in values.items():
                v = np.ascontiguousarray(v)
                s.write(name, v, v.shape, [0] * v.ndim, v.shape)
            s.end_step()


def plate_step(height: float, n: int = 8) -> dict:
    sys.path.insert(0, str(HEAT.parent))
    from heat import plate

    xy, quads = plate(n)
    t = np.full(n * n, height)
    return {"points": np.c_[xy[0].ravel(), xy[1].ravel(), 0.25 * t], "quad": quads, "temperature": t}


@pytest.mark.parametrize("latency", ["0", "3"])
def test_steps_of_the_first_steps_cells_and_of_their_own_play_alike(tmp_path, latency):
    """Steps in the first step's layout (rank 0 sends what they change, through the host's shared
    memory) and steps of cells of their own (sent whole: a 160x160 plate's too big for its slots,
    broadcast; a 20x20 plate's through them) in one stream: every step shown in turn, each first
    frame equal to one rank's render of it; with frames in flight (--latency 3) a slot whose frame has
    not landed yet is not rewritten (that step is broadcast)."""
    write_bp(tmp_path / "run.bp", [plate_step(0.2), plate_step(0.4, 160), plate_step(0.6), plate_step(0.8, 20),
                                   plate_step(0.9)])
    path = still(tmp_path, 1000)  # (the run ends once the last step is shown)
    out = tmp_path / "o"
    res = wall(out, f"adios2:{tmp_path / 'run.bp'}", path, extra=["--at-end", "stop", "--latency", latency])
    assert res.returncode == 0, res.stderr[-3000:]
    steps = shown(out)
    assert list(dict.fromkeys(steps)) == list(range(steps[0], 5)) and steps[0] <= 1, steps
    check_frames(tmp_path, out, steps, path)


def test_a_stream_whose_first_step_the_wall_cannot_use_ends_the_job_in_one_line(tmp_path):
    first = plate_step(0.5)
    first.pop("points")
    write_bp(tmp_path / "bad.bp", [first])
    res = wall(tmp_path / "o", f"adios2:{tmp_path / 'bad.bp'}", still(tmp_path, 5), extra=["--timeout", "10"])
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("multigpu: error:")]
    assert res.returncode == 2 and len(errors) == 1, res.stderr[-3000:]
    assert "step 0: no 'points' variable" in res.stderr and "the stream ended before a step the wall could use" in \
        errors[0], errors


def test_a_later_step_the_wall_cannot_use_is_said_once_and_left_out(tmp_path):
    bad = plate_step(0.6)
    bad["quad"] = bad["quad"] + 100
    write_bp(tmp_path / "run.bp", [plate_step(0.2), bad, plate_step(0.9)])
    out = tmp_path / "o"
    res = wall(out, f"adios2:{tmp_path / 'run.bp'}", still(tmp_path, 300), extra=["--at-end", "stop"])
    assert res.returncode == 0, res.stderr[-3000:]
    said = [ln for ln in res.stderr.splitlines() if "step 1:" in ln]
    assert len(said) == 1 and said[0].startswith("multigpu: warning: adios2:") and "uses point" in said[0], said
    assert sorted(p.name for p in (out / "steps").glob("step_*.vtu")) == ["step_000000.vtu", "step_000001.vtu"]
    assert shown(out)[-1] == 1  # the third step written, the second kept
