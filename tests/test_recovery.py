"""Recovery by relaunch, its pure parts (records/recovery.py, launcher/segments.py, the
launcher's command-line handling): where a run resumes, the summary's recoveries, the sweep of
left-over shared-memory segments. In one process, no MPI."""

import json
import os
import time

import numpy as np

from multigpu.launcher.mpirun import restart_bound
from multigpu.launcher.relaunch import _without, with_flight
from multigpu.launcher.segments import sweep
from multigpu.records import recovery
from multigpu.records.report import COLUMNS, TimingWriter, read_timings


def timings(out, frames: int, ranks: int, extra: str = ""):
    """A timings.csv of ``frames`` whole frames of ``ranks`` rows, then ``extra`` bytes."""
    out.mkdir(exist_ok=True)
    w = TimingWriter(out / "timings.csv")
    for f in range(frames):
        rows = np.zeros((ranks, len(COLUMNS)))
        rows[:, COLUMNS.index("frame")], rows[:, COLUMNS.index("rank")] = f, np.arange(ranks)
        w.write(rows)
    w.close()
    with open(out / "timings.csv", "a") as fh:
        fh.write(extra)


def test_a_run_resumes_after_its_last_whole_frame(tmp_path):
    timings(tmp_path, 7, 3)
    whole = (tmp_path / "timings.csv").read_bytes()
    partial = whole.splitlines(keepends=True)[1]  # a row of frame 0, as if frame 7 were half-written
    (tmp_path / "timings.csv").write_bytes(whole + partial.replace(b"0,", b"7,", 1) + b"7,1,0,0")
    assert recovery.resume_point(tmp_path, 3) == 7
    assert (tmp_path / "timings.csv").read_bytes() == whole  # the half-written frame is gone
    assert recovery.resume_point(tmp_path, 3, recorded=5) == 5  # a --record flight of 5 frames
    assert read_timings(tmp_path / "timings.csv")[:, 0].max() == 4


def test_the_tail_is_enough_for_a_long_run_and_an_empty_one_resumes_at_zero(tmp_path, monkeypatch):
    monkeypatch.setattr(recovery, "TAIL", 2000)  # far less than the file: only its end is read
    timings(tmp_path, 400, 2)
    assert recovery.resume_point(tmp_path, 2) == 400
    assert recovery.resume_point(tmp_path, 2, recorded=10) == 10  # not in the tail: the whole file is read
    (tmp_path / "e").mkdir()
    timings(tmp_path / "e", 0, 2)
    assert recovery.resume_point(tmp_path / "e", 2) == 0
    assert recovery.resume_point(tmp_path / "missing", 2) == 0


def test_the_summary_counts_each_recovery_and_its_dark_time(tmp_path, monkeypatch):
    timings(tmp_path, 3, 1)
    history = recovery.failure(3, "rank 1 died", [], recovery.last_shown_at(tmp_path))
    assert history[0]["resumed_at"] == 3 and history[0]["last_shown"] == 2 and history[0]["frames_lost"] == 0
    history[0]["last_shown_at"] = time.time() - 2.0
    monkeypatch.setenv(recovery.ENV, json.dumps(history))
    r = recovery.Recovery.resumed(3)
    assert r.doc()["recovery_count"] == 1 and r.doc()["recovery_seconds_max"] is None  # not back yet
    r.shown(3)
    doc = r.doc()
    assert 1.9 < doc["recoveries"][0]["seconds"] < 5 and doc["recovery_seconds_max"] == doc["recoveries"][0]["seconds"]
    assert recovery.Recovery.resumed(0).doc() == {}  # a run that never failed says nothing
    again = [{**history[0], "seconds": None}, *recovery.failure(3, "again", [], time.time() - 1.0)]
    monkeypatch.setenv(recovery.ENV, json.dumps(again))  # a restart that failed before its first frame
    r = recovery.Recovery.resumed(3)
    r.shown(3)
    assert r.doc()["recovery_count"] == 2 and r.doc()["recovery_seconds_max"] == r.doc()["recoveries"][1]["seconds"]


