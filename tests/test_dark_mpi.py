"""A wall that goes on without a PC (``--dark-tiles``, ``launcher/relaunch.py``): its tiles black,
every rank sharing the live ones, bit for bit a one-rank render with those tiles black; and on
two simulated hosts, under MPICH and Open MPI, a host that goes down and stays down: the
launcher restarts the wall on the other host with the lost tiles dark, then takes the host back
once its remote shell answers. Every job under a hard timeout, every process killed by id."""

import json
import os
import signal
import sys
import time

import pytest
from mpirun import ROOT, SMALL, mpi_named, read_png, run_mpi
from simhosts import SimHosts

from multigpu.core.canvas import Canvas

pytestmark = pytest.mark.mpi
W, H, FRAMES = 96, 80, 3


def walk(out, grid, tile, extra=()):
    res = run_mpi(grid[0] * grid[1], ["walkthrough", *SMALL, "--frames", str(FRAMES), "--grid", f"{grid[0]}x{grid[1]}",
                                      "--tile", f"{tile[0]}x{tile[1]}", "--mosaic-every", "1", "--no-overlay",
                                      "--cluster", "0", "--out", str(out), *extra])
    assert res.returncode == 0, res.stderr[-3000:]
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(FRAMES)]


@pytest.mark.parametrize("extra", [[], ["--balance", "cross"], ["--decomposition", "db"], ["--mullion", "6x4"]])
def test_dark_tiles_are_black_and_the_rest_is_the_one_rank_render(tmp_path, extra):
    mullion = (6, 4) if "--mullion" in extra else (0, 0)
    c = Canvas((2, 2), (W // 2, H // 2), mullion, (1, 2))
    ref = [img.copy() for img in walk(tmp_path / "one", (1, 1), c.size)]
    for img in ref:
        img[c.hidden()] = 0
    got = walk(tmp_path / "wall", (2, 2), (W // 2, H // 2), [*extra, "--dark-tiles", "1,2"])
    for f, (g, w) in enumerate(zip(got, ref)):
        assert (g == w).all(), f"frame {f}: {(g != w).any(axis=2).sum()} pixels differ"
    with open(tmp_path / "wall" / "timings.csv") as fh:
        rows = [line.split(",") for line in fh.read().splitlines()[1:]]
    assert any(int(r[2]) > 0 for r in rows if r[1] in ("1", "2"))  # the stand-ins draw live tiles' objects


@pytest.fixture(params=["mpich", "openmpi"])
def launcher(request):
    return mpi_named(request.param)


def test_a_host_that_stays_down_leaves_its_tiles_dark_until_it_answers(tmp_path, launcher):
    import subprocess

    out, frames = tmp_path / "o", 4000
    with SimHosts(["a", "b"], tmp_path / "hosts", network=True) as hosts:
        env = {**os.environ, **hosts.env, "MULTIGPU_CACHE": str(tmp_path / "cache"), "MULTIGPU_MPIEXEC": launcher.path,
               "LP_NUM_THREADS": "1", "MULTIGPU_REJOIN_EVERY": "2"}
        cmd = [sys.executable, "-m", "multigpu.launcher.mpirun", "-n", "4", "--hosts", "a:2,b:2", "walkthrough",
               *SMALL, "--frames", str(frames), "--grid", "2x2", "--tile", f"{W // 2}x{H // 2}", "--mosaic-every",
               "25", "--no-overlay", "--out", str(out), "--recover", "2", "--liveness", "5"]
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        try:
            csv, t = out / "timings.csv", time.monotonic()
            while not (csv.exists() and csv.read_text().count("\n") > 1 + 4 * 100):
                assert proc.poll() is None and time.monotonic() - t < 120, proc.communicate()[1][-3000:]
                time.sleep(0.1)
            hosts.down("b")
            t = time.monotonic()
            while json.loads((out / "summary.json").read_text())["config"].get("dark") != [2, 3]:
                assert proc.poll() is None and time.monotonic() - t < 120, proc.communicate()[1][-3000:]
                time.sleep(0.2)
            time.sleep(1.0)  # some frames without host b
            hosts.up("b")
            _, err = proc.communicate(timeout=240)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err[-3000:]
    assert "without b (tiles 2,3 dark)" in err and "every host answers" in err, err[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] and s["frames"] == frames and s["recovery_count"] == 1 and s["config"]["dark"] == []
    right = [read_png(out / "mosaic" / f"frame_{f:05d}.png")[:, W // 2:] for f in range(0, frames, 25)]
    dark = [not img.any() for img in right]
    assert any(dark) and not dark[0] and not dark[-1], dark  # dark while b was down, then back
