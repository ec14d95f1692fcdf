"""Frame exchange through node-shared memory: every rank's rendered pieces in one MPI window.

When all ranks run on one machine (the paper's multi-GPU workstation), a rank copies its
rendered pieces into its own segment of an ``MPI_Win_allocate_shared`` window before the
frame's barrier, and after it every tile owner copies (or depth-merges) the parts it needs
straight from the senders' segments: one copy per pixel instead of pack, two message copies
and unpack. Each segment has two halves used by alternate frames: a rank writes frame f+2's
pieces only after the barrier of frame f+1, which every rank reaches after its reads of frame
f, so a half is never overwritten while a peer still reads it. ``Win.Sync`` around the barrier
orders the stores and loads (MPI's unified memory model).

Opt-in (``--exchange shared``): Open MPI backs the window with a file in its session directory,
so a file-size limit or a full disk there can break it (measured: with Open MPI 4.1.4 a run
under RLIMIT_FSIZE did not end, where with messages it ends with the disk-full error).

Layout of a segment half: the rank's pieces in order, each its RGB bytes, then (sort-last)
its float32 depth.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.merge import merge_part
from multigpu.core.work import Piece
from multigpu.errors import InputError
from multigpu.parallel.exchange import wait_all

#: the most bytes a job may put in shared windows (all ranks, both halves) before it uses messages
MAX_SHARED_BYTES = 1 << 30


class SharedPieces:
    """The ``shared`` exchange backend: every rank's segment of one shared window, as numpy
    views; ``None`` from ``make`` when the window would be too big; refused (one line) when
    the ranks do not share one host."""

    def __init__(self, win, segments: list[np.ndarray], half: int):
        self.win, self.segments, self.half = win, segments, half

    name = "shared"

    @classmethod
    def make(cls, comm, size: tuple[int, int], with_depth: bool, timeout: float) -> "SharedPieces | None":
        from mpi4py import MPI

        per_half = size[0] * size[1] * (7 if with_depth else 3)  # a rank's pieces never exceed the display
        node = comm.Split_type(MPI.COMM_TYPE_SHARED)
        try:
            if node.Get_size() != comm.Get_size():  # every rank sees it: all refuse alike
                raise InputError.of("exchange", "shared needs every rank on one host, but the job spans several "
                                    "(use --exchange messages)")
            if 2 * per_half * comm.Get_size() > MAX_SHARED_BYTES:
                return None
            ok = np.ones(1, dtype=np.int32)
            try:
                win = MPI.Win.Allocate_shared(2 * per_half, 1, comm=node)
            except MPI.Exception:
                win, ok[0] = None, 0
            allok = np.zeros(1, dtype=np.int32)
            wait_all([comm.Iallreduce(ok, allok, op=MPI.MIN)], timeout, "shared window")
            if not allok[0]:
                if win is not None:
                    win.Free()
                return None
            order = np.zeros(comm.Get_size(), dtype=np.int32)  # node rank of every job rank
            wait_all([comm.Iallgather(np.array([node.Get_rank()], dtype=np.int32), order)], timeout, "shared window")
            segments = [np.frombuffer(win.Shared_query(int(order[r]))[0], dtype=np.uint8)[:2 * per_half]
                        for r in range(comm.Get_size())]
            win.Lock_all(MPI.MODE_NOCHECK)
            return cls(win, segments, per_half)
        finally:
            node.Free()

    def _base(self, frame: int) -> int:
        return (frame % 2) * self.half

    def publish(self, frame: int, me: int, rendered: list) -> None:
        """Copy this rank's rendered pieces ``(rgb, z or None)`` into its segment half."""
        seg, at = self.segments[me], self._base(frame)
        for rgb, z in rendered:  # pieces, not objects
            n = rgb.size
            seg[at:at + n] = rgb.reshape(-1)
            at += n
            if z is not None:
                seg[at:at + 4 * z.size] = np.ascontiguousarray(z, dtype=np.float32).view(np.uint8).reshape(-1)
                at += 4 * z.size
        self.win.Sync()  # the stores, before the frame's barrier

    def piece(self, frame: int, sender: int, rects, index: int, with_depth: bool):
        """Views of ``sender``'s piece ``index`` (rgb (h, w, 3), z (h, w) or None)."""
        seg, at = self.segments[sender], self._base(frame)
        sizes = [(int(r[3] - r[1]), int(r[2] - r[0])) for r in np.asarray(rects, dtype=np.int64).reshape(-1, 4)]
        per_px = 7 if with_depth else 3
        at += sum(h * w for h, w in sizes[:index]) * per_px
        h, w = sizes[index]
        rgb = seg[at:at + 3 * h * w].reshape(h, w, 3)
        z = seg[at + 3 * h * w:at + 7 * h * w].view(np.float32).reshape(h, w) if with_depth else None
        return rgb, z

    def close(self, collective: bool = True) -> None:
        """End the access epoch; free the window too when every rank does so together."""
        self.win.Unlock_all()
        if collective:
            self.win.Free()

    def compose(self, frame: int, me: int, rects, rendered: list, plan: list[Piece], tile, color: np.ndarray,
                depth: np.ndarray | None = None) -> tuple[int, int]:
        """Compose rank ``me``'s tile from the senders' published pieces (after the barrier):
        the same result as ``composite.composite``, parts in ascending sender order. Returns
        the bytes peers read from this rank (colour and depth, of which depth)."""
        self.win.Sync()  # the peers' stores, after the barrier
        with_depth = depth is not None
        for p in sorted((p for p in plan if p.receiver == me), key=lambda p: (p.sender, p.index)):  # parts
            rgb, z = self.piece(frame, p.sender, rects[p.sender], p.index, with_depth)
            ox, oy = (int(v) for v in np.asarray(rects[p.sender], dtype=np.int64).reshape(-1, 4)[p.index, :2])
            x0, y0, x1, y1 = p.rect
            src = np.s_[y0 - oy:y1 - oy, x0 - ox:x1 - ox]
            merge_part(color, depth, tile[:2], p.rect, rgb[src], None if z is None else z[src])
        px = sum(p.pixels for p in plan if p.sender == me and p.receiver != me)  # read by peers
        return px * (7 if with_depth else 3), px * 4 if with_depth else 0