def test_restarts_are_on_with_windows_and_off_headless():
    assert restart_bound(["walkthrough", "--present", "window"]) == 3
    assert restart_bound(["walkthrough"]) == 0
    assert restart_bound(["walkthrough", "--present", "window", "--recover", "0"]) == 0
    assert restart_bound(["walkthrough", "--recover=5"]) == 5
    assert restart_bound(["wall", "test", "w.json"]) == 0
    assert _without(["a", "--resume-at", "5", "b", "--resume-at=7"], "--resume-at") == ["a", "b"]


def test_the_sweep_removes_unmapped_segments_of_the_job_only(tmp_path):
    start = time.time()
    old = tmp_path / "mpich_shm_old_0"
    old.write_bytes(b"x")
    os.utime(old, (start - 3600, start - 3600))  # an earlier job's: not ours to judge
    left = tmp_path / "mpich_shm_left_0"
    left.write_bytes(b"x")
    other = tmp_path / "notes.txt"
    other.write_text("x")
    mapped = tmp_path / "vader_segment.busy"
    mapped.write_bytes(b"\0" * 4096)
    import mmap

    with open(mapped, "r+b") as fh, mmap.mmap(fh.fileno(), 4096):  # a live job's segment
        assert sweep(start, tmp_path) == ["mpich_shm_left_0"]
    assert old.exists() and other.exists() and mapped.exists() and not left.exists()


def test_the_statistics_panel_tells_the_operator_of_a_restart():
    from multigpu.display.hud import stats_panel

    args = (60.0, "auto", np.ones((4, 3)), np.full(4, 100.0), "path")
    plain, told = stats_panel(*args), stats_panel(*args, restarts=2)
    orange = lambda img: ((img[..., 0] > 200) & (img[..., 1] > 120) & (img[..., 1] < 200) & (img[..., 2] < 100)).sum()
    assert told.shape[0] > plain.shape[0] and orange(told[plain.shape[0] - 4:]) > 20  # its own last line


def test_a_restarted_flight_starts_where_its_record_ends(tmp_path):
    from multigpu.config import WalkConfig
    from multigpu.rank.walkthrough import make_path
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.pathfile import PathAppender

    flight = tmp_path / "flight.json"
    cams = np.array([[0, 0, 5 + i, 0, 0, 0, 0, 1, 0, 60, 0.1, 100] for i in range(3)], dtype=float)
    PathAppender(flight).append(cams)
    scene, _ = load_scene(SceneSpec(triangles=20_000))
    cfg = WalkConfig(path="interactive", present="window", record=str(flight), resume_at=3, offset=(1.0, 0.0, 0.0))
    start = make_path(cfg, scene).camera(0)
    assert np.allclose(start.position, [1, 0, 7]) and np.allclose(start.target, [1, 0, 0])  # the last, moved
    fresh = make_path(WalkConfig(path="interactive", present="window", record=str(flight)), scene).camera(0)
    assert not np.allclose(fresh.position, [0, 0, 7])  # a new flight starts where its path kind starts


def test_an_interactive_flight_that_can_restart_records_itself(tmp_path):
    fly = ["walkthrough", "--path", "interactive", "--present", "window"]
    assert with_flight(fly, tmp_path) == [*fly, "--record", str(tmp_path / "flight.json")]
    assert with_flight([*fly, "--record", "mine.json"], tmp_path) == [*fly, "--record", "mine.json"]
    assert with_flight(["walkthrough"], tmp_path) == ["walkthrough"]


