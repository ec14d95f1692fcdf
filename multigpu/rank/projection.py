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

from multigpu.core.bounds import BoxProjector
from multigpu.rank.exchange import barrier
from multigpu.rank.shared import host_segment


class EachRank:
    """Every rank projects every object (the default): one compiled call, no wait."""

    name = "each rank every object"

    def __init__(self, planner):
        self.planner = planner

    def project(self, frame: int, camera, timer):
        with timer.phase("project"):
            return self.planner.frame(camera, frame)

    def close(self, collective: bool = True) -> None:
        """Nothing held."""


def make_projection(cfg, comm, planner, n_objects: int) -> "tuple[EachRank | SharedProjection, str | None]":
    """``--projection``'s backend for this job, and why not the shared one where it was asked for
    and cannot be (None otherwise): every rank of the job the same."""
    if cfg.projection == "shared" and "series" in planner.scene.meta:
        return EachRank(planner), "a series' objects change with its steps"
    if cfg.projection == "shared" and comm.Get_size() > 1 and cfg.bounds == "box" and planner.viewer is None:
        shared, why = SharedProjection.make(comm, planner, n_objects, cfg.timeout)
        if shared is not None:
            return shared, None
        return EachRank(planner), why
    why = "a viewer's eyes are projected whole" if cfg.projection == "shared" and planner.viewer is not None else None
    return EachRank(planner), why


class SharedProjection:
    """This rank's slice [lo, hi) of the boxes and the host's shared (2, 4, N) rects; frames whose
    planner cannot project a slice (a decomposition that wants coverage) project every object."""

    def __init__(self, node, planner, rects: np.ndarray, lo: int, hi: int, timeout: float):
        self.node, self.planner, self.rects, self.lo, self.hi, self.timeout = node, planner, rects, lo, hi, timeout
        self.ranks = node.Get_size()
        self.name = f"shared: a slice per rank of {self.ranks} on a host"
        full, scene = planner.project, planner.scene
        # the slice's own projector (box bounds only: ``sliceable``)
        self.sub = (BoxProjector(scene.bmin[lo:hi], scene.bmax[lo:hi], full.dtype, compiled=full.compiled)
                    if isinstance(full, BoxProjector) else None)

    @classmethod
    def make(cls, comm, planner, n_objects: int, timeout: float) -> "tuple[SharedProjection | None, str | None]":
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
            return cls(node, planner, rects, at * n_objects // n, (at + 1) * n_objects // n, timeout), None
        finally:
            if not keep:
                node.Free()

    @property
    def sliceable(self) -> bool:
        """Whether this frame's projection can be made a slice at a time: box bounds, and a
        decomposition that wants no coverage."""
        return self.sub is not None and not self.planner.decomposition.needs_coverage

    def out(self, frame: int) -> np.ndarray:
        """Frame ``frame``'s (4, N) rects array (shared by the host's ranks)."""
        return self.rects[frame % 2]

    def project_slice(self, frame: int, camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(view, proj, light) of ``camera``, and the canvas rects of objects [lo, hi) into columns
        lo:hi of frame ``frame``'s array. A box's rect does not depend on the others, so the
        slices make ``Planner.frame``'s rects bit for bit (tests/test_projection.py)."""
        view, proj, light, rects = self.sub.frame(camera, self.planner.size)
        self.out(frame)[:, self.lo:self.hi] = rects.T
        return view, proj, light

    def gathered(self, frame: int) -> np.ndarray:
        """The (N, 4) visible rects of frame ``frame``, once every slice is in."""
        out, planner = self.out(frame), self.planner
        return planner.visible(out.T)

    def wait(self) -> None:
        """Until every rank of the host has written its slice (bounded by the job's timeout)."""
        barrier(self.node, self.timeout)

    def project(self, frame: int, camera, timer):
        """This rank's slice into the host's array (``project``), every slice of the host in
        (``sync``), then the whole array's visible rects."""
        if not self.sliceable:
            with timer.phase("project"):
                return self.planner.frame(camera)
        with timer.phase("project"):
            view, proj, light = self.project_slice(frame, camera)
        with timer.phase("sync"):
            self.wait()
        with timer.phase("project"):
            return view, proj, light, self.gathered(frame)

    def close(self, collective: bool = True) -> None:
        """Let the host's communicator go (the mapping goes with the arrays); only together."""
        if self.node is not None and collective:
            self.node.Free()
            self.node = None
