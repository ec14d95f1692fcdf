"""--present window on real X servers (Xvfb): what is on screen is the composite bit for bit,
tiles at their canvas places (one screen) or on their own X servers (a wall file), swap skew
recorded, and every way a window run ends: Escape, a window manager's close, Ctrl-C, no X
server, an X server that dies. Every job and server runs under a hard timeout and is killed by
process id."""

import json
import signal
import subprocess
import sys

import numpy as np
import pytest
from mpirun import ROOT, SMALL, read_png, run_mpi, start_mpi
from xserver import Xvfb, escape, need_tools, screenshot, wait_for, windows, wm_close

pytestmark = pytest.mark.mpi
GRID, TILE, MULLION = (2, 2), (60, 48), (7, 5)
CANVAS = (2 * 60 + 7, 2 * 48 + 5)


@pytest.fixture(scope="module")
def still_path(tmp_path_factory):
    """A path of 600 identical cameras: every frame shows the same picture, so a screenshot
    taken at any moment must equal any mosaic."""
    d = tmp_path_factory.mktemp("path")
    subprocess.run([sys.executable, "-m", "multigpu", "path", "make", "walkthrough", *SMALL[:2], "--frames", "60",
                    "--out", str(d / "walk.json")], cwd=ROOT, check=True, capture_output=True, timeout=120)
    doc = json.loads((d / "walk.json").read_text())
    doc["cameras"] = [doc["cameras"][40]] * 600
    (d / "still.json").write_text(json.dumps(doc))
    return d / "still.json"


def rows_written(out):
    f = out / "timings.csv"
    return f.exists() and len(f.read_text().splitlines()) > 1 + 4 * 10  # ten whole frames shown


def finish(proc, kill, timeout=120):
    try:
        return proc.communicate(timeout=timeout)
    finally:
        kill() if proc.poll() is None else None


def shown(n, args, x, wins, out):
    """A window job of ``n`` ranks on the X server ``x``: once ten frames are in and ``wins``
    windows open, the screen taken and Escape pressed; (screenshot, exit code, stderr)."""
    proc, kill = start_mpi(n, args, env={"DISPLAY": x.name})
    try:
        wait_for(lambda: rows_written(out) and len(windows(x.name)) == wins)
        shot = screenshot(x.name)
        escape(x.name, windows(x.name)[0])
        _, err = finish(proc, kill)
    finally:
        kill() if proc.poll() is None else None
    return shot, proc.returncode, err


def window_args(out, path, extra=()):
    return ["walkthrough", *SMALL, "--path", str(path), "--grid", "2x2", "--tile", "60x48", "--mullion", "7x5",
            "--mosaic-every", "100", "--no-overlay", "--present", "window", "--out", str(out), *extra]


