"""Waits that never hang, the setup agreement, the synchronization barrier and the partition
broadcast: the MPI primitives the frame loop uses (the frame exchange itself is ``composite.py``).

Waiting polls with short sleeps instead of MPI's busy-wait, so ranks that wait do not steal a
core from ranks still rendering when ranks outnumber cores, and every wait is bounded: a peer
that died or hangs turns into ``PeerTimeout`` instead of a frozen wall.
"""

from __future__ import annotations

import time
from contextvars import ContextVar, Token

import numpy as np

TAG = 7
#: checks every bounded wait of this thread runs while it polls (``job.Job.check``: stalled or
#: failed peers, interrupts); each raises to end the wait. A context variable, set by ``watch``:
#: a job watches its own waits only (ranks as threads of one process each have theirs)
_WATCH: ContextVar[tuple] = ContextVar("multigpu_watch", default=())


def watch(check) -> Token:
    """Run ``check`` in every bounded wait from now on (in this thread); ``unwatch`` the token."""
    return _WATCH.set((*_WATCH.get(), check))


def unwatch(token: Token) -> None:
    """Stop what ``watch`` started (in the thread that started it)."""
    try:
        _WATCH.reset(token)
    except ValueError:  # another thread's token: nothing of this thread's to undo
        pass
#: a wait runs the checks only once it has lasted this long (s): a frame's waits are mostly
#: shorter, and the checks (a few numpy calls) cost ~10 us of CPU per poll with cold caches,
#: while what they look for (a peer silent for seconds, a failure, an interrupt's grace) is
#: seen as soon either way
CHECK_AFTER = 0.01
#: the longest sleep between tests of a wait (s). MPI moves a non-blocking collective on only
#: inside a test, so every step of a gather waits for its partner's next test: at 2 ms a frame's
#: row gather and barriers took 7 ms a frame at 2x2 and 21 ms at 4x4 on an H100 (the frame period
#: 9.1 and 23 ms, against 2.8 and 5.0 at 0.1 ms); on this 2-core machine with 4 ranks of small
#: frames, 8.4 against 1.9 ms, the whole job's CPU time no higher (docs/BENCHMARKS.md)
POLL = 1e-4


class PeerTimeout(RuntimeError):
    """A wait on other ranks exceeded its bound."""


def wait_all(requests, timeout: float, what: str, most: float | None = None, statuses: list | None = None) -> None:
    """Complete MPI requests, sleeping between tests (growing to ``most`` s); raise PeerTimeout
    after ``timeout`` s. The requests' own class tests them (``MPI.Request.Testall``, or a
    stand-in communicator's), so waiting imports no MPI: a process that never sent stays
    MPI-free. ``statuses``: a list that gets each request's status (what a receive got)."""
    if not requests:
        return
    start = time.monotonic()
    deadline, checks = start + timeout, start + CHECK_AFTER
    sleep, most = 1e-5, POLL if most is None else most
    testall = type(requests[0]).Testall
    if statuses is not None:
        test = testall
        testall = lambda r: test(r, statuses)  # noqa: E731
    while not testall(requests):
        now = time.monotonic()
        if now > deadline:
            raise PeerTimeout(f"{what}: no answer from other ranks within {timeout:g} s")
        if now > checks:
            for check in _WATCH.get():
                check()
        time.sleep(sleep)
        sleep = min(sleep * 2, most)


def barrier(comm, timeout: float, most: float | None = None) -> None:
    """A bounded, non-spinning barrier (the paper's GPU-GPU synchronization); ``most``: the
    longest sleep between tests (the swap lock's is short: every rank leaves it within as much)."""
    wait_all([comm.Ibarrier()], timeout, "synchronization", most)


