"""The launcher's side of ``--recover``: supervise the job, and start it again after a failure.

After a failure (exit 1; or exit 2 from a restarted job: what it needs is gone, an X server that
died) the job restarts at the first frame not shown (``recovery``), at most ``bound`` times
within ``recovery.WINDOW`` (then one line and ``recovery.GAVE_UP``). On several
hosts each restart first asks every host to answer (``hosts.unreachable``): a host that does
not is left out, its tiles dark (``--dark-tiles``: black, drawn by nobody) and its processes
started last on the last host that answers (``hosts.survivors``), so the wall goes on with the
others sharing the live tiles. While a host is out it is asked again every ``REJOIN`` seconds;
once it answers the job is stopped after its frame (SIGTERM) and started again with it, at the
next frame: a rejoin is not a failure. An interactive flight records itself (``with_flight``)
so that a restart goes on from its last camera. Bad input, a signal, a finished run: their own
code.
"""

from __future__ import annotations

import collections
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

from multigpu import exits
from multigpu.launcher.hosts import remote_shell, survivors, unreachable
from multigpu.launcher.supervise import flag_value, out_dir, read_summary, supervise
from multigpu.records import recovery

#: seconds between asking a host that is out whether it answers again (MULTIGPU_REJOIN_EVERY)
REJOIN = float(os.environ.get("MULTIGPU_REJOIN_EVERY", "30"))


def recovering(launcher, ranks: int, argv: list[str], hosts, bound: int) -> int:
    """Run the job of ``launcher`` (``mpirun.Launcher``) under ``supervise`` until it ends for
    good (module doc); its exit code."""
    out, name = out_dir(argv), Path(launcher.path).name
    argv = with_flight(argv, out)
    rsh = remote_shell() if hosts else None  # checked at the start where there are hosts
    restarts: collections.deque = collections.deque()
    history: list[dict] = []
    env, args, place, gone = launcher.environ(), argv, hosts, set()
    standby = _standby(launcher, ranks, argv, hosts, out)
    adopt = None  # a standby handed the restart
    try:
        while True:
            rejoin = threading.Event()
            watch = (lambda proc: _watch(proc, hosts, gone, rsh, rejoin)) if gone else None
            if standby is not None:  # the next job, started once this one shows a frame, waits while it runs
                watch = (lambda proc: standby.after(proc, out / "timings.csv", launcher.environ()))
            code = supervise(launcher.command(ranks, args, hosts=place, env=env), env, out, name, watch, adopt)
            adopt = None
            refused = code == 2 and bool(restarts)  # a restart refused at the door: what it needs is gone (an X server)
            if out is None or (code != 1 and not refused and not rejoin.is_set()):
                return code
            summary = read_summary(out) or {}
            if rejoin.is_set():  # a host that was out answers: it takes its tiles back
                gone, reason = set(), None
                print(f"multigpu: {', '.join(sorted(_names(hosts)))}: every host answers; restarting the wall with "
                      "all of them", file=sys.stderr, flush=True)
            else:
                reason = ("the restarted job could not start (its error above)" if refused
                          else str(summary.get("stopped_by") or f"{name} exited {code}"))
                now = time.monotonic()
                while restarts and now - restarts[0] > recovery.WINDOW:
                    restarts.popleft()
                if len(restarts) >= bound:
                    print(f"multigpu: giving up: {len(restarts) + 1} failures within {recovery.WINDOW / 60:.0f} "
                          f"minutes (--recover {bound}), the last: {reason}; {out}/ keeps every frame shown",
                          file=sys.stderr, flush=True)
                    return exits.GAVE_UP
                restarts.append(now)
                gone = set(unreachable(hosts, rsh)) if hosts else set()
            place, dark = _placement(hosts, gone, argv, ranks)
            if hosts and not place:
                print("multigpu: giving up: no host answers", file=sys.stderr, flush=True)
                return exits.GAVE_UP
            history = [h if "seconds" in h else {**h, "seconds": None}  # a restart that failed before a frame
                       for h in summary.get("recoveries", history)]
            shown_at = recovery.last_shown_at(out)
            at = recovery.resume_point(out, ranks, recovery.recorded_frames(flag_value(argv, "--record")))
            if reason is not None:
                history = recovery.failure(at, reason, history, shown_at)
                without = f" without {', '.join(sorted(gone))} (tiles {','.join(map(str, dark))} dark)" if gone else ""
                print(f"multigpu: recovering ({len(restarts)} of at most {bound} restarts in "
                      f"{recovery.WINDOW / 60:.0f} minutes): {reason}; restarting the wall{without} at frame {at}",
                      file=sys.stderr, flush=True)
            env = launcher.environ({recovery.ENV: json.dumps(history)})
            args = [*_without(_without(argv, "--resume-at"), "--dark-tiles"), "--resume-at", str(at),
                    *(["--dark-tiles", ",".join(map(str, dark))] if dark else [])]
            if standby is not None and not refused and history:  # its ranks are up: they go on from frame `at`
                adopt = standby.go(at, [*history[:-1], {**history[-1], "standby": True}])
    except KeyboardInterrupt:  # Ctrl-C between two jobs: nothing is running
        return exits.INTERRUPTED
    finally:
        if standby is not None:
            standby.close()


