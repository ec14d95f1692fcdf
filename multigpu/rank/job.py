"""The MPI job's lifecycle, at the edge: liveness, failure notices, interrupts, the exit.

Bounded waits alone cannot tell a slow rank from a stopped one, so a run either kills long
frames or hangs on a stalled rank for the whole ``--timeout``. ``Job`` adds a liveness
channel beside the frame's messages: a daemon thread on every rank sends a heartbeat to every
other rank each ``interval`` seconds on a duplicated communicator (so it never matches frame
traffic) and drains what arrives. A peer that stays silent for ``liveness`` seconds is
stalled (``SIGSTOP``, a frozen node), whatever the frame timeout; a rank that fails sends a
failure notice on the same channel, so the others stop waiting at once and rank 0 saves what
the run produced before the job ends.

Every bounded wait (``exchange.wait_all``) calls ``Job.check`` while it polls; ``check``
raises ``PeerStalled``, ``PeerFailed`` or ``Interrupted`` (SIGINT/SIGTERM seen and the wait
still blocked ``interrupt_grace`` seconds later). Needs ``MPI_THREAD_MULTIPLE`` (mpi4py asks
for it by default); without it the job runs on timeouts alone.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

import numpy as np

from multigpu import exits
from multigpu.config import DEFAULT_LIVENESS
from multigpu.rank import exchange

HEARTBEAT, FAILED, BYE = 1, 2, 3
#: how long a closing rank waits for its peers' last heartbeats (their BYE), so none is left
#: unreceived at MPI_Finalize (UCX warns of each such message between hosts)
DRAIN = 2.0
#: seconds between heartbeats
INTERVAL = 0.5
#: seconds between the heartbeat thread's polls for arrivals: each poll drives MPI's progress,
#: which messages between hosts need on both ends (over TCP, a heartbeat polled for only once
#: per interval took seconds to arrive and the liveness check took a busy peer for a dead one)
POLL = 0.02
#: a wait blocked this long after SIGINT/SIGTERM gives up (the others did not stop with us)
INTERRUPT_GRACE = 3.0
#: after a failure elsewhere, a rank other than 0 gives rank 0 this long to save and end the job
FAILURE_GRACE = 10.0
#: pause before MPI_Abort, so the launcher forwards the last lines a rank printed
ABORT_PAUSE = 0.3
#: a job ending with a non-zero code: every rank leaves this long after the last reached the exit
EXIT_PAUSE = 1.0  # MPI_Finalize itself took over 0.6 s on a loaded machine: a rank still in it was killed (exit 9)
#: a peer silent this long is not beating now (shorter than ``liveness``: used once a run failed)
SILENT = 3.0


class PeerStalled(exchange.PeerTimeout):
    """A peer sent no heartbeat for ``liveness`` seconds: it is stopped or its node froze."""

    def __init__(self, ranks: list[int], seconds: float):
        self.ranks = ranks
        who = ", ".join(map(str, ranks))
        super().__init__(f"rank {who} stopped responding (no heartbeat for {seconds:g} s); ending the job")


class PeerFailed(RuntimeError):
    """A peer announced its own failure (it prints its message itself)."""

    def __init__(self, rank: int, message: str):
        self.rank = rank
        self.kind = message.split(":", 1)[0]  # the failure's class name (``announce_failure``)
        super().__init__(f"rank {rank} failed: {message}")


class Interrupted(Exception):
    """SIGINT or SIGTERM arrived; ``code`` is the conventional exit status 128 + signal."""

    def __init__(self, signum: int):
        self.signum = signum
        self.code = exits.by_signal(signum)
        super().__init__(f"interrupted by {signal.Signals(signum).name}")


class Job:
    """Liveness and interrupt state of one rank in a running job (see the module doc)."""

    def __init__(self, comm, liveness: float = DEFAULT_LIVENESS, interval: float = INTERVAL):
        from mpi4py import MPI

        self.rank, self.size = comm.Get_rank(), comm.Get_size()
        self.liveness = float(liveness)
        self.interval = float(interval)
        self.signum: int | None = None
        self.signal_time = 0.0
        self._watching = None  # the token of this job's check in every bounded wait (``__enter__``)
        self.failed: tuple[int, str] | None = None
        self.in_frames = False  # set by the frame loop: signals then stop after the frame
        start = time.monotonic()
        self.last_seen = np.full(self.size, start)
        self._stop = threading.Event()
        self._thread = None
        self.thread_cpu = 0.0  # CPU seconds the heartbeat thread has used so far
        self._old_handlers: dict[int, object] = {}
        threaded = MPI.Query_thread() == MPI.THREAD_MULTIPLE
        self.enabled = self.liveness > 0 and self.size > 1 and threaded
        self.comm = comm.Dup() if self.enabled else None
        if self.enabled:
            self._thread = threading.Thread(target=self._beat, name="multigpu-heartbeat", daemon=True)
            self._thread.start()

    # -- the heartbeat thread
    def _beat(self) -> None:
        from mpi4py import MPI

        peers = [p for p in range(self.size) if p != self.rank]
        token = np.zeros(1, dtype=np.uint8)
        self._pending = []
        next_beat = 0.0
        while not self._stop.is_set():
            if time.monotonic() >= next_beat:
                next_beat = time.monotonic() + self.interval
                self._pending = [r for r in self._pending if not r.Test()]
                if len(self._pending) < 64 * len(peers):  # a stopped peer does not pile up sends without end
                    self._pending += [self.comm.Isend([token, MPI.BYTE], dest=p, tag=HEARTBEAT) for p in peers]
            self._receive()  # between beats too: every poll drives MPI's progress
            self.thread_cpu = time.thread_time()
            self._stop.wait(POLL)

    def _receive(self) -> set[int]:
        """Take every message waiting (heartbeats, failures, goodbyes); the peers that said BYE."""
        from mpi4py import MPI

        status, byes = MPI.Status(), set()
        while self.comm.Iprobe(MPI.ANY_SOURCE, MPI.ANY_TAG, status):
            src, tag, n = status.Get_source(), status.Get_tag(), status.Get_count(MPI.BYTE)
            buf = np.empty(max(n, 1), dtype=np.uint8)
            self.comm.Recv([buf, n, MPI.BYTE], source=src, tag=tag)
            self.last_seen[src] = time.monotonic()
            if tag == FAILED and self.failed is None:
                self.failed = (src, bytes(buf[:n]).decode("utf-8", "replace"))
            elif tag == BYE:
                byes.add(src)
        return byes

    def _drain(self) -> None:
        """After the last heartbeat: say BYE to every peer and take what each sent until its
        BYE (messages from one sender arrive in order), for at most ``DRAIN`` s; so no
        heartbeat is left unreceived when MPI finalizes."""
        from mpi4py import MPI

        peers = {p for p in range(self.size) if p != self.rank}
        token = np.zeros(1, dtype=np.uint8)
        sends = [self.comm.Isend([token, MPI.BYTE], dest=p, tag=BYE) for p in peers]
        deadline, gone = time.monotonic() + DRAIN, set()
        while True:
            gone |= self._receive()
            done = MPI.Request.Testall(sends + self._pending)
            if (gone >= peers and done) or time.monotonic() > deadline:
                break
            time.sleep(1e-3)

    # -- what waits ask
    def stalled(self) -> list[int]:
        """Peers silent for longer than ``liveness`` seconds."""
        if not self.enabled:
            return []
        silent = time.monotonic() - self.last_seen > self.liveness
        silent[self.rank] = False
        return [int(p) for p in np.flatnonzero(silent)]

    def silent(self, rank: int) -> bool:
        """Whether ``rank`` has sent no heartbeat for ``SILENT`` seconds (False without liveness)."""
        return self.enabled and time.monotonic() - self.last_seen[rank] > max(SILENT, 4 * self.interval)

    def check(self) -> None:
        """Raise if a peer failed or stalled, or if an interrupt has waited out its grace."""
        if self.failed is not None:
            raise PeerFailed(*self.failed)
        if self.signum is not None and time.monotonic() - self.signal_time > INTERRUPT_GRACE:
            raise Interrupted(self.signum)
        stalled = self.stalled()
        if stalled:
            raise PeerStalled(stalled, self.liveness)

    def announce_failure(self, message: str) -> None:
        """Tell every peer that this rank failed (best effort, never blocks)."""
        if not self.enabled:
            return
        from mpi4py import MPI

        data = np.frombuffer(message.encode("utf-8")[:2000], dtype=np.uint8).copy()
        self._keep = [(data, self.comm.Isend([data, MPI.BYTE], dest=p, tag=FAILED))
                      for p in range(self.size) if p != self.rank]

    # -- signals: SIGINT/SIGTERM stop the run after the current frame
    def catch_signals(self) -> None:
        for s in (signal.SIGINT, signal.SIGTERM):
            self._old_handlers[s] = signal.signal(s, self._on_signal)

    def _on_signal(self, signum, frame) -> None:
        if self.signum is None:
            self.signum, self.signal_time = signum, time.monotonic()
        if not self.in_frames:  # setup: stop now (a frame in flight finishes first)
            raise Interrupted(signum)

    @property
    def interrupted(self) -> bool:
        return self.signum is not None

    def __enter__(self) -> "Job":
        self._watching = exchange.watch(self.check)
        return self

    def __exit__(self, kind, *exc) -> None:
        self.close(drain=kind is None)

    def close(self, drain: bool = False) -> None:
        """Stop the heartbeat, unhook from waits, restore the signal handlers. ``drain`` (a run
        every rank ended alike): take the peers' last heartbeats first (``_drain``)."""
        if self._watching is not None:
            exchange.unwatch(self._watching)
            self._watching = None
        for s, h in self._old_handlers.items():
            signal.signal(s, h)
        self._old_handlers.clear()
        if self._thread is not None:
            self._stop.set()
            self._thread.join(timeout=5.0)
            if drain and not self._thread.is_alive():
                self._drain()
            self._thread = None