def broadcast_partition(comm, part, k: int, n: int, timeout: float):
    """Rank 0's partition on every rank (the ``--partition broadcast`` variant): one
    non-blocking broadcast of regions, loads, splits and the bit-packed (K, N) T' masks."""
    from multigpu.core.balance import Partition

    m = max(k - 1, 0)
    ints, floats = 5 * k + m + 1, m  # regions, loads, split pixels, piece count (int64); splits (float64)
    head = 8 * (ints + floats)
    buf = np.empty(head + (k * n + 7) // 8, dtype=np.uint8)
    root = comm.Get_rank() == 0
    if root:
        pieces = 0 if part.pieces is None else sum(len(p) for p in part.pieces)
        head_ints = np.concatenate([part.regions.ravel(), part.loads, part.split_pixels, [pieces]]).astype(np.int64)
        buf[:8 * ints] = head_ints.view(np.uint8)
        buf[8 * ints:head] = np.asarray(part.splits, dtype=np.float64).view(np.uint8)
        buf[head:] = np.packbits(part.visible.ravel())
    wait_all([comm.Ibcast(buf, root=0)], timeout, "partition broadcast")
    i = buf[:8 * ints].view(np.int64)
    total = int(i[-1])
    if total:  # a strategy that gives ranks several pieces (cross): counts, rects, packed masks
        more = np.empty(8 * (k + 4 * total) + (total * n + 7) // 8, dtype=np.uint8)
        if root:
            counts = [len(p) for p in part.pieces]
            rects = np.concatenate([np.asarray(p, np.int64).reshape(-1, 4) for p in part.pieces])
            more[:8 * (k + 4 * total)] = np.concatenate([counts, rects.ravel()]).astype(np.int64).view(np.uint8)
            more[8 * (k + 4 * total):] = np.packbits(np.concatenate(part.piece_visible).ravel())
        wait_all([comm.Ibcast(more, root=0)], timeout, "partition broadcast")
    if root:
        return part
    visible = np.unpackbits(buf[head:], count=k * n).reshape(k, n).view(bool)
    regions, loads = i[:4 * k].reshape(k, 4).copy(), i[4 * k:5 * k].copy()
    splits, split_pixels = buf[8 * ints:head].view(np.float64).copy(), i[5 * k:-1].copy()
    if not total:
        return Partition(regions, loads, visible, splits, split_pixels)
    head_p = more[:8 * (k + 4 * total)].view(np.int64)
    at = np.concatenate([[0], np.cumsum(head_p[:k])])
    rects = head_p[k:].reshape(total, 4)
    masks = np.unpackbits(more[8 * (k + 4 * total):], count=total * n).reshape(total, n).view(bool)
    return Partition(regions, loads, visible, splits, split_pixels, None,
                     tuple(rects[at[r]:at[r + 1]].copy() for r in range(k)),
                     tuple(masks[at[r]:at[r + 1]].copy() for r in range(k)))


ERROR_BYTES = 1024  # an agreed setup error travels as a fixed-size buffer


def allgather_text(comm, text: str, timeout: float, what: str, nbytes: int = ERROR_BYTES) -> list[str]:
    """Every rank's ``text`` (UTF-8, cut to ``nbytes - 1`` bytes), on all ranks.

    Non-blocking and bounded: a fixed-size buffer per rank in one ``Iallgather``, so a rank
    that never arrives ends the wait (timeout, or sooner through the job's liveness check)."""
    mine = np.zeros(nbytes, dtype=np.uint8)
    msg = text.encode("utf-8")[:nbytes - 1]
    mine[:len(msg)] = np.frombuffer(msg, dtype=np.uint8)
    allbuf = np.zeros((comm.Get_size(), nbytes), dtype=np.uint8)
    wait_all([comm.Iallgather(mine, allbuf)], timeout, what)
    return [bytes(b).rstrip(b"\0").decode("utf-8", "replace") for b in allbuf]


def agree(comm, error: str | None, timeout: float, what: str = "setup") -> str | None:
    """Every rank's setup outcome; the first error (with its rank where ranks differ) or None,
    on all ranks. ``what`` names the wait in a timeout."""
    bad = [(r, e) for r, e in enumerate(allgather_text(comm, error or "", timeout, what)) if e]
    if not bad:
        return None
    r, e = bad[0]
    return e if len(set(e for _, e in bad)) == 1 else f"rank {r}: {e}"
