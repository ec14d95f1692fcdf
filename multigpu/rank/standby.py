"""A job started ahead of need (``--standby``): its ranks are launched, import what a run needs
and (headless) map the scene and make their GL context and buffers, then wait, idle, until the
launcher hands them a restart.

A restart after a failure spends most of its dark time before the first frame: the new ranks'
launch, MPI's start and the imports. The launcher (``launcher/standby.py``) starts the next
job while the current one runs, with ``ENV`` naming a file that does not exist yet. Its ranks
stop here, before they touch the output directory, a window, a port or a shared segment:
rank 0 looks for the file every ``POLL`` seconds, the others test a non-blocking broadcast as
often, so a job standing by costs the wall next to nothing. After a failure the launcher writes
the file (the frame to resume at, the recoveries so far); rank 0 broadcasts it and every rank
goes on as a restarted job would, from the frame the launcher named. A ``quit`` in the file
ends the standby quietly (the run ended another way).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from multigpu.records.recovery import STANDBY_ENV as ENV  # the go file's path, in a standby job's environment

#: seconds between looks while standing by
POLL = 0.02
#: seconds the go's broadcast may take once rank 0 has read it (every rank is looking by then)
GO_WAIT = 60.0
#: the largest go file read (bytes): a frame and a few recoveries' history
MOST_GO = 1 << 20


def standing_by() -> str | None:
    """The go file this job waits for, or None (not a standby). InputError where ``ENV`` names
    a file in a folder that does not exist: a stray setting (the launcher makes the folder
    first), which would otherwise keep a walk waiting without a word."""
    from multigpu.errors import InputError

    go_file = os.environ.get(ENV) or None
    if go_file and not Path(go_file).parent.is_dir():
        raise InputError(f"{ENV}={go_file}: no such folder: only the launcher's --standby sets it (unset it)")
    return go_file


def warm() -> None:
    """The imports a restarted rank would wait for (moderngl among them), done while the wall
    still runs."""
    import multigpu.gpu.render  # noqa: F401
    import multigpu.rank.frames  # noqa: F401
    import multigpu.rank.walkthrough  # noqa: F401


def prepared(args, comm):
    """What this standby can set up before its go (``walkthrough.prepare``: the scene, the GL
    context and buffers; headless only), or None, agreed by every rank: all have it or none."""
    from multigpu.config import setup_timeout
    from multigpu.flags import walk_config
    from multigpu.rank.exchange import agree
    from multigpu.rank.walkthrough import prepare

    ready, wait = None, GO_WAIT
    try:
        cfg = walk_config(args)
        wait = setup_timeout(cfg)
        if cfg.present == "headless" and not cfg.dark:
            ready = prepare(cfg, comm, wait)
    except Exception:  # noqa: BLE001 -- the restart then sets up as a fresh job does, and says what fails
        ready = None
    if agree(comm, None if ready is not None else "not prepared", wait, "standby") is None:
        return ready
    if ready is not None:
        ready.renderer.release()
    return None


def wait_for_go(comm, go_file: str) -> dict:
    """Stand by until the launcher writes ``go_file``; its contents, the same on every rank."""
    from multigpu.rank.exchange import wait_all

    size = np.zeros(1, dtype=np.int64)
    if comm.Get_rank() == 0:
        print(f"multigpu: standing by for a restart ({ENV}): waiting for the launcher's go", flush=True)
        path = Path(go_file)
        while not path.exists():
            if not path.parent.is_dir():  # the launcher is gone and took its folder: nothing will come
                break
            time.sleep(POLL)
        try:
            data = path.read_bytes()[:MOST_GO]
        except OSError:
            data = b'{"quit": true}'

        size[0] = len(data)
        wait_all([comm.Ibcast(size, root=0)], GO_WAIT, "standby's go")
        buf = bytearray(data)
    else:
        req = comm.Ibcast(size, root=0)
        while not req.Test():  # as long as the wall runs: no timeout
            time.sleep(POLL)
        buf = bytearray(int(size[0]))
    wait_all([comm.Ibcast(buf, root=0)], GO_WAIT, "standby's go")
    return go_of(bytes(buf), go_file)


def go_of(data: bytes, go_file: str) -> dict:
    """The launcher's go, checked (the same bytes give the same answer on every rank):
    ``{"quit": true}`` or ``{"resume_at": F, "history": [...]}``; InputError naming the file
    and what is wrong."""
    from multigpu.core.doors import Refusal, is_whole, parse_json
    from multigpu.errors import InputError

    got = parse_json(data, MOST_GO)
    if isinstance(got, Refusal):
        raise InputError(f"{ENV} {go_file}: {got}")
    if got == {"quit": True}:
        return got
    if (not isinstance(got, dict) or set(got) != {"resume_at", "history"} or not is_whole(got["resume_at"], 0, 1 << 62)
            or not isinstance(got["history"], list)):
        raise InputError(f"{ENV} {go_file}: must be {{\"quit\": true}} or {{\"resume_at\": FRAME, \"history\": [...]}}")
    return got


def go(args, got: dict) -> None:
    """A restarted job's start from the launcher's go: the frame to resume at (into the parsed
    command line ``args``), the recoveries so far, and this job's own start time."""
    import multigpu
    from multigpu.records import recovery

    args.resume_at = int(got["resume_at"])
    os.environ[recovery.ENV] = json.dumps(got["history"])
    os.environ.pop(ENV, None)
    multigpu.STARTED = time.time()  # the launch a restart measures is this one
