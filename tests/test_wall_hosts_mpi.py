"""A wall of several PCs, end to end: two simulated hosts (namespaces, simhosts.py), each with
its own X server started inside it, one wall file naming each rank's host, display and window
position, started by the launcher users run (``python -m multigpu.launcher.mpirun`` with no
placement flag) under MPICH and Open MPI. Each host's screenshot equals its tile of the mosaic
bit for bit; a host whose X server is missing is one line naming the host and the display, exit
2, and nothing left running. Every job, X server and namespace under a hard timeout, killed by id."""

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpirun import ROOT, SMALL, end_launcher, mpi_named, read_png, start_launcher
from simhosts import SimHosts
from xserver import need_tools, screenshot, wait_for, windows, wm_close

from multigpu.display.xvfb import start_xvfb, stop_xvfb

pytestmark = pytest.mark.mpi
TILE = (60, 96)


@pytest.fixture(params=["mpich", "openmpi"])
def mpiexec_env(request):
    return {"MULTIGPU_MPIEXEC": mpi_named(request.param).path}


def free_display() -> str:
    """A display number no X server on this machine holds: hosts with their own network have their
    own abstract sockets, so Xvfb's own choice would give each host :0, but they share
    /tmp/.X11-unix, where the second server's socket would replace the first's."""
    n = 0
    while Path(f"/tmp/.X{n}-lock").exists() or Path(f"/tmp/.X11-unix/X{n}").exists():
        n += 1
    return f":{n}"


def _pcs(tmp_path, sizes):
    """Hosts a and b, each running its own Xvfb of the given size (started inside the host)."""
    need_tools()
    with SimHosts(["a", "b"], tmp_path / "hosts", network=True) as hosts:
        servers = []
        try:
            for name, size in zip("ab", sizes):
                enter = ("nsenter", "--target", str(hosts.pids[name]), *hosts.spaces, "--")
                # tools present (need_tools): a failure fails
                servers.append(start_xvfb(size, prefix=enter, display=free_display()))
            yield hosts, [name for _, name in servers]
        finally:
            for proc, _ in servers:
                stop_xvfb(proc)


@pytest.fixture
def two_pcs(tmp_path):
    """Hosts a and b, a tile's screen and a bigger one."""
    yield from _pcs(tmp_path, (TILE, (80, 100)))


@pytest.fixture
def two_pcs_rows(tmp_path):
    """Hosts a and b, each an X server as wide as a row of two tiles."""
    yield from _pcs(tmp_path, ((2 * TILE[0], TILE[1]),) * 2)


def _still(tmp_path):
    """A path of identical cameras: any screenshot equals any mosaic."""
    p = tmp_path / "walk.json"
    subprocess.run([sys.executable, "-m", "multigpu", "path", "make", "walkthrough", *SMALL[:2], "--frames", "60",
                    "--out", str(p)], cwd=ROOT, check=True, capture_output=True, timeout=120)
    doc = json.loads(p.read_text())
    doc["cameras"] = [doc["cameras"][40]] * 600
    (tmp_path / "still.json").write_text(json.dumps(doc))
    return tmp_path / "still.json"


def _launch(tmp_path, hosts, env, wall, out):
    return start_launcher(["-n", "2", "walkthrough", *SMALL, "--path", str(_still(tmp_path)), "--wall", str(wall),
                           "--present", "window", "--mosaic-every", "100", "--no-overlay", "--out", str(out)],
                          {**hosts.env, **env})


def _shown_and_closed(proc, out, rows: int, displays, per_display: int, close, timeout: float = 120):
    """Once ``rows`` timing rows are written and each of ``displays`` holds ``per_display``
    windows: a screenshot of each, then ``close``'s first window closed as a window manager does
    and the launcher ended (killed by its group if still there). Returns the shots and stderr."""
    try:
        shown = lambda: (out / "timings.csv").exists() and len((out / "timings.csv").read_text().splitlines()) > rows
        wait_for(lambda: shown() and all(len(windows(x)) == per_display for x in displays), timeout=timeout)
        shots = tuple(screenshot(x) for x in displays)
        wm_close(close, windows(close)[0])
        _, err = end_launcher(proc)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    return shots, err


