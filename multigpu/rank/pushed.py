"""A live stream's steps sent by rank 0 to every rank, in the frame that first shows them.

Rank 0's keeper (``rank/spool.py``) makes each step it reads ready for the wall in a thread of its
own (``message``): where the step's cells are the first step's, only what it changes of the first
step's scene (``scene/same_cells.changes``: its vertices, colours, origin and boxes, made from the
arrays the stream handed over, no file read), else the whole scene built from its kept file; one
pickled message either way. At every frame's start (every rank at the same frame) rank 0 says the
newest step made that the wall does not show yet (a header: the step and the message's size) and
sends it: where every rank is on rank 0's host, through two slots of the host's shared memory
(``Board``), else (or where it does not fit) as a second broadcast; every rank swaps it in at this
very frame: no rank reads a file for it, no frame's rows have to land to name it. The first step
reaches a PC that cannot read rank 0's kept file by broadcast, once, at setup (``first_step``).

Where the keeper is making a step when a frame starts, rank 0 waits for it there, at most half a
frame (``HOLD``), its GIL free: the frame loop's GL calls hold Python's lock (moderngl never lets
it go), so the keeper, a thread of the same process, would otherwise make the step only in the
gaps between them and it would miss this frame.

The broadcasts are non-blocking, bounded by the job's timeout (``exchange.wait_all``); the header
is two or three integers a frame, the message a step's changed arrays (a 96x96 plate: 1 MB).
"""

from __future__ import annotations

import pickle
import time
from collections import deque

import numpy as np

from multigpu.rank.exchange import wait_all
from multigpu.scene.layout import Scene

#: the most rank 0 waits at a frame's start for a step being made, in frame periods (its median
#: over the last ``PERIODS`` frames): its GIL free, the keeper makes it at once (``spool.next_made``)
HOLD, PERIODS = 0.5, 8
#: room in a board's slot for a step's meta beyond its first step's (its fields' names and ranges)
META_BYTES = 1 << 20


def message(spec, mesh, path, first, write=None) -> bytearray:
    """Rank 0's message of a stream's step ``mesh`` (kept as file ``path``, written by ``write()``;
    the series' first step is file ``first``), coloured as ``spec`` says: what it changes of the
    first step's scene, else its whole scene built from ``path`` (writable: a broadcast's buffer)."""
    from multigpu.scene.models import load_step_file, step_changes

    got = step_changes(spec, mesh, path, first)
    if got is not None:
        changed, meta = got
        return bytearray(pickle.dumps({"changed": changed, "meta": meta}, protocol=pickle.HIGHEST_PROTOCOL))
    if write is not None:
        write()
    return whole(load_step_file(spec, path, first)[0])  # its cells are its own: built alone (and cached)


def whole(scene: Scene) -> bytearray:
    """The message of a whole scene: its arrays (mapped from the cache: sent as arrays), name, meta."""
    arrays = {k: np.asarray(v) for k, v in scene._arrays().items()}
    return bytearray(pickle.dumps({"arrays": arrays, "name": scene.name, "meta": scene.meta},
                                  protocol=pickle.HIGHEST_PROTOCOL))


def step_scene(base: Scene, msg: dict) -> Scene:
    """The scene of a step's message: ``base`` (the first step's) with the step's changes, or the
    step's own arrays."""
    if "changed" in msg:
        from multigpu.scene.same_cells import with_changes

        return with_changes(base, msg["changed"], msg["meta"])
    return Scene(**msg["arrays"], name=msg["name"], meta=msg["meta"])


class Pushed:
    """Every frame of a live run, the step rank 0 made to send next (``made``: rank 0's ``(last
    sent) -> (step, message) | None``, ``spool.next_made``) to every rank (``next``); through the
    host's shared memory where every rank is on rank 0's host (``Board``: ``size`` bytes a
    message at most, 0: none), else broadcast."""

    def __init__(self, comm, timeout: float, made=None, size: int = 0):
        self.comm, self.timeout, self.made = comm, float(timeout), made
        self.rank = comm.Get_rank()
        self.sent = -1
        self.starts: deque[float] = deque(maxlen=PERIODS + 1)  # rank 0: when the last frames asked
        self.board = Board.make(comm, self.timeout, size) if size else None
        # (step, message bytes[, board slot or -1]); step -1: nothing new
        self.head = np.zeros(2 if self.board is None else 3, dtype=np.int64)
        self.frames = self.landed = 0  # frames that asked (``next``), frames whose rows landed (``land``)

    def hold(self) -> float:
        """How long rank 0 waits for a step its keeper is making (``spool.next_made``): ``HOLD`` of
        the median of the last frames' periods (0 until there are some)."""
        self.starts.append(time.monotonic())
        if len(self.starts) < 3:
            return 0.0
        return HOLD * float(np.median(np.diff(self.starts)))

    def land(self) -> None:
        """A frame's rows landed on this rank (in order): every rank is past that frame's reading."""
        self.landed += 1

    def next(self) -> tuple[int, dict] | None:
        """Collective, every frame: ``(step, its message)`` where rank 0 has a step made to send, on
        every rank alike; None otherwise."""
        frame, self.frames = self.frames, self.frames + 1
        got = self.made(self.sent, self.hold()) if self.rank == 0 else None
        if self.board is None:
            k, buf = broadcast(self.comm, got, self.timeout, self.head)
        else:
            k, buf = self.board.send(self.comm, got, self.timeout, self.head, frame, self.landed)
        if k < 0:
            return None
        self.sent = k
        return k, pickle.loads(buf)


