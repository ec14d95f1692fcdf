"""Recovery by relaunch (``--recover N``): a failed job is started again where it stopped.

MPI's own fault tolerance (ULFM) is not in the MPIs this runs on (the MPICH wheel aborts under
``MPIR_CVAR_ENABLE_FT``; Debian's Open MPI 4.1 has none), so a failure ends the job as before
(a rank that dies, freezes past ``--liveness``, loses its X server, or a host that stops
answering: every rank stops, rank 0 keeps every whole frame) and the launcher
(``mpirun.recovering``) starts it again:

* what is left of the job is ended (its whole process session);
* ``timings.csv`` is trimmed to whole frames (``resume_point``; with ``--record`` also to the
  frames the flight file holds, so both stay one flight) and the job restarts with
  ``--resume-at F``, F the first frame not shown: the camera path goes on from there, the rows
  are appended, the mosaics kept, the summary counts every row since the run began;
* at most N restarts within ``WINDOW`` seconds; past that the launcher gives up with one line
  and exit code ``GAVE_UP``.

Each recovery is one line on the console and an entry of ``summary.json``'s ``recoveries``:
what failed, the last frame shown before, the frame resumed at, and ``seconds``: from the last
frame shown before the failure to the first frame shown after (the wall's dark time), with
``steps`` (``STEPS``: detection and teardown, launch, imports, scene, GL, first frame). The
launcher hands the recoveries so far to the restarted job in ``MULTIGPU_RECOVERIES``
(``Recovery``, rank 0's side). No MPI here.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from multigpu import exits

#: restarts are counted over this many seconds (a wall failing once a day recovers every time)
WINDOW = 600.0
#: the launcher's exit code when it gives up (more than N restarts within WINDOW)
GAVE_UP = exits.GAVE_UP  # the launcher's status when it gives up
#: the environment variable carrying the recoveries so far to a restarted job
ENV = "MULTIGPU_RECOVERIES"
#: a standby job's go file (launcher/standby.py writes it, rank/standby.py waits for it)
STANDBY_ENV = "MULTIGPU_STANDBY"
#: bytes of timings.csv's end read to find the last whole frame
TAIL = 1 << 20
#: when rank 0 reached each step of its setup (epoch seconds; ``mark``): a restart's breakdown
STARTUP: dict[str, float] = {}
#: a recovery's steps, each from the one before: the failed job ended (the failure detected, the
#: runtime's teardown), the new mpiexec started its ranks, their imports, the scene (cached),
#: the GL context and buffers, the first frame shown
STEPS = ("ended", "launched", "imported", "scene", "gl", "shown")


def mark(step: str) -> None:
    """Rank 0 reached ``step`` of its setup (``imported``, ``scene``, ``gl``)."""
    STARTUP.setdefault(step, time.time())


def restarts() -> int:
    """How many times this job's run was restarted before it (``timings.csv``'s ``restarts``:
    the rows after each recovery are marked by the count)."""
    return _RESTARTS


def _count() -> int:
    try:
        return len(json.loads(os.environ.get(ENV) or "[]"))
    except ValueError:
        return 0


_RESTARTS = _count()  # read once: a row's lookup costs nothing


def resume_point(out: Path, ranks: int, recorded: int | None = None) -> int:
    """The first frame not shown of the run in ``out``: ``timings.csv`` cut back to its last
    whole frame (every rank's row; a frame half-written when the job died goes), and to
    ``recorded`` frames where a ``--record`` flight holds fewer. Reads the file's tail only
    (a long run's file is large), all of it where the tail holds no whole frame. 0: no row."""
    from collections import Counter

    path = Path(out) / "timings.csv"
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.readline()
            for start in (max(len(head), size - TAIL), len(head)):
                fh.seek(start)
                data = fh.read()
                skip = 0 if start == len(head) else data.find(b"\n") + 1  # a line cut by the tail's start
                col = head.decode().split(",").index("frame")
                ends, frames, at = [], [], start + skip
                for line in data[skip:].split(b"\n")[:-1]:  # rows, a tail's worth (the last one unended: not whole)
                    at += len(line) + 1
                    ends.append(at)
                    frames.append(int(float(line.split(b",")[col])))
                count = Counter(frames)
                whole = [f for f, n in count.items() if n == ranks and (recorded is None or f < recorded)]
                if whole or start == len(head):
                    break
    except (OSError, ValueError, IndexError):
        return 0
    last = max(whole, default=None)
    cut = max((e for e, f in zip(ends, frames) if f == last), default=len(head))
    os.truncate(path, cut)
    return 0 if last is None else last + 1


def recorded_frames(record: str | None) -> int | None:
    """Cameras in a ``--record`` flight file (None: no flight recorded)."""
    if not record:
        return None
    try:
        return len(json.loads(Path(record).read_text())["cameras"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0


class Recovery:
    """Rank 0's view of the recoveries of its run: those done, and the one it is (a restarted
    job), timed at its first frame shown."""

    def __init__(self, done: list[dict], pending: dict | None):
        self.done, self.pending = done, pending

    @classmethod
    def resumed(cls, resume_at: int) -> "Recovery":
        """From ``MULTIGPU_RECOVERIES`` in a restarted job (``resume_at`` > 0), else none."""
        if not resume_at:
            return cls([], None)
        try:
            history = json.loads(os.environ.get(ENV, "[]"))
        except ValueError:
            history = []
        pending = history.pop() if history and "seconds" not in history[-1] else None
        return cls(history, pending)

    def shown(self, f: int) -> None:
        """Frame ``f`` is written: the first after a restart ends that recovery (one line)."""
        if self.pending is None:
            return
        from multigpu import STARTED

        p, self.pending = self.pending, None
        now = time.time()
        p["seconds"] = round(now - p["last_shown_at"], 3)
        at = {"ended": p.get("ended_at"), "launched": STARTED, **STARTUP, "shown": now}
        steps, before = {}, p["last_shown_at"]
        for name in STEPS:  # the steps this job saw, each from the one before
            if at.get(name) is not None:
                steps[name], before = round(at[name] - before, 3), at[name]
        p["steps"] = steps
        self.done.append(p)
        by = ", a standby took over" if p.get("standby") else ""
        print(f"multigpu: recovered: the wall is back at frame {f}, {p['seconds']:.1f} s after the last frame "
              f"before the failure{by} ({p['reason']}; " + ", ".join(f"{k} {v:.2f}" for k, v in steps.items()) + " s)",
              file=sys.stderr, flush=True)

    def doc(self) -> dict:
        """summary.json's recovery fields (none for a run that never failed)."""
        done = self.done + ([self.pending] if self.pending else [])
        if not done:
            return {}
        secs = [d["seconds"] for d in done if d.get("seconds") is not None]  # None: it failed again first
        return {"recoveries": done, "recovery_count": len(done), "frames_lost": sum(d["frames_lost"] for d in done),
                "recovery_seconds_max": max(secs) if secs else None}


def last_shown_at(out: Path) -> float:
    """When the run in ``out`` last showed a frame: ``timings.csv``'s last write (read before
    ``resume_point`` trims it)."""
    try:
        return os.stat(Path(out) / "timings.csv").st_mtime
    except OSError:
        return time.time()


def failure(resume_at: int, reason: str, history: list[dict], shown_at: float) -> list[dict]:
    """The recoveries so far with this one added: what failed, the last frame shown (and when:
    ``shown_at``), the frame resumed at, and the path frames it skips (none: the path resumes at
    the first frame not shown)."""
    return [*history, {"reason": reason, "last_shown": resume_at - 1, "resumed_at": resume_at,
                       "last_shown_at": shown_at, "ended_at": time.time(), "frames_lost": 0}]