def test_each_host_shows_its_tile_of_the_mosaic(tmp_path, two_pcs, mpiexec_env):
    hosts, (xa, xb) = two_pcs
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": f"{TILE[0]}x{TILE[1]}", "mullion": "9x0", "displays": [
        {"rank": 0, "host": "a", "display": xa, "position": [0, 0]},
        {"rank": 1, "host": "b", "display": xb, "position": [20, 4]}]}))
    out = tmp_path / "wall"
    proc = _launch(tmp_path, hosts, mpiexec_env, wall, out)
    try:
        shown = lambda: (out / "timings.csv").exists() and len((out / "timings.csv").read_text().splitlines()) > 21
        wait_for(lambda: shown() and windows(xa) and windows(xb), timeout=120)
        shots = screenshot(xa), screenshot(xb)
        wm_close(xb, windows(xb)[0])  # the person at host b closes its window
        _, err = end_launcher(proc)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err[-2000:]
    s = json.loads((out / "summary.json").read_text())
    assert [r["host"] for r in s["config"]["ranks"]] == ["a", "b"]
    assert s["present"]["swap_skew_ms_by_host"] == {"a": 0.0, "b": 0.0}  # each PC's own skew (one rank each: 0)
    mosaic = read_png(out / "mosaic" / "frame_00000.png")
    assert mosaic.shape[1] == 2 * TILE[0] + 9 and mosaic[:, TILE[0]:TILE[0] + 9].max() == 0  # the mullion
    assert (shots[0] == mosaic[:, :TILE[0]]).all()
    assert (shots[1][4:4 + TILE[1], 20:20 + TILE[0]] == mosaic[:, TILE[0] + 9:]).all()
    assert s["stopped_by"] == "window closed (rank 1's window)"
    assert not hosts.processes("a") and not hosts.processes("b") or all(
        "Xvfb" in open(f"/proc/{p}/cmdline").read() for n in "ab" for p in hosts.processes(n))


def test_a_stereo_wall_of_two_pcs_shows_each_its_packed_tile(tmp_path, two_pcs):
    """Side by side on two simulated PCs: each host's screen is its packed tile of the mosaic, bit
    for bit, and its halves are the eyes' own mosaics' parts."""
    from multigpu.core.canvas import Canvas
    from multigpu.core.stereo import Stereo

    hosts, (xa, xb) = two_pcs
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": f"{TILE[0]}x{TILE[1]}", "mullion": "8x0",
                                "screen_m": [1.28, 0.96], "stereo": {"mode": "side-by-side"}, "displays": [
        {"rank": 0, "host": "a", "display": xa, "position": [0, 0]},
        {"rank": 1, "host": "b", "display": xb, "position": [20, 4]}]}))
    out = tmp_path / "wall"
    proc = _launch(tmp_path, hosts, {"MULTIGPU_MPIEXEC": mpi_named("mpich").path}, wall, out)
    shots, err = _shown_and_closed(proc, out, 21, (xa, xb), 1, xb)
    assert proc.returncode == 0, err[-2000:]
    mosaic = read_png(out / "mosaic" / "frame_00000.png")
    assert (shots[0] == mosaic[:, :TILE[0]]).all()
    assert (shots[1][4:4 + TILE[1], 20:20 + TILE[0]] == mosaic[:, TILE[0] + 8:]).all()
    eye = Stereo("side-by-side", Canvas((1, 2), TILE, (8, 0))).eye
    left, right = (read_png(out / "mosaic" / d / "frame_00000.png") for d in ("left", "right"))
    ew = TILE[0] // 2
    for k, x in ((0, 0), (1, TILE[0] + 8)):  # each tile: the left eye's part, then the right eye's
        ex = int(eye.tiles()[k][0])
        assert (mosaic[:, x:x + ew] == left[:, ex:ex + ew]).all() and (mosaic[:, x + ew:x + TILE[0]] ==
                                                                       right[:, ex:ex + ew]).all()


