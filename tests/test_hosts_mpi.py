"""Across hosts: two simulated hosts (namespaces with their own hostname, /dev/shm, IPC and network,
joined by shaped links: ``multigpu.studies.simhosts``) of two ranks each, started through each MPI's
own host placement and a remote shell. The wall equals the one-rank render bit for bit and the run
ends with no MPI/UCX warnings; the summary says where each rank ran; a scene cache every host shares
is built once; the default exchange shares memory within a host and sends messages between hosts;
``--exchange shared`` is refused across hosts. Every job runs under a hard timeout and every
namespace process is killed by id."""

import json

import numpy as np
import pytest
from mpirun import SMALL, mpi_named, read_png, run_mpi
from simhosts import SimHosts

from multigpu.gpu.buffers import VERSION as GL_VERSION

pytestmark = pytest.mark.mpi
W, H = 96, 80
FRAMES = 4
HOSTS = [("a", 2), ("b", 2)]
QUIET = ("UCX", "unexpected", "WARN", "Warning", "warning")  # nothing of the kind at the end of a run


@pytest.fixture(params=["mpich", "openmpi"])
def launcher(request):
    return mpi_named(request.param)


@pytest.fixture
def hosts(tmp_path):
    with SimHosts([h for h, _ in HOSTS], tmp_path / "hosts", network=True) as h:
        yield h


def args(out, frames=FRAMES, extra=()):
    return ["walkthrough", *SMALL, "--frames", str(frames), "--grid", "2x2", "--tile", f"{W // 2}x{H // 2}",
            "--mosaic-every", "1", "--no-overlay", "--cluster", "0", "--out", str(out), *extra]  # one cache key


def frames_of(out, n=FRAMES):
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(n)]


def test_two_hosts_compose_like_one_rank_and_build_the_shared_cache_once(tmp_path, hosts, launcher):
    cache = tmp_path / "cache"  # a directory every host sees, as a home on a network file system
    env = {**hosts.env, "MULTIGPU_CACHE": str(cache)}
    res = run_mpi(4, args(tmp_path / "wall"), env=env, launcher=launcher, hosts=HOSTS, timeout=180)
    assert res.returncode == 0, res.stderr[-3000:]
    noise = [line for line in (res.stdout + res.stderr).splitlines() if any(w in line for w in QUIET)]
    assert not noise, noise[:5]
    s = json.loads((tmp_path / "wall" / "summary.json").read_text())
    assert [r["host"] for r in s["config"]["ranks"]] == ["a", "a", "b", "b"] and s["config"]["hosts"] == 2
    assert [r["node_rank"] for r in s["config"]["ranks"]] == [0, 1, 0, 1]
    # the default exchange: each host's ranks share a window, messages go between the hosts
    assert s["config"]["exchange"] == "shared + messages" and "exchange_why" not in s["config"]
    assert all(isinstance(r["egl_device"], int) for r in s["config"]["ranks"])  # one device here: 0
    assert s["config"]["scene"]["cached"] is False  # built here, once, by rank 0
    built = sorted(p.name for p in cache.rglob("*") if p.is_file())
    partial = [n for n in built if ".part" in n or ".tmp" in n or n.startswith(".")]
    assert built and not partial, built  # whole files only
    # the GL buffers file beside the cache, written once, is what every rank on both hosts draws from
    gl = [n for n in built if n.endswith(f".gl{GL_VERSION}")]
    assert len(gl) == 1 and all(r["gl_buffers"].endswith(gl[0]) or gl[0] in r["gl_buffers"]
                                for r in s["config"]["ranks"]), (gl, s["config"]["ranks"])
    ref = run_mpi(1, [*args(tmp_path / "one"), "--grid", "1x1", "--tile", f"{W}x{H}"],
                  env={"MULTIGPU_CACHE": str(cache)})
    assert ref.returncode == 0, ref.stderr[-3000:]
    for f, (got, want) in enumerate(zip(frames_of(tmp_path / "wall"), frames_of(tmp_path / "one"))):
        assert got.shape == (H, W, 3) and (got == want).all(), f"frame {f}: {(got != want).any(axis=2).sum()} px"
    assert json.loads((tmp_path / "one" / "summary.json").read_text())["config"]["scene"]["cached"] is True
    assert sorted(p.name for p in cache.rglob("*") if p.is_file()) == built  # read, never rebuilt


@pytest.mark.parametrize("extra", [["--balance", "cross"], ["--decomposition", "db"],
                                   ["--balance", "cross", "--projection", "shared"]])
