"""A stand-in for an MPI communicator: ``K`` ranks as threads of one process (or as calls of one
thread, where nothing waits on a peer), so the frame pipeline runs without ``mpiexec`` and without
starting MPI in the test process.

It answers the calls the frame loop makes (``Get_rank``, ``Get_size``, ``Isend``, ``Irecv``,
``Ibarrier``, ``Iallgather``, ``Igather``, ``Ibcast``) with requests whose class tests them
(``Request.Testall``, as ``exchange.wait_all`` calls it). MPI's rules hold where the pipeline
leans on them: every rank calls the collectives in one order, sends are copied when posted, and
receives from one sender with one tag match its messages in the order both were posted.
"""

from __future__ import annotations

import threading
from collections import deque

import numpy as np

_MISSING = object()


class Request:
    """A non-blocking call's completion: ``test`` is tried on each ``Test`` until it says done."""

    def __init__(self, test):
        self._test, self.done = test, False
        self.count = 0  # bytes a receive got

    def Test(self) -> bool:  # noqa: N802
        if not self.done:
            self.done = bool(self._test())
        return self.done

    @classmethod
    def Testall(cls, requests, statuses=None) -> bool:  # noqa: N802
        done = all([r.Test() for r in requests])  # every one tested, as MPI's does
        if done and statuses is not None:
            statuses[:] = [Status(r.count) for r in requests]
        return done


class Status:
    """What a completed request got: a receive's byte count (``Get_count``, as MPI's)."""

    def __init__(self, count: int):
        self.count = count

    def Get_count(self, datatype=None) -> int:  # noqa: N802
        return self.count


class World:
    """What the ranks share: the messages in flight, the receives posted and each collective's
    contributions (by its place in the ranks' common order)."""

    def __init__(self, size: int):
        self.size = size
        self.lock = threading.Lock()
        self.mail: dict[tuple, deque] = {}  # (source, dest, tag): messages in the order sent
        self.waiting: dict[tuple, deque] = {}  # (source, dest, tag): receives in the order posted
        self.rounds: dict[int, list] = {}  # collective number: each rank's part, then how many took it
        self.dups: dict[int, "World"] = {}  # the n-th Dup's world, made by the first rank to call it

    def comms(self) -> list["ThreadComm"]:
        return [ThreadComm(self, r) for r in range(self.size)]


class ThreadComm:
    """Rank ``rank`` of a ``World``."""

    def __init__(self, world: World, rank: int):
        self.world, self.rank, self.calls = world, rank, 0

    def Get_rank(self) -> int:  # noqa: N802
        return self.rank

    def Dup(self) -> "ThreadComm":  # noqa: N802
        """As MPI's: the same ranks, with messages of their own (the n-th Dup of every rank meets)."""
        w = self.world
        self.duped = getattr(self, "duped", 0) + 1
        with w.lock:
            world = w.dups.setdefault(self.duped, World(w.size))
        return ThreadComm(world, self.rank)

    def Free(self) -> None:  # noqa: N802
        pass

    def Get_size(self) -> int:  # noqa: N802
        return self.world.size

    def Isend(self, buf, dest: int, tag: int = 0) -> Request:  # noqa: N802
        w = self.world
        with w.lock:
            w.mail.setdefault((self.rank, dest, tag), deque()).append(np.array(buf, copy=True))
        return Request(lambda: True)

    def Irecv(self, buf, source: int, tag: int = 0) -> Request:  # noqa: N802
        w, key, me = self.world, (source, self.rank, tag), object()
        with w.lock:
            w.waiting.setdefault(key, deque()).append(me)

        def test() -> bool:
            with w.lock:
                mail, posted = w.mail.get(key), w.waiting[key]
                if not mail or posted[0] is not me:
                    return False
                msg = mail.popleft()
                posted.popleft()
            out = buf.reshape(-1).view(np.uint8)
            data = msg.reshape(-1).view(np.uint8)
            # as MPI: a message may be shorter than its receive (a compressed one), never longer
            assert data.size <= out.size, f"message of {data.size} bytes truncated by a {out.size}-byte receive"
            out[:data.size] = data
            request.count = data.size
            return True

        request = Request(test)
        return request

    def _collective(self, part, finish, needs=None) -> Request:
        """This rank's ``part`` of the next collective; ``finish(parts)`` once the parts of the
        ranks in ``needs`` are in (None: every rank's). As MPI's, a rank's call completes as soon
        as what it receives is there: a gather's sender and a broadcast's root wait for no one."""
        w, n = self.world, self.calls
        self.calls += 1
        with w.lock:
            entry = w.rounds.setdefault(n, [[_MISSING] * w.size, 0])
            entry[0][self.rank] = part
        wanted = range(w.size) if needs is None else needs

        def test() -> bool:
            with w.lock:
                parts = entry[0]
                if any(parts[r] is _MISSING for r in wanted):
                    return False
            finish(parts)
            with w.lock:
                entry[1] += 1
                if entry[1] == w.size and not any(p is _MISSING for p in entry[0]):
                    del w.rounds[n]
            return True

        return Request(test)

    def Ibarrier(self) -> Request:  # noqa: N802
        return self._collective(True, lambda parts: None)

    def Iallgather(self, send, recv) -> Request:  # noqa: N802
        def finish(parts):
            rows = recv.reshape(self.world.size, -1)
            for r, p in enumerate(parts):
                rows[r] = p.reshape(-1)

        return self._collective(np.array(send, copy=True), finish)

    def Igather(self, send, recv, root: int = 0) -> Request:  # noqa: N802
        def finish(parts):
            if self.rank == root:
                rows = recv.reshape(self.world.size, -1)
                for r, p in enumerate(parts):
                    rows[r] = p.reshape(-1)

        return self._collective(np.array(send, copy=True), finish, None if self.rank == root else ())

    def Ibcast(self, buf, root: int = 0) -> Request:  # noqa: N802
        def finish(parts):
            if self.rank != root:
                buf[...] = parts[root].reshape(buf.shape)

        return self._collective(np.array(buf, copy=True) if self.rank == root else None, finish,
                                (root,) if self.rank != root else ())


def run_ranks(size: int, body, timeout: float = 120.0) -> list:
    """``body(comm)`` on ``size`` threads, one rank each; every rank's result, or the first
    rank's error raised here (a rank still running after ``timeout`` s fails the call)."""
    comms = World(size).comms()
    results: list = [None] * size
    errors: list = [None] * size

    def rank(r: int) -> None:
        try:
            results[r] = body(comms[r])
        except BaseException as exc:  # noqa: BLE001 - raised again in the caller's thread
            errors[r] = exc

    threads = [threading.Thread(target=rank, args=(r,), name=f"rank-{r}", daemon=True) for r in range(size)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout)
    if any(t.is_alive() for t in threads):
        raise TimeoutError(f"ranks still running after {timeout:g} s: "
                           f"{[r for r, t in enumerate(threads) if t.is_alive()]}")
    for e in errors:
        if e is not None:
            raise e
    return results