def _job_of_two_ranks(tmp_path, summary: dict):
    """A stand-in job: a session whose two children carry ``mpi4py`` on their command line, an
    output folder with a fresh timings.csv and ``summary``."""
    import subprocess
    import sys

    out = tmp_path / "o"
    out.mkdir()
    started = time.time()
    from multigpu.records.report import COLUMNS

    (out / "timings.csv").write_text(",".join(COLUMNS) + "\n" + ",".join("0" * len(COLUMNS)) + "\n")
    (out / "summary.json").write_text(json.dumps(summary))
    sleeper = f"{sys.executable} -c 'import time; time.sleep(30)' mpi4py"
    proc = subprocess.Popen(["bash", "-c", f"{sleeper} & {sleeper} & wait"], start_new_session=True)
    return proc, out, started


def _two_ranks(root: int) -> list[int]:
    """The stand-in job's two rank pids, once both have started (bounded)."""
    from multigpu.launcher.supervise import _local_ranks

    for _ in range(100):
        ranks = _local_ranks(root)
        if len(ranks) == 2:
            return ranks
        time.sleep(0.05)
    return ranks


def test_the_launcher_ends_a_job_whose_local_rank_died(tmp_path):
    """A rank of this host gone while the frames run and rank 0's record open: the launcher kills
    the job's session itself (Open MPI's own teardown took 2.6 s), and only then."""
    import signal
    import threading

    from multigpu.launcher.supervise import _wait

    proc, out, started = _job_of_two_ranks(tmp_path, {"complete": False})
    try:
        ranks = _two_ranks(proc.pid)
        assert len(ranks) == 2
        threading.Timer(0.5, lambda: os.kill(ranks[0], signal.SIGKILL)).start()
        t = time.monotonic()
        code = _wait(proc, out, started)
        assert time.monotonic() - t < 10 and code == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def test_the_launcher_leaves_a_job_whose_record_is_closed(tmp_path):
    """After rank 0 closed its record (a stop, the end), ranks leave in their own time: a rank
    gone then ends nothing."""
    import os
    import signal
    import threading

    from multigpu.launcher.supervise import _gone, _wait

    proc, out, started = _job_of_two_ranks(tmp_path, {"complete": False, "stopped_by": "escape key"})
    try:
        ranks = _two_ranks(proc.pid)
        os.kill(ranks[0], signal.SIGKILL)
        waiting = threading.Thread(target=_wait, args=(proc, out, started), daemon=True)
        waiting.start()
        time.sleep(1.5)
        assert proc.poll() is None and not _gone(ranks[1])  # nothing killed
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def test_a_ranks_own_child_ending_or_a_job_before_its_frames_ends_nothing(tmp_path):
    """A fork of a rank (it carries the rank's command line until it execs: ctypes' library
    search, an encoder) that ends is no rank's death; nor is a rank gone before any row."""
    import os
    import signal
    import subprocess
    import sys
    import threading

    from multigpu.launcher.supervise import _frames_running, _local_ranks, _wait
    from multigpu.records.report import COLUMNS

    out = tmp_path / "o"
    out.mkdir()
    started = time.time()
    (out / "timings.csv").write_text(",".join(COLUMNS) + "\n")
    (out / "summary.json").write_text(json.dumps({"complete": False}))
    assert not _frames_running(out, started)  # the header alone: setup, not frames
    (out / "timings.csv").write_text(",".join(COLUMNS) + "\n" + ",".join("0" * len(COLUMNS)) + "\n")
    assert _frames_running(out, started)
    code = "import os, time\nif os.fork() == 0:\n    time.sleep(0.6)\n    os._exit(0)\ntime.sleep(30)\n"
    proc = subprocess.Popen(["bash", "-c", f"{sys.executable} -c '{code}' mpi4py & wait"], start_new_session=True)
    try:
        for _ in range(100):
            if _local_ranks(proc.pid):
                break
            time.sleep(0.05)
        assert len(_local_ranks(proc.pid)) == 1  # the rank, not its fork
        threading.Thread(target=_wait, args=(proc, out, started), daemon=True).start()
        time.sleep(1.5)  # the fork has ended
        assert proc.poll() is None  # nothing killed
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def test_a_standby_is_for_a_job_on_one_host_and_waits_for_its_go(tmp_path):
    """--standby: refused with --hosts (rank 0 reads the launcher's go file); the ranks' side
    gives a go's frame and recoveries to the restarted job, and a quit ends the standby."""
    import argparse
    import threading

    import pytest

    from multigpu.errors import InputError
    from multigpu.launcher.mpirun import find_launcher
    from multigpu.launcher.relaunch import _standby
    from multigpu.rank import standby

    with pytest.raises(InputError, match="--standby works for a job on one host"):
        _standby(find_launcher(), 2, ["walkthrough", "--standby"], [("pc1", 1), ("pc2", 1)], tmp_path)
    assert _standby(find_launcher(), 2, ["walkthrough"], None, tmp_path) is None

    class _Done:  # a request that is complete
        @staticmethod
        def Testall(requests):
            return True

    class _Comm:  # one rank: the broadcasts are its own
        def Get_rank(self):
            return 0

        def Ibcast(self, buf, root=0):
            return _Done()

    def say(go, what: str) -> None:  # as the launcher writes it: whole, by a rename
        tmp = go.with_suffix(".tmp")
        tmp.write_text(what)
        os.replace(tmp, go)

    go = tmp_path / "go.json"
    threading.Timer(0.2, say, (go, json.dumps({"resume_at": 42, "history": [{"reason": "x"}]}))).start()
    got = standby.wait_for_go(_Comm(), str(go))
    args = argparse.Namespace(resume_at=0)
    standby.go(args, got)
    assert args.resume_at == 42 and json.loads(os.environ.pop(recovery.ENV)) == [{"reason": "x"}]
    go = tmp_path / "quit.json"  # the run ended another way: the standby ends quietly
    threading.Timer(0.2, say, (go, json.dumps({"quit": True}))).start()
    assert standby.wait_for_go(_Comm(), str(go)) == {"quit": True}
    gone = tmp_path / "gone"  # the launcher went and took its folder: nothing will come, the standby ends
    gone.mkdir()
    threading.Timer(0.2, gone.rmdir).start()
    assert standby.wait_for_go(_Comm(), str(gone / "go.json")) == {"quit": True}
    for bad in ("[]", '{"resume_at": "x", "history": []}', "{", '{"resume_at": 1' + "0" * 400 + ', "history": []}'):
        go = tmp_path / "bad.json"  # defect 12: once parsed outside the error path (a traceback)
        say(go, bad)
        with pytest.raises(InputError, match=f"MULTIGPU_STANDBY {go}: "):
            standby.wait_for_go(_Comm(), str(go))


