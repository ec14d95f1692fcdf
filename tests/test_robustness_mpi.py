"""Bad input ends the whole job with one clear line; a failing rank ends it fast; nothing lost."""

import csv
import json
import os
import signal
import time
from pathlib import Path

import pytest
from mpirun import SMALL, run_mpi, start_mpi

from multigpu.config import WalkConfig
from multigpu.records.report import read_timings

pytestmark = pytest.mark.mpi
LATENCY = WalkConfig().latency  # frames in flight by default: a rank stopped at frame f leaves f - LATENCY shown


def test_corrupt_model_and_bad_path_file(tmp_path):
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"glTF\x02\x00\x00\x00garbage")
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--model", str(bad), "--out", str(tmp_path / "o")])
    assert res.returncode != 0 and "bad.glb" in res.stderr and "Traceback" not in res.stderr
    p = tmp_path / "p.json"
    p.write_text(json.dumps({"keyframes": [{"position": [0, 0, 0]}]}))
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--path", str(p), "--out", str(tmp_path / "o")])
    assert res.returncode != 0 and "missing the field 'target'" in res.stderr


def _rows(out):
    with open(out / "timings.csv") as fh:
        return list(csv.DictReader(fh))


def _summary_matches_csv(out):
    """summary.json describes exactly the whole frames in timings.csv."""
    s = json.loads((out / "summary.json").read_text())
    frames = {int(r["frame"]) for r in _rows(out)}
    assert s["frames"] == len(frames) == s["frames_written"]
    assert frames == set(range(len(frames)))
    read_timings(out / "timings.csv")  # parses: whole rows only
    return s


def _segments() -> set[str]:
    """The shared exchange's segment files in /dev/shm (``multigpu-PID-HEX``)."""
    return {p.name for p in Path("/dev/shm").glob("multigpu-*")} if Path("/dev/shm").is_dir() else set()


def _leaked(before: set[str], grace: float = 10.0) -> list[str]:
    """Segment files made since ``before`` still there once their makers are gone (a rank can
    outlive its ``mpiexec`` by a moment; one alive after ``grace`` seconds is another job's)."""
    new = _segments() - before
    end = time.monotonic() + grace
    while time.monotonic() < end and any(Path(f"/proc/{n.split('-')[1]}").exists() for n in new):
        time.sleep(0.1)
    return sorted(n for n in new & _segments() if not Path(f"/proc/{n.split('-')[1]}").exists())


@pytest.mark.parametrize("latency", [0, 1, 2])
@pytest.mark.parametrize("failing", [0, 1])
def test_exception_on_one_rank_ends_job_and_keeps_frames(tmp_path, failing, latency):
    """The job ends fast with the failing rank's error, the frames every rank showed kept (with N
    frames in flight, N fewer: drawn, never shown); its shared segment was unlinked at setup,
    so nothing is left in /dev/shm."""
    out = tmp_path / "o"
    before = _segments()
    t = time.monotonic()
    res = run_mpi(3, ["walkthrough", *SMALL, "--grid", "1x3", "--frames", "40", "--mosaic-every", "0",
                      "--latency", str(latency), "--out", str(out)], timeout=60,
                  env={"MULTIGPU_FAULT": f"{failing}:6"})
    assert time.monotonic() - t < 30
    assert res.returncode != 0
    assert res.stderr.count("injected fault at frame 6") == 1, res.stderr
    assert f"rank {failing}: RuntimeError: injected fault at frame 6" in res.stderr
    s = _summary_matches_csv(out)
    assert s["complete"] is False and s["frames"] == 6 - latency and "injected fault" in s["stopped_by"]
    assert s["config"]["exchange"] == "shared" and not _leaked(before)


def test_failed_rerun_leaves_no_stale_summary_or_mosaics(tmp_path):
    out = tmp_path / "o"
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "8", "--mosaic-every", "1",
                      "--out", str(out)], timeout=90)
    assert res.returncode == 0 and json.loads((out / "summary.json").read_text())["complete"] is True
    (out / "mine.txt").write_text("not a run output")
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "8", "--mosaic-every", "2",
                      "--out", str(out)], timeout=90, env={"MULTIGPU_FAULT": f"1:{3 + LATENCY}"})
    assert res.returncode != 0
    s = _summary_matches_csv(out)
    assert s["complete"] is False and s["frames"] == 3
    pngs = sorted(p.name for p in (out / "mosaic").glob("frame_*.png"))
    assert pngs == ["frame_00000.png", "frame_00000_partition.png", "frame_00002.png", "frame_00002_partition.png"]
    assert (out / "mine.txt").read_text() == "not a run output"  # only the run's own files are replaced
    assert not list(out.glob(".*.tmp")) and not list((out / "mosaic").glob(".*tmp*"))