class Board:
    """Two slots of a host's shared memory, each holding one of rank 0's messages, where every
    rank is on rank 0's host: rank 0 copies a message into a slot and broadcasts only the header
    naming it, every rank reads it from there (a 96x96 plate's 1 MB broadcast took some 2 ms of
    every rank's swap frame, waiting for each other's turns on shared cores). Rank 0 writes a slot
    only once the rows of the frame that last read it have landed (every rank posts its row after
    reading), else, like a message over ``size`` bytes (a step of cells of its own), it is sent
    by broadcast."""

    def __init__(self, memory: np.ndarray, size: int):
        self.memory, self.size = memory, int(size)
        self.read_at = [-1, -1]  # the frame each slot was last read in
        self.slot = 0  # the slot rank 0 writes next

    @classmethod
    def make(cls, comm, timeout: float, size: int) -> "Board | None":
        """The board of ``size`` bytes a slot, or None (every rank the same) where the ranks span
        several hosts or the host's segment cannot be had (the messages are broadcast then)."""
        from mpi4py import MPI

        from multigpu.rank.shared import host_segment

        node = comm.Split_type(MPI.COMM_TYPE_SHARED)
        try:
            if node.Get_size() != comm.Get_size():  # (every rank sees it alike)
                return None
            most = np.zeros(1, dtype=np.int64)  # every rank's slot the same size
            wait_all([comm.Iallreduce(np.array([size], dtype=np.int64), most, op=MPI.MAX)], timeout, "a stream's steps")
            size = int(most[0])
            memory, _ = host_segment(comm, node, 2 * size, timeout, "a stream's steps")
            return None if memory is None else cls(memory, size)
        finally:
            node.Free()

    def send(self, comm, got: tuple[int, bytearray] | None, timeout: float, head: np.ndarray, frame: int,
             landed: int) -> tuple:
        """``broadcast``'s ``(number, buffer)`` on every rank, the bytes through a slot where they fit."""
        if comm.Get_rank() == 0:
            head[:] = -1, 0, -1
            if got is not None:
                slot = self.slot
                free = len(got[1]) <= self.size and landed > self.read_at[slot]
                head[:] = got[0], len(got[1]), slot if free else -1
                if free:
                    self.memory[slot * self.size:slot * self.size + len(got[1])] = np.frombuffer(got[1], np.uint8)
                    self.slot ^= 1
        wait_all([comm.Ibcast(head, root=0)], timeout, "live step")
        k, size, slot = int(head[0]), int(head[1]), int(head[2])
        if k < 0:
            return -1, None
        if slot < 0:  # (a message too big, or its slot still being read)
            buf = np.frombuffer(got[1], dtype=np.uint8) if comm.Get_rank() == 0 else np.empty(size, dtype=np.uint8)
            wait_all([comm.Ibcast(buf, root=0)], timeout, "live step")
            return k, buf
        self.read_at[slot] = frame
        return k, self.memory[slot * self.size:slot * self.size + size].copy()


def step_bytes(base: Scene) -> int:
    """The most bytes a step's message in ``base``'s layout takes (``same_cells.changes``: its
    vertices, colours, boxes and meta, pickled), with room to spare for its meta."""
    n, v = base.n_objects, len(base.vertices)
    parts = 0 if base.part_count is None else len(base.part_count)
    return int(base.vertices.nbytes + 4 * v + 8 * (8 * n + 6 * parts + 3)) + META_BYTES + len(pickle.dumps(base.meta))


def broadcast(comm, got: tuple[int, bytearray] | None, timeout: float, head: np.ndarray | None = None) -> tuple:
    """Rank 0's ``got`` ``(number, bytes)`` on every rank, ``(number, buffer)``: two non-blocking
    broadcasts (the number and size, then the bytes), bounded by ``timeout``; ``(-1, None)`` where
    rank 0 has none. ``head``: the two-integer buffer to reuse."""
    head = np.zeros(2, dtype=np.int64) if head is None else head
    root = comm.Get_rank() == 0
    if root:
        head[:] = (-1, 0) if got is None else (got[0], len(got[1]))
    wait_all([comm.Ibcast(head, root=0)], timeout, "live step")
    k, size = int(head[0]), int(head[1])
    if k < 0:
        return -1, None
    buf = np.frombuffer(got[1], dtype=np.uint8) if root else np.empty(size, dtype=np.uint8)
    wait_all([comm.Ibcast(buf, root=0)], timeout, "live step")
    return k, buf


def first_step(comm, scene_of, have: bool, timeout: float) -> Scene | None:
    """A stream's first step where this rank's host cannot read it (another PC: rank 0 keeps the
    steps on its own disk): rank 0's scene of it (``scene_of()``, called on rank 0 where some rank
    lacks it) sent whole; None on every rank that has the file (``have``), or where all have it."""
    from multigpu.rank.exchange import allgather_text

    lacking = [t != "1" for t in allgather_text(comm, "1" if have else "0", timeout, "a stream's first step", 2)]
    if not any(lacking):
        return None
    _, buf = broadcast(comm, (0, whole(scene_of())) if comm.Get_rank() == 0 else None, timeout)
    return step_scene(None, pickle.loads(buf)) if lacking[comm.Get_rank()] else None
