"""Bad input ends the whole job with one clear line; a failing rank ends it fast; nothing lost."""

import csv
import json
import time

import pytest

from mpirun import SMALL, run_mpi

pytestmark = pytest.mark.mpi


@pytest.mark.parametrize("flags,needle", [
    (["--strips", "1"], "--strips must be >= 2"),
    (["--tile", "0x5"], "--tile must be positive"),
    (["--grid", "two"], "--grid must look like"),
    (["--frames", "0"], "--frames must be >= 1"),
    (["--balance", "magic"], "--balance must be one of"),
    (["--model", "/nonexistent/m.obj"], "file not found"),
    (["--path", "/nonexistent/p.json"], "path file not found"),
    (["--out", "/proc/multigpu-cannot-write"], "not writable"),
    (["--device", "99"], "--device 99"),
    (["--subfrustum", "tiles"], "--subfrustum must be one of"),
    (["--partition", "gossip"], "--partition must be 'redundant' or 'broadcast'"),
    (["--cluster", "-3"], "--cluster must be >= 0"),
    (["--offset", "1e8,x"], "--offset must look like X,Y,Z"),
    (["--offset", "1e300,0,0"], "--offset must be three finite numbers"),
    (["--tile", "16384x64", "--subfrustum", "scissor"], "exceeds this GL's maximum framebuffer"),
])
def test_bad_input_matrix(tmp_path, flags, needle):
    args = ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "2", "--out", str(tmp_path / "o"), *flags]
    args = args[:args.index("--grid")] + args[args.index("--grid") + 2:] if "--grid" in flags else args
    res = run_mpi(2, args, timeout=90)
    assert res.returncode != 0
    assert needle in res.stderr, res.stderr[-2000:]
    assert "Traceback" not in res.stderr
    assert res.stderr.count("multigpu: error:") == 1


def test_corrupt_model_and_bad_path_file(tmp_path):
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"glTF\x02\x00\x00\x00garbage")
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--model", str(bad), "--out", str(tmp_path / "o")])
    assert res.returncode != 0 and "bad.glb" in res.stderr and "Traceback" not in res.stderr
    p = tmp_path / "p.json"
    p.write_text(json.dumps({"keyframes": [{"position": [0, 0, 0]}]}))
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--path", str(p), "--out", str(tmp_path / "o")])
    assert res.returncode != 0 and "missing the field 'target'" in res.stderr


def test_exception_on_one_rank_ends_job_and_keeps_frames(tmp_path):
    out = tmp_path / "o"
    t = time.monotonic()
    res = run_mpi(3, ["walkthrough", *SMALL, "--grid", "1x3", "--frames", "40", "--mosaic-every", "0",
                      "--out", str(out)], timeout=60, env={"MULTIGPU_FAULT": "1:6"})
    assert time.monotonic() - t < 30
    assert res.returncode != 0
    assert "rank 1: RuntimeError: injected fault at frame 6" in res.stderr
    with open(out / "timings.csv") as fh:
        rows = list(csv.DictReader(fh))
    frames = {int(r["frame"]) for r in rows}
    assert set(range(6)) <= frames and len(rows) >= 6 * 3
    s = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else None
    assert s is None or s["complete"] is False


def _start(args, tmp_path):
    import os
    import signal
    import subprocess
    import sys

    from mpirun import MPIEXEC, ROOT

    cmd = [MPIEXEC, "-n", "2", sys.executable, "-m", "mpi4py", "-m", "multigpu", "walkthrough", *SMALL,
           "--grid", "1x2", "--mosaic-every", "0", "--out", str(tmp_path / "o"), *args]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env={**os.environ, "LP_NUM_THREADS": "1"})
    return proc, lambda: os.killpg(proc.pid, signal.SIGKILL)


def _wait_for_frames(path, n, limit=60):
    t = time.monotonic()
    while time.monotonic() - t < limit:
        if path.exists() and sum(1 for _ in open(path)) > n:
            return
        time.sleep(0.2)
    raise AssertionError("the run produced no frames")


def test_sigterm_stops_cleanly_with_complete_outputs(tmp_path):
    import signal

    proc, kill = _start([], tmp_path)
    try:
        _wait_for_frames(tmp_path / "o" / "timings.csv", 10)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            kill()
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["complete"] is False and 0 < s["frames"] < 1200
    with open(tmp_path / "o" / "timings.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * s["frames"]  # every written frame is complete
    assert "stopped after" in out


def test_sigkill_of_one_rank_ends_the_job(tmp_path):
    import os
    import signal
    import subprocess

    proc, kill = _start(["--timeout", "10"], tmp_path)
    try:
        _wait_for_frames(tmp_path / "o" / "timings.csv", 6)
        pids = subprocess.run(["pgrep", "-f", "-s", str(proc.pid), "mpi4py -m multigpu"], capture_output=True,
                              text=True).stdout.split()
        assert pids
        os.kill(int(pids[-1]), signal.SIGKILL)
        proc.communicate(timeout=40)
    finally:
        if proc.poll() is None:
            kill()
    assert proc.returncode != 0