def test_bad_input_leaves_no_new_directory_and_old_outputs_alone(tmp_path):
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--seed", "3", "--balance", "magic",
                      "--out", str(tmp_path / "new" / "o")])
    assert res.returncode == 2 and not (tmp_path / "new" / "o").exists()
    out = tmp_path / "o"
    assert run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "3", "--out", str(out)]).returncode == 0
    before = (out / "summary.json").read_text()
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--path", str(tmp_path / "none.json"),
                      "--out", str(out)])
    assert res.returncode == 2 and (out / "summary.json").read_text() == before


@pytest.mark.parametrize("flags,needle", [
    (["--seed", "-1"], "--seed must be >= 0, got -1"),
    (["--model", "/nonexistent/m.obj"], "--model /nonexistent/m.obj: model file not found"),
    (["--tile", "16384x64", "--subfrustum", "scissor"], "exceeds this GL's maximum framebuffer"),
    (["--bogus-flag"], "unrecognized arguments: --bogus-flag"),
    (["--grid", "1x3"], "needs 3 ranks but the job has 2"),
])
def test_errors_print_once_and_exit_together(tmp_path, flags, needle):
    """Every rank hits these: one line on stderr, exit 2, no MPI_Abort banner."""
    args = ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "2", "--out", str(tmp_path / "o")]
    if "--grid" in flags:
        args = args[:args.index("--grid")] + args[args.index("--grid") + 2:]
    res = run_mpi(2, args + flags, timeout=60)
    assert res.returncode == 2
    assert res.stderr.count(needle) == 1, res.stderr
    assert "Abort(" not in res.stderr and "Traceback" not in res.stderr


def test_video_with_several_ranks(tmp_path):
    out = tmp_path / "o"
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "4", "--video", "--mosaic-every", "0",
                      "--timeout", "30", "--out", str(out)], timeout=90)
    assert res.returncode == 0, res.stderr[-2000:]
    assert (out / "mosaic.mp4").stat().st_size > 1000
    import imageio.v2 as imageio

    with imageio.get_reader(str(out / "mosaic.mp4")) as r:
        assert sum(1 for _ in r) == 4


@pytest.mark.slow
def test_rank_stalled_in_setup_ends_the_job(tmp_path):
    """A rank frozen (SIGSTOP) before the first agreement: the others notice its silence."""
    out = tmp_path / "o"
    t = time.monotonic()
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "5", "--liveness", "3", "--out", str(out)],
                  timeout=60, env={"MULTIGPU_FAULT": "1:setup:stop"})
    assert time.monotonic() - t < 20
    assert res.returncode != 0
    assert res.stderr.count("rank 1 stopped responding") == 1, res.stderr
    assert not out.exists()  # refused before any frame: no directory left behind


@pytest.mark.slow
def test_rank_stalled_mid_run_ends_job_within_default_liveness(tmp_path):
    """Default settings: a frozen rank ends the job in about 30 s (not the 120 s frame timeout),
    and rank 0 keeps every whole frame."""
    out = tmp_path / "o"
    t = time.monotonic()
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "50", "--mosaic-every", "0",
                      "--out", str(out)], timeout=90, env={"MULTIGPU_FAULT": "1:4:stop"})
    took = time.monotonic() - t
    assert res.returncode != 0 and took < 45, (took, res.stderr)
    assert "rank 1 stopped responding (no heartbeat for 30 s)" in res.stderr
    s = _summary_matches_csv(out)
    assert s["complete"] is False and s["frames"] in _kept(4)


