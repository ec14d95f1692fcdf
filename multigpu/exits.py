"""The exit codes the whole job ends with, whichever MPI runs it and whichever side (a rank, the
launcher) decides (docs/USAGE.md, "Failures and exit codes"). Every place that ends the job takes
its code from here."""

from __future__ import annotations

import signal

DONE = 0  #: every planned frame shown, or the user stopped the run (Escape, a closed window)
FAILED = 1  #: a rank, its host or an output failed (rank 0's frames kept)
BAD_INPUT = 2  #: bad input or an output that cannot be written: one line naming it
GAVE_UP = 3  #: ``--recover N``: more failures than N within the window


def by_signal(signum: int) -> int:
    """The conventional status of a run ended by signal ``signum``: 128 + signum."""
    return 128 + int(signum)


INTERRUPTED = by_signal(signal.SIGINT)  #: Ctrl-C (130)
