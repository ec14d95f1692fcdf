"""The host's ranks share the projection of the object bounds (``--projection shared``).

Every rank plans the same partition from the same object rects (the paper's redundant
balancing), and on scenes of very many objects projecting every box is most of it. Where the
ranks of a host can share memory, each projects a slice of the boxes into one array in a segment of that
host (``shared._map_segment``: made, mapped and unlinked as the exchange's), waits for the
host's other ranks (a barrier: the ``sync`` phase), and plans from the whole array. A box's rect
depends on that box alone, so the rects are the ones every rank would have made (bit for bit).
The array is kept twice, frames alternating, so a frame's rects stay valid through the next
frame as the planner's own do. Ranks on other hosts have their own segment and slices.
It cuts a rank's balancing CPU by about a fifth from ~50k objects and saves nothing below ~10k,
where the wait costs wall time (docs/USAGE.md, measured): not the default.
"""

from __future__ import annotations

import numpy as np

from multigpu.parallel.exchange import barrier
from multigpu.parallel.shared import host_segment


class SharedProjection:
    """This rank's slice [lo, hi) of the boxes and the host's shared (2, 4, N) rects."""

    def __init__(self, node, rects: np.ndarray, lo: int, hi: int, timeout: float):
        self.node, self.rects, self.lo, self.hi, self.timeout = node, rects, lo, hi, timeout
        self.ranks = node.Get_size()

    @classmethod
    def make(cls, comm, n_objects: int, timeout: float) -> "tuple[SharedProjection | None, str | None]":
        """The shared projection, or (None, why not): every rank of the job the same."""
        from mpi4py import MPI

        node = comm.Split_type(MPI.COMM_TYPE_SHARED)
        keep = False
        try:
            n = node.Get_size()
            total = 2 * 4 * 8 * max(n_objects, 1)
            memory, why = host_segment(comm, node, total, timeout, "shared projection",
                                       "one rank per host" if n < 2 else None)
            if why:
                return None, why
            at = node.Get_rank()
            rects = memory[:total].view(np.float64).reshape(2, 4, max(n_objects, 1))[:, :, :n_objects]
            keep = True
            return cls(node, rects, at * n_objects // n, (at + 1) * n_objects // n, timeout), None
        finally:
            if not keep:
                node.Free()

    def out(self, frame: int) -> np.ndarray:
        """Frame ``frame``'s (4, N) rects array (shared by the host's ranks)."""
        return self.rects[frame % 2]

    def wait(self) -> None:
        """Until every rank of the host has written its slice (bounded by the job's timeout)."""
        barrier(self.node, self.timeout)

    def close(self) -> None:
        """Let the host's communicator go (the mapping goes with the arrays)."""
        if self.node is not None:
            self.node.Free()
            self.node = None
