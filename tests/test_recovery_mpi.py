"""``--recover`` under mpiexec, MPICH and Open MPI: a rank killed (SIGKILL) or frozen (SIGSTOP)
mid-run, and the wall comes back at the first frame not shown, the run one run (every frame
once in timings.csv, the restart marked, the summary counting it, mosaics whole); failures that
repeat are bounded (exit 3, one line); Ctrl-C during a recovery ends everything (exit 130).
Nothing is left behind: no rank process, no new shared-memory segment. Each launcher runs in
its own process group under a hard timeout, killed by id."""

import json
import os
import signal
import time
from pathlib import Path

import pytest
from mpirun import SMALL, end_launcher, read_png, start_launcher

from multigpu.launcher.mpirun import find_launcher, launcher_for, openmpi_on_path
from multigpu.records.report import read_timings
from multigpu.studies.recovery_bench import rank_pids as ranks_of

pytestmark = pytest.mark.mpi
FRAMES = 400


@pytest.fixture(params=["default", "openmpi"], scope="module")
def mpiexec(request):
    if request.param == "default":
        return find_launcher().path
    path = openmpi_on_path()
    if path is None:
        pytest.skip("no Open MPI mpiexec here (Debian: apt install openmpi-bin)")
    if os.path.realpath(launcher_for(path).path) == os.path.realpath(find_launcher().path):
        pytest.skip("the default mpiexec is Open MPI already")
    return path


def segments() -> set[str]:
    shm = Path("/dev/shm")
    return {p.name for p in shm.glob("mpich_shm_*")} | {p.name for p in shm.glob("vader_segment.*")}


def rows_written(out: Path) -> int:
    try:
        return (out / "timings.csv").read_text().count("\n") - 1
    except OSError:
        return 0


def launch(tmp_path, mpiexec, extra=(), env=None):
    out = tmp_path / "o"
    args = ["-n", "2", "walkthrough", *SMALL, "--grid", "1x2", "--tile", "64x48", "--frames", str(FRAMES),
            "--mosaic-every", "50", "--out", str(out), "--recover", "2", *extra]
    proc = start_launcher(args, {"LP_NUM_THREADS": "1", "MULTIGPU_MPIEXEC": mpiexec, **(env or {})})
    return proc, out


def wait_rows(proc, out: Path, rows: int, timeout: float = 90) -> None:
    t = time.monotonic()
    while rows_written(out) < rows:
        assert proc.poll() is None and time.monotonic() - t < timeout, end_launcher(proc, 5)[1][-3000:]
        time.sleep(0.1)


def killed_once(args: list[str], out: Path, rows: int, env: dict | None = None) -> tuple[int, str]:
    """``python -m multigpu.launcher.mpirun ARGS`` (outputs in ``out``) with its last rank killed
    once ``rows`` timing rows are written: its exit code and stderr (its process group killed if
    it outlives the wait)."""
    from multigpu.studies.recovery_bench import rank_pids

    proc = start_launcher(args, {"LP_NUM_THREADS": "1", **(env or {})})
    try:
        wait_rows(proc, out, rows)
        os.kill(rank_pids(out)[-1], signal.SIGKILL)
        _, err = end_launcher(proc, 150)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    return proc.returncode, err


@pytest.mark.parametrize("how", ["SIGKILL", "SIGSTOP"])
def test_a_killed_or_frozen_rank_and_the_wall_comes_back(tmp_path, mpiexec, how):
    before = segments()
    proc, out = launch(tmp_path, mpiexec, ["--liveness", "3", "--video"])
    try:
        wait_rows(proc, out, 2 * 60)
        victim = ranks_of(out)[-1]
        os.kill(victim, getattr(signal, how))
        _, err = end_launcher(proc, 150)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err[-3000:]
    assert err.count("multigpu: recovering (1 of at most 2") == 1 and err.count("multigpu: recovered:") == 1, err
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is True and s["frames"] == FRAMES and s["recovery_count"] == 1
    r = s["recoveries"][0]
    assert r["resumed_at"] == r["last_shown"] + 1 and 0 < r["seconds"] < 60, r
    rows = read_timings(out / "timings.csv")
    frames = rows[:, 0].reshape(-1, 2)
    assert (frames[:, 0] == frames[:, 1]).all() and (frames[:, 0] == range(FRAMES)).all()  # every frame, once
    restarts = rows[:, -1].reshape(-1, 2)[:, 0]
    assert (restarts[:r["resumed_at"]] == 0).all() and (restarts[r["resumed_at"]:] == 1).all()
    for f in range(0, FRAMES, 50):
        assert read_png(out / "mosaic" / f"frame_{f:05d}.png").shape == (48, 128, 3)
    assert (out / "mosaic.mp4").stat().st_size > 0 and (out / "mosaic-r1.mp4").stat().st_size > 0  # a video each
    assert not ranks_of(out), "a rank outlived the run"
    assert not (segments() - before), "a failed job's shared-memory segment was left"