def launcher_rank() -> int:
    """This process's rank as the launcher set it (MPICH/Hydra, Open MPI, Slurm), 0 if none.
    Readable before MPI starts, so argument errors can be printed once."""
    for var in ("PMI_RANK", "OMPI_COMM_WORLD_RANK", "PMIX_RANK", "SLURM_PROCID"):
        v = os.environ.get(var)
        if v is not None and v.strip().isdigit():
            return int(v)
    return 0


def collective_exit(code: int) -> None:
    """End this rank with ``code`` after every rank agreed to stop: finalize MPI and leave,
    so the launcher sees a plain exit status and prints no ``MPI_Abort`` banner (mpi4py's
    ``-m mpi4py`` would abort on a non-zero ``SystemExit``)."""
    sys.stdout.flush()
    sys.stderr.flush()
    leave = None
    try:
        from mpi4py import MPI

        if MPI.Is_initialized() and not MPI.Is_finalized():
            if code:  # one moment for every rank to leave at: MPICH's launcher kills (and reports
                # exit 9 for) the ranks still finalizing when the first exits non-zero
                leave = MPI.COMM_WORLD.allreduce(time.time(), op=MPI.MAX) + EXIT_PAUSE
            MPI.Finalize()
    finally:
        if leave is not None:
            time.sleep(min(max(leave - time.time(), 0.0), 2 * EXIT_PAUSE))
        os._exit(code)


def teardown_barrier(comm) -> None:
    """Wait (bounded) until every rank has closed its window and GL context, deaf to further
    SIGINT/SIGTERM, so the ranks leave together: once one exits non-zero, MPICH's launcher
    kills those still busy (and reports exit 9)."""
    for s in (signal.SIGINT, signal.SIGTERM):  # the launcher's forwarded copy of the signal, arriving late
        signal.signal(s, signal.SIG_IGN)
    try:
        exchange.barrier(comm, 10.0)
    except exchange.PeerTimeout:
        pass
