"""Test-only fault injection: a rank that raises or freezes at a chosen frame or at setup, so
the tests can see every failure end the job with its frames kept."""

from __future__ import annotations

import os

#: the test-only fault to inject, read once: a lookup in ``os.environ`` (its miss is a KeyError
#: caught inside) costs ~10 us of CPU per frame with the caches cold, 4 % of a city frame's balancing
FAULT_SPEC = os.environ.get("MULTIGPU_FAULT")


def fault(rank: int, where: int | str) -> None:
    """Test-only fault injection: MULTIGPU_FAULT='RANK:WHERE[:stop]' (in the job's environment
    at start) with WHERE a frame number or 'setup' raises there, or with ':stop' stops the rank
    (SIGSTOP: a frozen rank; if something continues it, it carries on as if nothing happened).
    'RANK:compose:sleep=S' holds the rank back S seconds in every frame, after the exchange's
    wait and before it reads its peers' parts (where a peer running ahead could overwrite them).
    'RANK:FRAME:corrupt' spoils the rank's framed messages of that frame instead (``corrupt``)."""
    spec = FAULT_SPEC
    if spec:
        r, w, *action = spec.split(":")
        if int(r) == rank and w == str(where) and action != ["corrupt"]:
            if action and action[0].startswith("sleep="):
                import time

                time.sleep(float(action[0][len("sleep="):]))
                return
            if action == ["stop"]:
                import signal

                os.kill(os.getpid(), signal.SIGSTOP)
                return
            raise RuntimeError(f"injected fault at {'frame ' if isinstance(where, int) else ''}{where}")


def corrupt(rank: int, frame: int, message):
    """Test-only: ``message`` (a framed one, ``core/wire.py``) spoilt where MULTIGPU_FAULT is
    'RANK:FRAME:corrupt' for this rank and frame: a compressed payload's second half flipped, a
    raw one cut short; else ``message`` itself."""
    if FAULT_SPEC != f"{rank}:{frame}:corrupt":
        return message
    from multigpu.core import wire

    if wire.header(message)[0] == 0:
        return message[:-max(1, (message.nbytes - wire.HEADER_BYTES) // 2)]
    bad = message.copy()
    bad[wire.HEADER_BYTES + (message.nbytes - wire.HEADER_BYTES) // 2:] ^= 0x5A
    return bad