def test_a_standby_takes_the_wall_over(tmp_path, mpiexec):
    """--standby: the next job waits while the wall runs; a killed rank's restart is that job,
    launched and imported already. The run is one run as above, and nothing is left after it."""
    before = segments()
    proc, out = launch(tmp_path, mpiexec, ["--standby"])
    try:
        wait_rows(proc, out, 2 * 60)
        t = time.monotonic()
        while len(ranks_of(out, standbys=True)) < 4:  # the standby's two ranks beside the job's two
            assert proc.poll() is None and time.monotonic() - t < 60, end_launcher(proc, 5)[1][-3000:]
            time.sleep(0.1)
        os.kill(ranks_of(out)[-1], signal.SIGKILL)
        _, err = end_launcher(proc, 150)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err[-3000:]
    assert err.count("multigpu: recovered:") == 1 and "a standby took over" in err, err[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is True and s["frames"] == FRAMES and s["recovery_count"] == 1
    r = s["recoveries"][0]
    assert r["standby"] is True and r["resumed_at"] == r["last_shown"] + 1, r
    frames = read_timings(out / "timings.csv")[:, 0].reshape(-1, 2)
    assert (frames[:, 0] == frames[:, 1]).all() and (frames[:, 0] == range(FRAMES)).all()  # every frame, once
    assert not ranks_of(out, standbys=True), "a rank or a standby's outlived the run"
    assert not (segments() - before), "a shared-memory segment was left"


def test_failures_that_repeat_are_bounded(tmp_path, mpiexec):
    proc, out = launch(tmp_path, mpiexec, env={"MULTIGPU_FAULT": "1:20"})  # every start fails at frame 20
    _, err = end_launcher(proc, 150)
    assert proc.returncode == 3, err[-3000:]
    assert err.count("multigpu: recovering") == 2 and err.count("multigpu: giving up: 3 failures") == 1, err[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert 15 <= s["frames"] <= 20 and s["complete"] is False  # the frames before the fault, each once
    assert not ranks_of(out)


def test_ctrl_c_during_a_recovery_ends_everything(tmp_path, mpiexec):
    proc, out = launch(tmp_path, mpiexec, ["--frames", "100000"])
    try:
        wait_rows(proc, out, 2 * 30)
        old = ranks_of(out)
        os.kill(old[-1], signal.SIGKILL)
        t = time.monotonic()
        while not (set(ranks_of(out)) - set(old)):  # the restarted job's ranks, starting up
            assert proc.poll() is None and time.monotonic() - t < 60, end_launcher(proc, 5)[1][-3000:]
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the launcher and its job
        _, err = end_launcher(proc, 60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err[-3000:]
    assert "multigpu: recovering (1 of" in err
    assert not ranks_of(out)


def test_an_x_server_that_dies_and_comes_back(tmp_path):
    """Windows on two X servers; one dies mid-run: restarts fail while it is gone, and once it
    is back (as a display manager restarts it) the wall comes back whole (windowed runs recover
    by default)."""
    from xserver import Xvfb, need_tools

    need_tools()
    out, frames = tmp_path / "o", 600
    with Xvfb((64, 48)) as a:
        b = Xvfb((64, 48))
        try:
            wall = tmp_path / "wall.json"
            wall.write_text(json.dumps({"grid": "1x2", "tile": "64x48", "displays": [
                {"rank": 0, "display": a.screen(0), "position": [0, 0]},
                {"rank": 1, "display": b.screen(0), "position": [0, 0]}]}))
            args = ["-n", "2", "walkthrough", *SMALL, "--wall", str(wall), "--present", "window", "--frames",
                    str(frames), "--mosaic-every", "100", "--no-overlay", "--out", str(out), "--liveness", "5"]
            proc = start_launcher(args, {"LP_NUM_THREADS": "1"})
            try:
                wait_rows(proc, out, 2 * 60)
                name = b.name
                b.stop()
                time.sleep(1.5)  # restarts fail meanwhile: its display is gone
                b = Xvfb((64, 48), display=name)
                _, err = end_launcher(proc, 180)
            finally:
                if proc.poll() is None:
                    os.killpg(proc.pid, signal.SIGKILL)
        finally:
            b.stop()
    assert proc.returncode == 0, err[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] and s["frames"] == frames and s["recovery_count"] >= 1, err[-3000:]
    frames_seen = read_timings(out / "timings.csv")[:, 0].reshape(-1, 2)[:, 0]
    assert (frames_seen == range(frames)).all()