def _kept(f: int) -> set:
    """The frames a rank frozen as it starts frame ``f`` leaves: every frame all ranks showed; with
    frames in flight under Open MPI (messages move only inside MPI calls) the frozen rank may keep
    its last row, and that frame with it."""
    from multigpu.launcher.mpirun import find_launcher

    shown = f - LATENCY
    return {shown, shown - 1} if LATENCY and find_launcher().flavor == "openmpi" else {shown}


def _wait_for_frames(path, n, limit=120):
    t = time.monotonic()
    while time.monotonic() - t < limit:
        if path.exists() and sum(1 for _ in open(path)) > n:
            return
        time.sleep(0.2)
    raise AssertionError("the run produced no frames")


def _start(args, tmp_path, env=None):
    return start_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--mosaic-every", "0", "--out", str(tmp_path / "o"),
                         *args], env=env)


def _expected_signal_exit(sig):
    """(exit code, signal the ranks see): MPICH's mpiexec forwards the signal and returns the
    ranks' 128 + signal; Open MPI's forwards Ctrl-C as SIGTERM and returns 1 itself."""
    from multigpu.launcher.mpirun import find_launcher

    if find_launcher().flavor == "openmpi":
        return 1, signal.SIGTERM
    return 128 + sig, sig


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_cleanly_with_complete_outputs_and_nonzero_exit(tmp_path, sig):
    code, seen = _expected_signal_exit(sig)
    proc, kill = _start([], tmp_path)
    try:
        _wait_for_frames(tmp_path / "o" / "timings.csv", 10)
        os.killpg(proc.pid, sig)  # as Ctrl-C does: the launcher and every rank
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            kill()
    assert proc.returncode == code, err
    s = _summary_matches_csv(tmp_path / "o")
    assert s["complete"] is False and 0 < s["frames"] < 1200 and s["stopped_by"] == f"signal {seen.name}"
    assert "stopped after" in out


@pytest.mark.slow
def test_ctrl_c_ends_a_job_waiting_on_a_frozen_rank(tmp_path):
    proc, kill = _start(["--liveness", "0"], tmp_path, env={"MULTIGPU_FAULT": "1:5:stop"})
    try:
        _wait_for_frames(tmp_path / "o" / "timings.csv", 2 * min(_kept(5)))
        time.sleep(1.0)
        t = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        took = time.monotonic() - t
    finally:
        if proc.poll() is None:
            kill()
    code, seen = _expected_signal_exit(signal.SIGINT)
    assert took < 10 and proc.returncode == code, (took, proc.returncode, err)
    assert err.count("interrupted by SIG") == (1 if code == 130 else err.count("interrupted by SIG")) <= 1
    frames = _summary_matches_csv(tmp_path / "o")["frames"]
    # Open MPI's daemon continues a SIGSTOPped rank, so there the rank is not frozen for long
    assert frames in _kept(5) if code == 130 else frames >= min(_kept(5))


def test_second_job_on_the_same_out_is_refused(tmp_path):
    proc, kill = _start(["--frames", "100000"], tmp_path)  # still running when the second job starts
    try:
        _wait_for_frames(tmp_path / "o" / "timings.csv", 4)
        res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "3", "--out", str(tmp_path / "o")])
        assert res.returncode == 2
        assert res.stderr.count("multigpu: error:") == 1
        assert f"--out {tmp_path / 'o'}: in use by another multigpu job (pid" in res.stderr
        os.killpg(proc.pid, signal.SIGTERM)
        proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            kill()
    _summary_matches_csv(tmp_path / "o")  # the first job's outputs are intact


