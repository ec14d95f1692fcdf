"""``multigpu bench recovery``: how long the wall is dark when a rank dies, and where the time goes.

The default plant on a 2x2 wall of 256x256 tiles (4 ranks) runs under the launcher with
``--recover 1``, the caches warm (a first run builds the scene cache, its buffers file and the
compiled kernels); a rank is killed (SIGKILL) after 150 frames and the launcher brings the wall
back at the first frame not shown. Each round's ``summary.json`` holds the recovery's
``seconds`` (from the last frame shown before the kill to the first after) and its ``steps``
(``records/recovery.py``: the failure detected and the job torn down, the new ranks launched,
their imports, the scene, the GL context and buffers, the first frame), all wall time.
"""

from __future__ import annotations

import json
import os
import signal
import tempfile
import time
from pathlib import Path

import numpy as np

from multigpu.records.recovery import STEPS
from multigpu.studies.tables import Columns

#: frames before the kill, and in all
KILL_AFTER, FRAMES = 150, 400


def rank_pids(out, standbys: bool = False) -> list[int]:
    """Pids of the rank processes (``python -m mpi4py ...``) writing the run in ``out``; with
    ``standbys``, those of a job started as a standby too (``--standby``)."""
    pids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                argv = Path(f"/proc/{d}/cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if b"mpi4py" in argv and str(out).encode() in argv and (standbys or not _standing_by(int(d))):
                pids.append(int(d))
    return sorted(pids)


def _standing_by(pid: int) -> bool:
    """Whether rank process ``pid`` was started as a standby (``--standby``): not the running job's."""
    from multigpu.records.recovery import STANDBY_ENV

    try:
        return f"{STANDBY_ENV}=".encode() in Path(f"/proc/{pid}/environ").read_bytes()
    except OSError:
        return True


def one_round(cache: str, tmp: str, k: int, kill: bool = True, standby: bool = False) -> dict:
    """One run, killed once after ``KILL_AFTER`` frames (``kill``); its summary. ``standby``:
    with ``--standby`` (the next job started and waiting)."""
    out = os.path.join(tmp, f"run-{k}")
    from multigpu.studies.runs import end, start

    args = ["walkthrough", "--frames", str(FRAMES), "--mosaic-every", "0", "--no-progress", "--out", out,
            "--recover", "1", *(["--standby"] if standby else [])]
    proc = start(4, args, {"MULTIGPU_CACHE": cache}, as_users=True)
    try:
        csv, t = Path(out) / "timings.csv", time.monotonic()
        while kill and not (csv.exists() and csv.read_text().count("\n") > 1 + 4 * KILL_AFTER):
            if proc.poll() is not None or time.monotonic() - t > 600:
                raise RuntimeError(f"bench recovery: the run ended early: {proc.communicate()[1][-500:]}")
            time.sleep(0.05)
        if kill:
            os.kill(rank_pids(out)[-1], signal.SIGKILL)
        _, err = proc.communicate(timeout=600)
    finally:
        end(proc)
    if proc.returncode != 0:
        raise RuntimeError(f"bench recovery: exit {proc.returncode}: {err.strip().splitlines()[-1:]}")
    return json.loads((Path(out) / "summary.json").read_text())


def bench_recovery(quick: bool) -> list[dict]:
    """The dark time of a recovery and its steps, restarted and from a standby (``--standby``),
    alternated round by round; per round and the medians of each."""
    rounds = 2 if quick else 5
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cache = os.path.join(tmp, "cache")
        one_round(cache, tmp, -1, kill=False)  # the caches warm: scene, buffers file, compiled kernels
        print(f"bench recovery: default plant, 2x2 wall of 256x256 tiles (4 ranks), a rank killed after "
              f"{KILL_AFTER} frames; wall seconds")
        table = Columns(("round", "round", ">6"), ("how", "restart", ">8"), ("seconds", "dark s", "7.2f"),
                        *((s, s, "9.2f") for s in STEPS))
        print(table.header(), flush=True)
        for k in range(rounds):
            for how in (("restart", "standby") if k % 2 == 0 else ("standby", "restart")):
                r = one_round(cache, tmp, 2 * k + (how == "standby"), standby=how == "standby")["recoveries"][0]
                rows.append({"round": k, "how": how, "seconds": r["seconds"], **r["steps"]})
                print(table.row({s: float("nan") for s in STEPS} | rows[-1]), flush=True)
    for how in ("restart", "standby"):
        mine = [r for r in rows if r["how"] == how]
        med = {s: float(np.median([r.get(s, np.nan) for r in mine])) for s in ("seconds", *STEPS)}
        print(table.row({**med, "round": "median", "how": how}), flush=True)
    return rows
