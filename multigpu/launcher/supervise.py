"""The launcher's hold on a job: run ``mpiexec`` in its own session, pass signals on once, map
what it returns to the documented exit codes, and leave nothing behind after a failure. Also
what the launcher reads of a walkthrough's command line (its ``--out``, a flag's value)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from multigpu import exits


def out_dir(argv: list[str]) -> Path | None:
    """The ``--out`` directory of a ``walkthrough`` command line (its default ``out``), else None."""
    if not argv or argv[0] != "walkthrough":
        return None
    from multigpu.config import DEFAULT_OUT

    out = DEFAULT_OUT
    for i, a in enumerate(argv):
        if a == "--out" and i + 1 < len(argv):
            out = argv[i + 1]
        elif a.startswith("--out="):
            out = a.split("=", 1)[1]
    return Path(out)


def flag_value(argv: list[str], flag: str) -> str | None:
    """The value of ``flag`` in a command line (``--flag V`` or ``--flag=V``; the last wins)."""
    value = None
    for i, a in enumerate(argv):
        if a == flag and i + 1 < len(argv):
            value = argv[i + 1]
        elif a.startswith(flag + "="):
            value = a.split("=", 1)[1]
    return value


def _die_with_parent() -> None:
    """In the launcher's child: be sent SIGKILL if this wrapper dies (Linux), so a wrapper
    killed whole by its caller never leaves a job behind in the launcher's own session."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def start_job(cmd: list[str], env: dict) -> subprocess.Popen:
    """The launcher started in a session of its own, killed if this wrapper dies (Linux sends the
    signal when the *thread* that started it ends: start it from a thread that outlives it)."""
    return subprocess.Popen(cmd, env=env, start_new_session=True, preexec_fn=_die_with_parent)


def end_job(proc: subprocess.Popen) -> None:
    """Kill what is left of a job ``start_job`` made and reap it: this host's ranks first (a
    runtime may start them in sessions of their own), then the launcher's session."""
    for pid in _local_ranks(proc.pid):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait()


#: seconds a job has to stop after the launcher passed it a signal (its ranks stop after the frame they
#: are in, their waits within ``rank.job.INTERRUPT_GRACE``) before the launcher ends it
STOP_GRACE = 10.0


def _end_unless_stopped(proc: subprocess.Popen, signum: int) -> None:
    """End the job if it has not stopped ``STOP_GRACE`` seconds after ``signum`` was passed to it:
    a rank that was still starting (a restart's) when the signal came ignores it, and would keep
    the wall running."""
    try:
        proc.wait(STOP_GRACE)
    except subprocess.TimeoutExpired:
        print(f"multigpu: the job did not stop within {STOP_GRACE:g} s of {signal.Signals(signum).name}: "
              "ending it", file=sys.stderr, flush=True)
        end_job(proc)