def test_a_passive_wall_of_two_pcs_shows_each_eye_on_its_own_output(tmp_path, two_pcs_rows):
    """Passive stereo on two simulated PCs, each with two outputs side by side on its X screen: the
    left-eye window shows the tile of the left eye's mosaic, the right-eye window the right's, bit
    for bit."""
    hosts, (xa, xb) = two_pcs_rows
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": f"{TILE[0]}x{TILE[1]}", "mullion": "8x0",
                                "screen_m": [1.28, 0.96], "stereo": {"mode": "passive"}, "displays": [
        {"rank": k, "host": h, "display": x, "position": [0, 0], "right_eye_position": [TILE[0], 0]}
        for k, (h, x) in enumerate((("a", xa), ("b", xb)))]}))
    out = tmp_path / "wall"
    proc = _launch(tmp_path, hosts, {"MULTIGPU_MPIEXEC": mpi_named("mpich").path}, wall, out)
    shots, err = _shown_and_closed(proc, out, 21, (xa, xb), 2, xb)
    assert proc.returncode == 0, err[-2000:]
    left, right = (read_png(out / "mosaic" / d / "frame_00000.png") for d in ("left", "right"))
    assert (read_png(out / "mosaic" / "frame_00000.png") == np.concatenate([left, right], axis=1)).all()
    for shot, x in zip(shots, (0, TILE[0] + 8)):  # each PC: its tile of the left eye, then of the right eye
        assert (shot[:, :TILE[0]] == left[:, x:x + TILE[0]]).all()
        assert (shot[:, TILE[0]:] == right[:, x:x + TILE[0]]).all()
    assert (left != right).any()


def test_a_host_without_its_x_server_is_one_line_and_exit_2(tmp_path, two_pcs, mpiexec_env):
    hosts, (xa, _) = two_pcs
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": f"{TILE[0]}x{TILE[1]}", "displays": [
        {"rank": 0, "host": "a", "display": xa, "position": [0, 0]},
        {"rank": 1, "host": "b", "display": ":987", "position": [0, 0]}]}))
    proc = _launch(tmp_path, hosts, mpiexec_env, wall, tmp_path / "nox")
    _, err = end_launcher(proc)
    assert proc.returncode == 2, err[-2000:]
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and ":987" in lines[0] and "host b" in lines[0], err
    assert not windows(xa)  # no window left open on host a
    left = [p for n in "ab" for p in hosts.processes(n) if "Xvfb" not in open(f"/proc/{p}/cmdline").read()]
    assert not left, left


def test_a_pc_per_row_shows_its_row_of_the_mosaic(tmp_path, two_pcs_rows, mpiexec_env):
    """A 2x2 wall cabled by rows: tiles 0 and 2 (the top row) on host a, 1 and 3 on host b. The
    launcher places two processes on each host and they drive their host's tiles; each host's
    screen equals its row of the mosaic, bit for bit."""
    hosts, (xa, xb) = two_pcs_rows
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "2x2", "tile": f"{TILE[0]}x{TILE[1]}", "displays": [
        {"rank": 0, "host": "a", "display": xa, "position": [0, 0]},
        {"rank": 1, "host": "b", "display": xb, "position": [0, 0]},
        {"rank": 2, "host": "a", "display": xa, "position": [TILE[0], 0]},
        {"rank": 3, "host": "b", "display": xb, "position": [TILE[0], 0]}]}))
    out = tmp_path / "rows"
    proc = start_launcher(["-n", "4", "walkthrough", *SMALL, "--path", str(_still(tmp_path)), "--wall", str(wall),
                           "--present", "window", "--mosaic-every", "100", "--no-overlay", "--out", str(out)],
                          {**hosts.env, **mpiexec_env})
    shots, err = _shown_and_closed(proc, out, 41, (xa, xb), 2, xa, timeout=180)
    assert proc.returncode == 0, err[-2000:]
    s = json.loads((out / "summary.json").read_text())
    assert [r["host"] for r in s["config"]["ranks"]] == ["a", "b", "a", "b"]  # by tile: rows on their hosts
    mosaic = read_png(out / "mosaic" / "frame_00000.png")
    assert (shots[0] == mosaic[:TILE[1]]).all() and (shots[1] == mosaic[TILE[1]:]).all()
    left = [p for n in "ab" for p in hosts.processes(n) if "Xvfb" not in open(f"/proc/{p}/cmdline").read()]
    assert not left, left