def test_each_host_shares_memory_and_messages_cross_hosts(tmp_path, hosts, launcher, extra):
    """The default exchange on two hosts: cross's colour pieces and db's depth pieces reach
    their tiles through each host's window and through messages between the hosts, and the
    wall equals the one-rank render; with ``--projection shared`` each host's two ranks project
    half of the bounds each into their host's own array."""
    env = {**hosts.env, "MULTIGPU_CACHE": str(tmp_path / "cache")}
    res = run_mpi(4, args(tmp_path / "wall", extra=extra), env=env, launcher=launcher, hosts=HOSTS, timeout=180)
    assert res.returncode == 0, res.stderr[-3000:]
    s = json.loads((tmp_path / "wall" / "summary.json").read_text())
    assert s["config"]["exchange"] == "shared + messages" and s["bytes_sent_per_frame"] > 0
    assert s["config"]["projection"] == ("shared: a slice per rank of 2 on a host" if "--projection" in extra
                                         else "each rank every object")
    ref = run_mpi(1, [*args(tmp_path / "one"), "--grid", "1x1", "--tile", f"{W}x{H}"],
                  env={"MULTIGPU_CACHE": str(tmp_path / "cache")})
    assert ref.returncode == 0, ref.stderr[-3000:]
    for f, (got, want) in enumerate(zip(frames_of(tmp_path / "wall"), frames_of(tmp_path / "one"))):
        assert (got == want).all(), f"frame {f}: {(got != want).any(axis=2).sum()} px"


@pytest.mark.parametrize("extra", [["--scene", "swarm", "--path-kind", "still"],
                                   ["--moving", "0.3", "--decomposition", "hybrid", "--projection", "shared"]],
                         ids=["swarm", "machinery-hybrid"])
def test_a_moving_scene_on_two_hosts_composes_like_one_rank(tmp_path, hosts, launcher, extra):
    """Scenes that move, across hosts: every rank on either host poses the same frame at the same
    scene time, so the wall equals one rank's render of each frame, and the frames change."""
    env = {**hosts.env, "MULTIGPU_CACHE": str(tmp_path / "cache")}
    res = run_mpi(4, args(tmp_path / "wall", extra=extra), env=env, launcher=launcher, hosts=HOSTS, timeout=180)
    assert res.returncode == 0, res.stderr[-3000:]
    ref = run_mpi(1, [*args(tmp_path / "one", extra=extra), "--grid", "1x1", "--tile", f"{W}x{H}"],
                  env={"MULTIGPU_CACHE": str(tmp_path / "cache")})
    assert ref.returncode == 0, ref.stderr[-3000:]
    want = frames_of(tmp_path / "one")
    assert (want[-1] != want[0]).any()
    for f, (got, one) in enumerate(zip(frames_of(tmp_path / "wall"), want)):
        assert (got == one).all(), f"frame {f}: {(got != one).any(axis=2).sum()} px"
    assert json.loads((tmp_path / "wall" / "summary.json").read_text())["cpu"]["posing_cpu_ms"] > 0


def test_shared_exchange_across_hosts_is_refused_in_one_line(tmp_path, hosts, launcher):
    res = run_mpi(4, args(tmp_path / "shared", extra=["--exchange", "shared"]), launcher=launcher, hosts=HOSTS,
                  env={**hosts.env, "MULTIGPU_CACHE": str(tmp_path / "cache")}, timeout=180)
    assert res.returncode == 2, res.stderr[-3000:]
    errors = [line for line in res.stderr.splitlines() if line.startswith("multigpu: error:")]
    assert len(errors) == 1 and "--exchange shared needs every rank on one host" in errors[0], res.stderr[-2000:]