def supervise(cmd: list[str], env: dict, out: Path | None, name: str = "mpiexec", started_job=None,
              proc: subprocess.Popen | None = None) -> int:
    """Run the launcher, pass it SIGINT/SIGTERM/SIGHUP exactly once each, and return the
    documented exit code whichever MPI runs the job: 0 done, 2 bad input, 128 + signal when a
    signal stopped it (Open MPI's mpiexec itself returns 1 there), 1 any failure (MPICH's
    mpiexec returns 255 when a host dies, Open MPI's 9 or 1). If the runtime
    killed rank 0 before it closed its record (a host died), summary.json is rewritten from
    the whole frames in timings.csv and one line says so. After a failure nothing of the job is
    left: its process session is killed and its shared-memory segments swept (``segments``).
    ``started_job``: called with the launcher's process once it runs (``relaunch``'s watch).
    ``proc``: a job already started (a standby handed the restart), supervised from now."""
    started = time.time()
    if proc is None:
        proc = start_job(cmd, env)
    if started_job is not None:
        started_job(proc)
    got: list[int] = []

    def forward(signum, _frame):
        got.append(signum)
        try:
            os.killpg(proc.pid, signum)  # the launcher and every local rank, as a terminal's Ctrl-C
        except ProcessLookupError:
            pass
        if len(got) == 1:  # a rank that missed it (sent before its handler, as a restart starts) ends anyway
            threading.Thread(target=_end_unless_stopped, args=(proc, signum), daemon=True).start()

    old = {s: signal.signal(s, forward) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        code = _wait(proc, out, started)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # what is left of the job's session (a rank the runtime missed)
        except (ProcessLookupError, PermissionError):
            pass
    code = exits.by_signal(-code) if code < 0 else code
    if code == exits.DONE or (code == exits.BAD_INPUT and not got):  # a signal during setup: the ranks' own code
        return code
    from multigpu.launcher.segments import sweep

    sweep(started)  # the shared-memory segments of ranks that never finished
    summary = read_summary(out)
    if got and summary is not None and str(summary.get("stopped_by", "")).startswith("signal "):
        return exits.by_signal(got[0])
    if out is not None:
        from multigpu.records.record import salvage

        frames = salvage(out, f"the job ended abnormally ({name} exited {code}: a rank or its host died)")
        if frames is not None:
            print(f"multigpu: the job ended without rank 0 closing its record ({name} exited {code}: a rank or "
                  f"its host died); {out}/summary.json rewritten from the {frames} whole frames in timings.csv",
                  file=sys.stderr, flush=True)
    return exits.by_signal(got[0]) if got else exits.FAILED


#: seconds between the launcher's looks at its job's local ranks
WATCH = 0.1


def _wait(proc: subprocess.Popen, out: Path | None, started: float) -> int:
    """The launcher's exit status, once it ends or the launcher ends it. The launcher knows of a
    rank's death first: a rank process of this host gone while the frames run and rank 0 has not
    closed its record is a failure, and the job's session is killed at once instead of waiting
    for the MPI runtime's own teardown (Open MPI took 2.6 s). Every whole frame is in timings.csv;
    the summary is then rewritten from it (``salvage``). A rank that leaves normally does so only
    after rank 0 closed its record (a bad input leaves before the frames, a stop after closing)."""
    seen: set[int] = set()
    while True:
        try:
            return proc.wait(timeout=WATCH)
        except subprocess.TimeoutExpired:
            pass
        if out is None:
            continue
        now = set(_local_ranks(proc.pid))
        if any(_gone(p) for p in seen - now) and _frames_running(out, started):
            end_job(proc)
            return proc.returncode
        seen |= now


def _local_ranks(root: int) -> list[int]:
    """Pids of this host's rank processes (``python -m mpi4py ...``) descended from ``root``; not
    a rank's own children (a fork carries its parent's command line until it execs)."""
    parent = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat", "rb") as fh:
                    parent[int(d)] = int(fh.read().rsplit(b")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    under = []
    for pid in parent:
        p, hops = pid, 0
        while p in parent and p != root and hops < 16:
            p, hops = parent[p], hops + 1
        if p == root and pid != root:
            try:
                if b"mpi4py" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    under.append(pid)
            except OSError:
                continue
    ranks = set(under)
    out = []
    for pid in under:  # a handful
        p, hops = parent.get(pid), 0
        while p is not None and p != root and p not in ranks and hops < 16:
            p, hops = parent.get(p), hops + 1
        if p not in ranks:
            out.append(pid)
    return out


def _gone(pid: int) -> bool:
    """Whether process ``pid`` has ended (no longer there, or a zombie not yet reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_bytes().rsplit(b")", 1)[1].split()[0] == b"Z"
    except (OSError, IndexError):
        return True


def _frames_running(out: Path, started: float) -> bool:
    """Whether this job has shown frames (rows in timings.csv written since it started, beyond
    the header) and rank 0 has not closed its record (summary.json neither complete nor stopped)."""
    from multigpu.records.report import COLUMNS

    try:
        st = (out / "timings.csv").stat()
    except OSError:
        return False
    if st.st_mtime < started or st.st_size <= len(",".join(COLUMNS)) + 1:
        return False
    summary = read_summary(out)
    return summary is not None and not summary.get("complete") and not summary.get("stopped_by")


def read_summary(out: Path | None) -> dict | None:
    import json

    try:
        return json.loads((out / "summary.json").read_text()) if out is not None else None
    except (OSError, ValueError):
        return None