def _standby(launcher, ranks: int, argv: list[str], hosts, out: Path | None):
    """A ``Standby`` where the command line asks for one (``--standby``), else None. Its go file
    is read by rank 0 on this machine: a job on one host (bad input otherwise)."""
    from multigpu.errors import InputError
    from multigpu.launcher.standby import Standby

    if "--standby" not in argv or out is None:
        return None
    if hosts:
        raise InputError.of("standby", "works for a job on one host (the waiting job's rank 0 reads the "
                            "launcher's go file); leave it out with --hosts")
    return Standby(launcher, ranks, _without(_without(argv, "--resume-at"), "--dark-tiles"))


def with_flight(argv: list[str], out: Path | None) -> list[str]:
    """An interactive flight that can be restarted records itself (``--record OUT/flight.json``,
    unless it has a ``--record``), so a restart goes on from its last camera."""
    if out is None or flag_value(argv, "--path") != "interactive" or flag_value(argv, "--record") is not None:
        return argv
    return [*argv, "--record", str(Path(out) / "flight.json")]


def _names(hosts) -> set[str]:
    return {h for h, _ in hosts or []}


def _placement(hosts, gone: set[str], argv: list[str], ranks: int) -> tuple[list | None, list[int]]:
    """Where the job's processes go without the ``gone`` hosts, and the tiles those drove."""
    if not gone:
        return hosts, []
    from multigpu.wall import load_wall, tile_order

    wall = flag_value(argv, "--wall")
    base = (tile_order(load_wall(wall), ranks) if wall else None) or list(range(ranks))
    dark, at = [], 0
    for h, n in hosts:  # hosts, a handful
        if h in gone:
            dark += base[at:at + n]
        at += n
    return survivors(hosts, gone), sorted(dark)


def _watch(proc, hosts, gone: set[str], rsh: str | None, rejoin: threading.Event) -> None:
    """While the job runs without ``gone``, ask them every ``REJOIN`` seconds; once every one
    answers, stop the job after its frame (it is started again with them)."""
    asked = [(h, n) for h, n in hosts if h in gone]

    def ask():
        while proc.poll() is None:
            time.sleep(REJOIN)
            if proc.poll() is None and not unreachable(asked, rsh):
                rejoin.set()
                try:
                    os.killpg(proc.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
                return

    threading.Thread(target=ask, daemon=True).start()


def _without(argv: list[str], flag: str) -> list[str]:
    """``argv`` without ``flag`` and its value (``--flag V`` or ``--flag=V``)."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a == flag:
            skip = True
        elif not a.startswith(flag + "="):
            out.append(a)
    return out