def test_a_stray_standby_setting_is_refused_not_waited_on(monkeypatch):
    """Defect 12: a MULTIGPU_STANDBY left in the environment made any walk wait forever, without a word."""
    import pytest

    from multigpu.errors import InputError
    from multigpu.rank import standby

    monkeypatch.setenv(standby.ENV, "/nonexistent-folder/go.json")
    with pytest.raises(InputError, match="only the launcher's --standby sets it"):
        standby.standing_by()
    monkeypatch.delenv(standby.ENV)
    assert standby.standing_by() is None


def test_a_job_that_missed_the_signal_is_ended_by_the_launcher(monkeypatch, capsys):
    """A rank still starting when Ctrl-C came (a restart's, before its handler) ignores it: the
    launcher ends the job once it has not stopped within its grace, never a wall left running."""
    import signal
    import sys

    from multigpu.launcher import supervise

    monkeypatch.setattr(supervise, "STOP_GRACE", 0.5)
    proc = supervise.start_job([sys.executable, "-c", "import signal, time; signal.signal(signal.SIGINT, "
                                "signal.SIG_IGN); print('up', flush=True); time.sleep(60)"], dict(os.environ))
    try:
        time.sleep(0.5)
        os.killpg(proc.pid, signal.SIGINT)  # ignored, as a rank without its handler yet
        supervise._end_unless_stopped(proc, signal.SIGINT)
        assert proc.poll() is not None and "did not stop within 0.5 s of SIGINT" in capsys.readouterr().err
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