@pytest.mark.parametrize("mpi,exchange", [("default", "auto"), ("default", "shared"), ("openmpi", "auto")])
def test_disk_full_keeps_whole_rows_and_no_temp_files(tmp_path, mpi, exchange):
    """RLIMIT_FSIZE makes writes past 20 kB fail (EFBIG, as a full disk gives ENOSPC). The
    shared segment finds no room under that limit, so the job uses messages and says why."""
    import subprocess

    from mpirun import ROOT

    from multigpu.launcher.mpirun import find_launcher, launcher_for, openmpi_on_path

    out = tmp_path / "o"
    if mpi == "openmpi" and openmpi_on_path() is None:
        pytest.skip("no Open MPI mpiexec here (Debian: apt install openmpi-bin)")
    launcher = find_launcher() if mpi == "default" else launcher_for(openmpi_on_path())
    cmd = launcher.command(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "400", "--mosaic-every", "0",
                               "--exchange", exchange, "--out", str(out)])
    py = cmd.index("-m")  # python -m mpi4py ... -> python tests/fsize_limited.py BYTES -m multigpu ...
    cmd[py:py + 2] = [str(ROOT / "tests" / "fsize_limited.py"), "20000"]
    res = subprocess.run(cmd, cwd=ROOT, env=launcher.environ(), capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr  # one line naming the file, the whole job exit 2
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("multigpu")]
    assert errors == [f"multigpu: error: cannot write {out / 'timings.csv'}: File too large; "
                      f"kept {(out / 'timings.csv').stat().st_size} bytes of whole rows"], res.stderr
    assert "Traceback" not in res.stderr and "MPI_Abort" not in res.stderr
    s = _summary_matches_csv(out)
    assert 0 < s["frames"] < 400 and s["complete"] is False
    assert s["stopped_by"] == "an output could not be written (rank 0)"
    assert s["config"]["exchange"] == "messages" and "file-size limit" in s["config"]["exchange_why"]
    assert not [p.name for p in out.rglob(".*") if p.name != ".multigpu.lock"]


def test_sigkill_of_one_rank_ends_the_job(tmp_path):
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


def test_open_mpi_runs_and_refuses_bad_input(tmp_path):
    """With a system Open MPI (Debian's openmpi-bin), the launcher passes what it needs: more
    ranks than cores, root, its own libmpi; outputs equal MPICH's."""
    from multigpu.launcher.mpirun import launcher_for, openmpi_on_path

    found = openmpi_on_path()
    if not found:
        pytest.skip("no Open MPI mpiexec on this machine (Debian: apt install openmpi-bin)")
    ompi = launcher_for(found)
    args = ["walkthrough", *SMALL, "--grid", "2x2", "--tile", "40x32", "--frames", "3", "--mosaic-every", "1",
            "--no-overlay"]
    res = run_mpi(4, [*args, "--out", str(tmp_path / "ompi")], launcher=ompi, timeout=120)
    assert res.returncode == 0, res.stderr[-3000:]
    ref = run_mpi(4, [*args, "--out", str(tmp_path / "mpich")], timeout=120)
    assert ref.returncode == 0
    from mpirun import read_png

    for f in range(3):
        a, b = (read_png(tmp_path / d / "mosaic" / f"frame_{f:05d}.png") for d in ("ompi", "mpich"))
        assert (a == b).all()
    bad = run_mpi(4, [*args, "--seed", "-2", "--out", str(tmp_path / "x")], launcher=ompi, timeout=60)
    assert bad.returncode == 2 and bad.stderr.count("--seed must be >= 0") == 1, bad.stderr


def test_shared_segment_where_asked_and_messages_where_it_cannot_be_made(tmp_path):
    """``MULTIGPU_SHM_DIR`` names where the host's segments are made (the exchange's and, with
    ``--projection shared``, the projection's): a directory of our own holds them during the run and nothing after;
    one that does not exist makes every rank use messages and project every object, the job
    still completes, and summary.json says why in the system's words."""
    seg = tmp_path / "seg"
    seg.mkdir()
    for where, exchange in ((seg, "shared"), (tmp_path / "missing", "messages")):
        out = tmp_path / f"o_{exchange}"
        res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "6", "--mosaic-every", "0",
                          "--projection", "shared", "--out", str(out)], timeout=90,
                         env={"MULTIGPU_SHM_DIR": str(where)})
        assert res.returncode == 0, res.stderr[-2000:]
        s = json.loads((out / "summary.json").read_text())
        assert s["complete"] is True and s["config"]["exchange"] == exchange
        if exchange == "messages":
            assert s["config"]["exchange_why"] == (f"messages: no shared segment (cannot create a segment in {where}: "
                                                   "No such file or directory)")
            # the bounds' projection has no segment either: every rank projects every object
            assert s["config"]["projection"] == "each rank every object"
            assert s["config"]["projection_why"] == f"cannot create a segment in {where}: No such file or directory"
        else:
            assert s["config"]["projection"] == "shared: a slice per rank of 2 on a host"
    assert not list(seg.iterdir())  # both segments unlinked once both ranks had mapped them
