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
    wait and before it reads its peers' parts (where a peer running ahead could overwrite them)."""
    spec = FAULT_SPEC
    if spec:
        r, w, *action = spec.split(":")
        if int(r) == rank and w == str(where):
            if action and action[0].startswith("sleep="):
                import time

                time.sleep(float(action[0][len("sleep="):]))
                return
            if action == ["stop"]:
                import signal

                os.kill(os.getpid(), signal.SIGSTOP)
                return
            raise RuntimeError(f"injected fault at {'frame ' if isinstance(where, int) else ''}{where}")
