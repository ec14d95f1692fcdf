"""A live stream's steps sent by rank 0 to every rank, in the frame that first shows them.

Rank 0's keeper (``rank/spool.py``) makes each step it reads ready for the wall in a thread of its
own (``message``): where the step's cells are the first step's, only what it changes of the first
step's scene (``scene/same_cells.changes``: its vertices, colours, origin and boxes, made from the
arrays the stream handed over, no file read), else the whole scene built from its kept file; one
pickled message either way. At every frame's start (every rank at the same frame) rank 0 says the
newest step made that the wall does not show yet (a header: the step and the message's size) and
sends it (a second broadcast), and every rank swaps it in at this very frame: no rank reads a file
for it, no frame's rows have to land to name it, and ranks on other hosts get it the same way.

Both broadcasts are non-blocking, bounded by the job's timeout (``exchange.wait_all``); the header
is two integers a frame, the message a step's changed arrays (a 96x96 plate: 0.3 MB).
"""

from __future__ import annotations

import pickle

import numpy as np

from multigpu.rank.exchange import wait_all
from multigpu.scene.layout import Scene


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
    scene, _ = load_step_file(spec, path, first)  # its cells are its own: built alone (and cached)
    arrays = {k: np.asarray(v) for k, v in scene._arrays().items()}  # (mapped from the cache: sent as arrays)
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
    sent) -> (step, message) | None``, ``spool.next_made``) to every rank (``next``)."""

    def __init__(self, comm, timeout: float, made=None):
        self.comm, self.timeout, self.made = comm, float(timeout), made
        self.rank = comm.Get_rank()
        self.head = np.zeros(2, dtype=np.int64)  # (step, message bytes); -1: nothing new
        self.sent = -1

    def next(self) -> tuple[int, dict] | None:
        """Collective, every frame: ``(step, its message)`` where rank 0 has a step made to send, on
        every rank alike; None otherwise."""
        blob = None
        if self.rank == 0:
            got = self.made(self.sent)
            if got is not None:
                k, blob = got
                self.head[:] = (k, len(blob))
            else:
                self.head[:] = (-1, 0)
        wait_all([self.comm.Ibcast(self.head, root=0)], self.timeout, "live step")
        k, size = int(self.head[0]), int(self.head[1])
        if k < 0:
            return None
        buf = np.frombuffer(blob, dtype=np.uint8) if self.rank == 0 else np.empty(size, dtype=np.uint8)
        wait_all([self.comm.Ibcast(buf, root=0)], self.timeout, "live step")
        self.sent = k
        return k, pickle.loads(buf)
