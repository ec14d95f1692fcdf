"""A frame's timing row on every rank: filled by column name, gathered from every rank in one
non-blocking allgather, and landed in frame order. With frames in flight a row lands a step
after it was posted, so a fast rank does not wait there for a slow one's current frame."""

from __future__ import annotations

import numpy as np

from multigpu.rank.exchange import wait_all
from multigpu.records.report import COLUMNS


class Rows:
    """Rows of ``K`` ranks; ``later``: land a frame's row at the next ``post`` (or ``land``)."""

    def __init__(self, comm, timeout: float, later: bool):
        self.comm, self.timeout, self.later = comm, timeout, later
        self.col = {c: i for i, c in enumerate(COLUMNS)}
        self.allrows = np.zeros((comm.Get_size(), len(COLUMNS) + 1))  # the last landed frame's (+ stop flags)
        self.posted = None  # (frame, row, every, request, extra)

    def post(self, frame: int, values: dict, flag: float, extra=None) -> list:
        """This rank's row of ``frame`` (``values`` by column, the stop ``flag`` last) on its way
        to every rank; returns the rows landed now: ``[(frame, (K, C + 1) rows, extra)]``."""
        landed = self.land() if self.later else []
        row = np.zeros(len(COLUMNS) + 1)
        col = self.col
        for c, v in values.items():
            row[col[c]] = v
        row[-1] = flag
        every = np.zeros((self.comm.Get_size(), len(COLUMNS) + 1))
        request = self.comm.Iallgather(row, every)
        self.posted = (frame, row, every, request, extra)
        if self.later:  # pushed now and at the next frame's start (``push``): a rank that then fails or freezes
            request.Test()  # would otherwise keep its part, and the frame every rank showed would be lost
            return landed
        return self.land()

    def push(self) -> None:
        """Drive the posted row's gather on (a test): without a progress thread (Open MPI) it moves
        only inside MPI calls, and a rank about to freeze or fail should have sent its part."""
        if self.posted is not None:
            self.posted[3].Test()

    def land(self, timeout: float | None = None) -> list:
        """The posted row, once every rank's has arrived (bounded: the job's timeout, or
        ``timeout``)."""
        if self.posted is None:
            return []
        frame, _, every, request, extra = self.posted
        wait_all([request], self.timeout if timeout is None else timeout, "timing gather")
        self.posted = None
        self.allrows = every
        return [(frame, every, extra)]
