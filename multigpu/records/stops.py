"""Why a run stopped early: the stop flag a frame's row carries, and the words for it."""

from __future__ import annotations

import numpy as np

#: the stop flag of a frame's row: > 0 a signal number, < 0 a window event or a failed write
STOPS = {-1: "escape key", -2: "window closed", -3: "escape key (the monitor)", -4: "window closed (the monitor)",
         -5: "an output could not be written", -6: "stop (the panel)", -7: "the series ended (--at-end stop)"}
STOP_FLAG = {why: flag for flag, why in STOPS.items()}


def stopped_by_flags(signum: int, flags: np.ndarray | None, ranks: int) -> str | None:
    """What stopped the run: a signal this rank got, else the first rank's stop flag (None: nothing)."""
    flags = flags if flags is not None else np.zeros(ranks)
    if signum:
        import signal

        return f"signal {signal.Signals(signum).name}"
    if (flags < 0).any():
        r = int(np.flatnonzero(flags < 0)[0])
        why = STOPS[int(flags[r])]
        if why == STOPS[-5]:
            return f"{why} (rank {r})"
        whole = why.endswith(("(the monitor)", "(the panel)", "(--at-end stop)"))  # no window's
        return why if whole else f"{why} (rank {r}'s window)"
    return None