def test_the_operators_view_on_a_pc_of_its_own(tmp_path, mpiexec_env):
    """The wall on host a, the operator's view (``--monitor``) on the desk PC with its own X
    server, as the wall file says: it shows the wall, its keys reach the run (B: the next
    strategy on every rank), and Escape there ends the run."""
    from multigpu.display.xvfb import start_xvfb, stop_xvfb
    from multigpu.records.report import BALANCE_NAMES, read_timings

    need_tools()
    with SimHosts(["a", "desk"], tmp_path / "hosts", network=True) as hosts:
        servers = []
        try:
            for name, size in (("a", (2 * TILE[0], TILE[1])), ("desk", (320, 240))):
                enter = ("nsenter", "--target", str(hosts.pids[name]), *hosts.spaces, "--")
                servers.append(start_xvfb(size, prefix=enter, display=free_display()))  # a failure fails
            xa, xd = (name for _, name in servers)
            wall = tmp_path / "wall.json"
            wall.write_text(json.dumps({"grid": "1x2", "tile": f"{TILE[0]}x{TILE[1]}", "displays": [
                {"rank": 0, "host": "a", "display": xa, "position": [0, 0]},
                {"rank": 1, "host": "a", "display": xa, "position": [TILE[0], 0]}],
                "monitor": {"position": [10, 20], "host": "desk", "display": xd, "address": "desk"}}))
            out = tmp_path / "wall"
            proc = start_launcher(["-n", "2", "walkthrough", *SMALL, "--path", str(_still(tmp_path)), "--wall",
                                   str(wall), "--present", "window", "--monitor", "--mosaic-every", "100",
                                   "--no-overlay", "--out", str(out), "--recover", "0"], {**hosts.env, **mpiexec_env})
            try:
                view = wait_for(lambda: windows(xd, "multigpu monitor"), timeout=120)[0]
                wait_for(lambda: screenshot(xd)[20:20 + TILE[1] // 2, 10:10 + TILE[0]].max() > 0, timeout=60)
                shot = screenshot(xd)
                for step in (["mousemove", "--window", view, "5", "5"], ["keydown", "--window", view, "b"],
                             ["keyup", "--window", view, "b"]):  # as escape() in xserver.py: the key to the window
                    subprocess.run(["xdotool", *step], timeout=10, check=True, env={**os.environ, "DISPLAY": xd})
                wait_for(lambda: len(set(read_timings(out / "timings.csv")[:, -2])) > 1, timeout=60)
                subprocess.run(["xdotool", "keydown", "--window", view, "Escape"], timeout=10, check=True,
                               env={**os.environ, "DISPLAY": xd})
                _, err = end_launcher(proc)
            finally:
                if proc.poll() is None:
                    os.killpg(proc.pid, signal.SIGKILL)
        finally:
            for p, _ in servers:
                stop_xvfb(p)
    assert proc.returncode == 0, err[-2000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["stopped_by"] == "escape key (the monitor)", s["stopped_by"]
    balances = {BALANCE_NAMES[int(b)] for b in read_timings(out / "timings.csv")[:, -2]}
    assert len(balances) >= 2  # B on the desk switched every rank's strategy
    assert shot[20:20 + TILE[1] // 2, 10:10 + TILE[0]].mean() > 5  # the wall, shrunk, on the desk's screen


def test_a_hosts_x_server_that_dies_and_comes_back(tmp_path, two_pcs, mpiexec_env):
    """Host b's X server dies mid-run under windows: the wall's restarts fail while it is gone
    (each one counted), and once it is back on its display (as a display manager restarts it)
    the launcher brings the whole wall back, every frame once in timings.csv."""
    from multigpu.records.report import read_timings

    hosts, (xa, xb) = two_pcs
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": f"{TILE[0]}x{TILE[1]}", "displays": [
        {"rank": 0, "host": "a", "display": xa, "position": [0, 0]},
        {"rank": 1, "host": "b", "display": xb, "position": [0, 0]}]}))
    out, frames = tmp_path / "wall", 500
    proc = start_launcher(["-n", "2", "walkthrough", *SMALL, "--wall", str(wall), "--present", "window",
                           "--frames", str(frames), "--mosaic-every", "100", "--no-overlay", "--out", str(out),
                           "--liveness", "5"], {**hosts.env, **mpiexec_env})
    revived = None
    try:
        wait_for(lambda: (out / "timings.csv").exists() and len((out / "timings.csv").read_text().splitlines()) > 81,
                 timeout=120)
        server = next(p for p in hosts.processes("b") if "Xvfb" in open(f"/proc/{p}/cmdline").read())
        os.kill(server, signal.SIGKILL)
        import time

        time.sleep(1.5)  # restarts fail meanwhile
        enter = ("nsenter", "--target", str(hosts.pids["b"]), *hosts.spaces, "--")
        revived = start_xvfb((80, 100), prefix=enter, display=xb)
        _, err = end_launcher(proc, 240)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        if revived is not None:
            stop_xvfb(revived[0])
    assert proc.returncode == 0, err[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] and s["frames"] == frames and s["recovery_count"] >= 1, err[-3000:]
    assert (read_timings(out / "timings.csv")[:, 0].reshape(-1, 2)[:, 0] == range(frames)).all()