def test_a_host_dying_mid_run_ends_the_job_with_every_whole_frame_kept(tmp_path, hosts, launcher):
    """Host b's namespace killed mid-run: the MPI runtime tears the job down (MPICH at once,
    Open MPI within seconds) long before ``--liveness``; no rank is left, the exit code is 1
    through ``python -m multigpu.launcher.mpirun``, timings.csv holds whole frames only and
    summary.json is rewritten from them, saying what happened."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    from mpirun import ROOT

    from multigpu.records.report import COLUMNS, read_timings

    out, liveness = tmp_path / "o", 20
    env = {**os.environ, **hosts.env, "MULTIGPU_CACHE": str(tmp_path / "cache"), "MULTIGPU_MPIEXEC": launcher.path,
           "LP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "multigpu.launcher.mpirun", "-n", "4", "--hosts", "a:2,b:2",
           *args(out, frames=100000, extra=["--mosaic-every", "0", "--liveness", str(liveness)])]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        csv, t = out / "timings.csv", time.monotonic()
        while not (csv.exists() and csv.read_text().count("\n") > 1 + 4 * 60):
            assert proc.poll() is None and time.monotonic() - t < 120, proc.communicate()[1][-3000:]
            time.sleep(0.2)
        assert hosts.processes("b"), "no rank on host b"
        hosts.kill("b")
        t = time.monotonic()
        _, err = proc.communicate(timeout=liveness + 30)
        took = time.monotonic() - t
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 1 and took < liveness, (proc.returncode, took, err[-3000:])
    assert "summary.json rewritten from the" in err, err[-3000:]
    left, t = hosts.processes("a") + hosts.processes("b"), time.monotonic()
    while left and time.monotonic() - t < 10:  # the runtime's last processes finish leaving
        time.sleep(0.2)
        left = hosts.processes("a") + hosts.processes("b")
    assert not left, [Path(f"/proc/{p}/cmdline").read_bytes()[:200] for p in left]  # no rank left behind
    rows = read_timings(csv)
    frame = rows[:, COLUMNS.index("frame")]
    assert len(rows) % 4 == 0 and (frame == np.repeat(np.arange(len(rows) // 4), 4)).all()  # whole frames
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and s["frames"] == s["frames_written"] == len(rows) // 4 > 60
    assert "ended abnormally" in s["stopped_by"]


@pytest.mark.parametrize("extra", [["--balance", "cross", "--mullion", "6x4", "--latency", "2"],
                                   ["--decomposition", "db", "--latency", "0"],
                                   ["--decomposition", "hybrid", "--mullion", "6x4"]])
def test_pixels_between_hosts_cross_the_link_compressed_and_compose_exactly(tmp_path, hosts, launcher, extra):
    """What crosses PCs crosses their links (the links' own counters), zstd-compressed by default,
    and the wall is the one-rank render bit for bit: with bezels and frames in flight, sort-first
    and sort-last; ``--compress none`` puts the raw pixels on the same links."""
    cache = {"MULTIGPU_CACHE": str(tmp_path / "cache")}
    tw, th = 160, 120  # pieces above the size below which they go raw (core/wire.py: LEAST)
    extra = [*extra, "--tile", f"{tw}x{th}"]
    walls, onlink = {}, {}
    for compress in ("auto", "none"):
        out = tmp_path / compress
        before = hosts.wire()
        res = run_mpi(4, args(out, extra=[*extra, "--compress", compress]), env={**hosts.env, **cache},
                      launcher=launcher, hosts=HOSTS, timeout=180)
        assert res.returncode == 0, res.stderr[-3000:]
        after = hosts.wire()
        onlink[compress] = sum(after[h][0] - before[h][0] for h in after)  # what the hosts sent on their links
        walls[compress] = json.loads((out / "summary.json").read_text())
    auto, raw = walls["auto"], walls["none"]
    assert auto["config"]["compress"] == "zstd:1 between PCs" and raw["config"]["compress"] == "none"
    assert 0 < auto["wire"]["bytes_per_frame"] < raw["wire"]["bytes_per_frame"] / 2
    sent_raw = raw["wire"]["bytes_per_frame"] * raw["frames"]
    assert onlink["none"] >= sent_raw  # the messages took the network, not this machine's shared memory
    assert onlink["auto"] < onlink["none"] - sent_raw / 2
    mull = extra[extra.index("--mullion") + 1] if "--mullion" in extra else "0x0"
    mx, my = (int(v) for v in mull.split("x"))
    ref = run_mpi(1, [*args(tmp_path / "one"), "--grid", "1x1", "--tile", f"{2 * tw + mx}x{2 * th + my}"], env=cache)
    assert ref.returncode == 0, ref.stderr[-3000:]
    shown = np.ones((2 * th + my, 2 * tw + mx), bool)  # the canvas but the pixels behind the bezels (black)
    shown[:, tw:tw + mx] = shown[th:th + my, :] = False
    for compress in ("auto", "none"):
        for f, (got, want) in enumerate(zip(frames_of(tmp_path / compress), frames_of(tmp_path / "one"))):
            assert got.shape == want.shape and (got[shown] == want[shown]).all(), \
                f"{compress} frame {f}: {(got != want)[shown].any(axis=-1).sum()} px"


def test_a_time_series_on_two_hosts_shows_every_step_at_its_frame_like_one_rank(tmp_path, hosts, launcher):
    """A simulation's time series across hosts: a step a frame, every rank on either host swapping
    it in at the same frame (``--late-step wait``: each at its own frame), each step built once for
    both hosts (the cache is shared, its build locked), the wall equal to one rank's render."""
    from test_series import write_series

    write_series(tmp_path / "series", 4)
    flags = ["--model", str(tmp_path / "series" / "run.pvd"), "--color-by", "height", "--steps-per-second", "30",
             "--late-step", "wait", "--path-kind", "orbit"]
    env = {**hosts.env, "MULTIGPU_CACHE": str(tmp_path / "cache")}
    res = run_mpi(4, args(tmp_path / "wall", frames=6, extra=flags), env=env, launcher=launcher, hosts=HOSTS,
                  timeout=180)
    assert res.returncode == 0, res.stderr[-3000:]
    ref = run_mpi(1, [*args(tmp_path / "one", frames=6, extra=flags), "--grid", "1x1", "--tile", f"{W}x{H}"],
                  env={"MULTIGPU_CACHE": str(tmp_path / "cache")})
    assert ref.returncode == 0, ref.stderr[-3000:]
    want = frames_of(tmp_path / "one", 6)
    assert all((want[f] != want[f + 1]).any() for f in range(5))  # a step a frame
    for f, (got, one) in enumerate(zip(frames_of(tmp_path / "wall", 6), want)):
        assert (got == one).all(), f"frame {f}: {(got != one).any(axis=2).sum()} px"
    assert json.loads((tmp_path / "wall" / "summary.json").read_text())["series"]["step_changes"] == 5
