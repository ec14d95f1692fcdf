"""Frame exchange through node-shared memory: the parts peers need, in one MPI window.

When all ranks run on one machine (the paper's multi-GPU workstation), a rank copies the parts
of its rendered pieces that other tiles need into its own segment of an
``MPI_Win_allocate_shared`` window before the frame's barrier, and after it every tile owner
copies (or depth-merges) them straight from the senders' segments: one copy per pixel instead of
pack, two message copies and unpack; a rank's own tile's parts never leave its pieces. Each
segment has two halves used by alternate frames: a rank writes frame f+2's parts only after the
barrier of frame f+1, which every rank reaches after its reads of frame f, so a half is never
overwritten while a peer still reads it. ``Win.Sync`` around the barrier orders the stores and
loads (MPI's unified memory model).

The default where every rank shares a host (``--exchange auto``). MPI backs the window with a
file in ``/dev/shm``, and Open MPI 4.1 does not return from the allocation when making that file
fails (measured: under RLIMIT_FSIZE its run never ended, where MPICH's fails and the job uses
messages). So before allocating, every rank checks that its file-size limit and the free space
of ``/dev/shm`` hold the whole window (``room``), and all use messages where one does not.

Layout of a segment half: the rank's parts for other tiles in ``transfers`` order, each its RGB
bytes, then (sort-last) its float32 depth.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.merge import merge_part
from multigpu.core.work import Piece
from multigpu.errors import InputError
from multigpu.parallel.composite import _local, _pack, _unpack
from multigpu.parallel.exchange import allgather_text, wait_all

#: the most bytes a job may put in shared windows (all ranks, both halves) before it uses messages
MAX_SHARED_BYTES = 1 << 30


def room(nbytes: int, shm: str = "/dev/shm") -> str | None:
    """Why this process cannot back a shared window of ``nbytes`` (None: it can): its file-size
    limit, or the free space of ``shm`` where that exists (a container's is often 64 MiB)."""
    import os
    import resource

    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if soft != resource.RLIM_INFINITY and soft < nbytes:
        return f"the file-size limit ({soft} bytes) is below the {nbytes}-byte window"
    try:
        st = os.statvfs(shm)
    except OSError:
        return None
    free = st.f_bavail * st.f_frsize
    if free < nbytes:
        return f"{shm} has {free} bytes free, below the {nbytes}-byte window"
    return None


class SharedPieces:
    """The ``shared`` exchange backend: every rank's segment of one shared window, as numpy
    views. ``make`` gives (None, why) when the window would be too big or finds no room, and
    refuses (one line) when the ranks do not share one host and the user asked for it."""

    def __init__(self, win, segments: list[np.ndarray], half: int, with_depth: bool):
        self.win, self.segments, self.half, self.depth = win, segments, half, with_depth

    name = "shared"

    @classmethod
    def make(cls, comm, size: tuple[int, int], with_depth: bool, timeout: float,
             asked: bool = True) -> "tuple[SharedPieces | None, str | None]":
        """The backend, or None and why not (every rank the same). ``asked``: the user chose
        ``--exchange shared``, so ranks on several hosts are an error, not a reason."""
        from mpi4py import MPI

        per_half = size[0] * size[1] * (7 if with_depth else 3)  # a rank's parts never exceed the display
        K = comm.Get_size()
        node = comm.Split_type(MPI.COMM_TYPE_SHARED)
        try:
            if node.Get_size() != K:  # every rank sees it: all refuse alike
                if asked:
                    raise InputError.of("exchange", "shared needs every rank on one host, but the job spans "
                                        "several (use --exchange messages)")
                return None, "the ranks span several hosts"
            total = 2 * per_half * K
            if total > MAX_SHARED_BYTES:
                return None, f"the window ({total} bytes) would exceed {MAX_SHARED_BYTES} bytes"
            why = room(total + K * 65536)  # + page rounding per segment
            texts = allgather_text(comm, why or "", timeout, "shared window")
            why = next((t for t in texts if t), None)
            if why:  # before the allocation: Open MPI does not return from a failed one
                return None, why
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
                return None, "MPI could not allocate the window"
            order = np.zeros(K, dtype=np.int32)  # node rank of every job rank
            wait_all([comm.Iallgather(np.array([node.Get_rank()], dtype=np.int32), order)], timeout, "shared window")
            segments = [np.frombuffer(win.Shared_query(int(order[r]))[0], dtype=np.uint8)[:2 * per_half]
                        for r in range(K)]
            win.Lock_all(MPI.MODE_NOCHECK)
            return cls(win, segments, per_half, with_depth), None
        finally:
            node.Free()

    def _base(self, frame: int) -> int:
        return (frame % 2) * self.half

    def publish(self, frame: int, me: int, rects, rendered: list, plan: list[Piece]) -> None:
        """Copy the parts of this rank's rendered pieces ``(rgb, z or None)`` that peers' tiles
        need into its segment half, in ``plan`` order (its own tile's parts stay where they are)."""
        out = [p for p in plan if p.sender == me and p.receiver != me]  # parts, not objects
        if out:
            _pack(self.segments[me][self._base(frame):], out, rects[me], rendered, self.depth)
        self.win.Sync()  # the stores, before the frame's barrier

    def close(self, collective: bool = True) -> None:
        """End the access epoch; free the window too when every rank does so together."""
        self.win.Unlock_all()
        if collective:
            self.win.Free()

    def compose(self, frame: int, me: int, rects, rendered: list, plan: list[Piece], tile, color: np.ndarray,
                depth: np.ndarray | None = None) -> tuple[int, int]:
        """Compose rank ``me``'s tile from its own pieces and the senders' published parts (after
        the barrier): the same result as ``composite.composite``, parts in ascending sender
        order. Returns the bytes peers read from this rank (colour and depth, of which depth)."""
        self.win.Sync()  # the peers' stores, after the barrier
        with_depth = depth is not None
        per_px = 7 if with_depth else 3
        at: dict[int, int] = {}  # where each sender's next published part starts
        for p in plan:  # sorted by (sender, receiver, index): K*K pairs x pieces, not objects
            s = p.sender
            if s == me or p.receiver == s:
                if p.receiver == me:
                    merge_part(color, depth, tile[:2], p.rect, *_local(p, rects[me], rendered))
                continue
            start = at.get(s, self._base(frame))
            at[s] = start + p.pixels * per_px
            if p.receiver == me:
                (_, rgb, z), = _unpack(self.segments[s][start:], [p], with_depth)
                merge_part(color, depth, tile[:2], p.rect, rgb, z)
        px = sum(p.pixels for p in plan if p.sender == me and p.receiver != me)  # read by peers
        return px * per_px, px * 4 if with_depth else 0