@pytest.mark.parametrize("latency", ["0", "2"])
def test_screen_shows_the_composite_and_escape_ends_the_run(tmp_path, still_path, latency):
    out = tmp_path / "win"
    with Xvfb(CANVAS) as x:
        shot, code, err = shown(4, window_args(out, still_path, ["--latency", latency]), x, 4, out)
    assert code == 0, err[-2000:]
    mosaic = read_png(out / "mosaic" / "frame_00000.png")
    assert shot.shape == mosaic.shape == (CANVAS[1], CANVAS[0], 3)
    assert (shot == mosaic).all(), f"{(shot != mosaic).any(axis=2).sum()} screen pixels differ from the composite"
    assert (mosaic[48:53].max() == 0) and (mosaic[:, 60:67].max() == 0)  # mullions black, never rendered
    s = json.loads((out / "summary.json").read_text())
    assert not s["complete"] and s["stopped_by"].startswith("escape key")
    assert s["frames_written"] < 600 and s["config"]["present"] == "window"
    p = s["present"]
    assert 0 <= p["swap_skew_ms_median"] <= p["swap_skew_ms_p99"] <= p["swap_skew_ms_max"]
    assert p["present_ms_median"] > 0
    import csv

    with open(out / "timings.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 * s["frames_written"]
    frame0 = [r for r in rows if r["frame"] == "0"]
    assert len({r["swap_skew_ms"] for r in frame0}) == 1  # one skew per frame, on every row
    assert min(float(r["swap_ms"]) for r in frame0) == 0.0
    assert max(float(r["swap_ms"]) for r in frame0) == pytest.approx(float(frame0[0]["swap_skew_ms"]), abs=1e-3)


def test_one_x_server_per_rank_from_a_wall_file(tmp_path, still_path):
    with Xvfb((60, 96)) as a, Xvfb((80, 100)) as b:
        wall = tmp_path / "wall.json"
        wall.write_text(json.dumps({"grid": "1x2", "tile": "60x96", "displays": [
            {"rank": 0, "display": a.screen(0), "position": [0, 0]},
            {"rank": 1, "display": b.screen(0), "position": [20, 4]}]}))
        out = tmp_path / "two"
        args = ["walkthrough", *SMALL, "--path", str(still_path), "--wall", str(wall), "--present", "window",
                "--mosaic-every", "100", "--no-overlay", "--out", str(out)]
        proc, kill = start_mpi(2, args)
        try:
            wait_for(lambda: rows_written(out) and windows(a.name) and windows(b.name))
            shots = screenshot(a.name), screenshot(b.name)
            wm_close(b.name, windows(b.name)[0])  # the user closes rank 1's window
            _, err = finish(proc, kill)
        finally:
            kill() if proc.poll() is None else None
    assert proc.returncode == 0, err[-2000:]
    mosaic = read_png(out / "mosaic" / "frame_00000.png")
    assert (shots[0] == mosaic[:, :60]).all()
    assert (shots[1][4:100, 20:80] == mosaic[:, 60:]).all()
    assert shots[1][:4].max() == 0 and shots[1][:, :20].max() == 0  # only the window at (20, 4)
    s = json.loads((out / "summary.json").read_text())
    assert s["stopped_by"] == "window closed (rank 1's window)"


def test_ctrl_c_ends_a_window_run_with_130(tmp_path, still_path):
    with Xvfb(CANVAS) as x:
        out = tmp_path / "int"
        proc, kill = start_mpi(4, window_args(out, still_path), env={"DISPLAY": x.name})
        try:
            wait_for(lambda: rows_written(out))
            import os

            os.killpg(proc.pid, signal.SIGINT)
            _, err = finish(proc, kill)
        finally:
            kill() if proc.poll() is None else None
        assert windows(x.name) == []  # no window left behind
    from multigpu.launcher.mpirun import find_launcher

    # MPICH forwards Ctrl-C and returns 130; Open MPI forwards it as SIGTERM and returns 1 (docs/USAGE.md)
    code, seen = (1, "SIGTERM") if find_launcher().flavor == "openmpi" else (130, "SIGINT")
    assert proc.returncode == code, err[-2000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["stopped_by"] == f"signal {seen}"
    lines = (out / "timings.csv").read_text().splitlines()
    assert (len(lines) - 1) == 4 * s["frames_written"]


@pytest.mark.parametrize("display", [None, ":987"], ids=["unset", "no-server"])
def test_no_x_server_is_one_line_and_exit_2(tmp_path, display, still_path):
    need_tools()
    env = {"DISPLAY": display} if display else {"DISPLAY": ""}
    res = run_mpi(4, window_args(tmp_path / "nox", still_path), env=env, timeout=120)
    assert res.returncode == 2, res.stderr[-2000:]
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--present window" in lines[0] and "DISPLAY" in lines[0], res.stderr
    assert not (tmp_path / "nox").exists()  # nothing created by a run refused at the door


def test_an_x_server_that_dies_ends_the_job(tmp_path, still_path):
    x = Xvfb(CANVAS)
    out = tmp_path / "dies"
    proc, kill = start_mpi(4, window_args(out, still_path, ["--liveness", "10"]), env={"DISPLAY": x.name})
    try:
        wait_for(lambda: rows_written(out))
        x.stop()
        _, err = finish(proc, kill, timeout=60)  # within --liveness, with margin for the launcher
    finally:
        kill() if proc.poll() is None else None
        x.stop()
    assert proc.returncode != 0
    lines = (out / "timings.csv").read_text().splitlines()
    assert (len(lines) - 1) % 4 == 0 and len(lines) > 1 + 4 * 10  # whole frames, nothing lost
    np.testing.assert_array_equal(read_png(out / "mosaic" / "frame_00000.png")[48:53], 0)
