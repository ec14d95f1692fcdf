"""Frame exchange through node-shared memory: the parts a host's ranks need from each other, in
one shared-memory segment per host; messages between hosts.

A rank copies the parts of its rendered pieces that tiles of its own host's ranks need into its
slice of the host's segment before the frame's barrier, and after it every tile owner copies (or
depth-merges) them straight from the senders' slices: one copy per pixel instead of pack, two
message copies and unpack. A rank's own tile's parts never leave its pieces; parts for ranks on
other hosts go as messages (``composite``, which also merges every part in ascending sender
order), as DESIGN.md has it: shared per node, messages between nodes. Each slice is a ring of
frames (``core.inflight.slots``: 2 in the strict order, 3 at latency 1 and 2, 4 at latency 3): the
loop's waits let a rank run at most ``held_back_reach`` frames ahead of a peer still reading a
frame's parts, so a slot is never overwritten while a peer still reads it. The barrier orders the
stores and the loads: both MPIs synchronize a barrier between ranks of one host through
shared-memory atomics with release and acquire fences.

The segment is ours, not MPI's (``MPI_Win_allocate_shared``). The host's lowest rank creates a
file in ``/dev/shm`` and reserves every byte of it up front (``posix_fallocate``), the host's
ranks map it, and it is unlinked as soon as every rank has: a segment that cannot be made fails
at once, with the system's reason, and the job uses messages; a full ``/dev/shm`` later can not
kill a rank with SIGBUS at a page first touched mid-run; a killed job leaves no file behind. (Open
MPI 4.1 does not return from a shared-window allocation that fails: under RLIMIT_FSIZE its run
never ended.) Before making it, every rank still checks that its file-size limit and the free
space of ``/dev/shm`` hold its host's segment (``room``), so the reason names the limit.

Layout of a slot: the rank's parts for its host's other ranks in ``transfers`` order, each
its RGB bytes, then (sort-last) its float32 depth.
"""

from __future__ import annotations

import mmap
import os
import resource
import secrets

import numpy as np

from multigpu.core.work import Piece
from multigpu.errors import InputError
from multigpu.rank.composite import Sent, _pack, _unpack, post
from multigpu.rank.exchange import agree, allgather_text, wait_all

#: the most bytes a host's segment may hold (its ranks, both halves) before the job uses messages
MAX_SHARED_BYTES = 1 << 30


#: where the host's segment file is made (tmpfs on Linux; ``MULTIGPU_SHM_DIR`` names another)
SHM = "/dev/shm"


def room(nbytes: int, shm: str = SHM) -> str | None:
    """Why this process cannot back a shared segment of ``nbytes`` (None: it can): its file-size
    limit, or the free space of ``shm`` where that exists (a container's is often 64 MiB)."""
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if soft != resource.RLIM_INFINITY and soft < nbytes:
        return f"the file-size limit ({soft} bytes) is below the {nbytes}-byte segment"
    try:
        st = os.statvfs(shm)
    except OSError:
        return None
    free = st.f_bavail * st.f_frsize
    if free < nbytes:
        return f"{shm} has {free} bytes free, below the {nbytes}-byte segment"
    return None


def reserve(nbytes: int, shm: str = SHM) -> tuple[str, str | None]:
    """A new file of ``nbytes`` in ``shm`` with every byte reserved now (``posix_fallocate``):
    (its path, None), or ("", why not) with nothing left behind."""
    if not hasattr(os, "posix_fallocate"):  # not Linux
        return "", "this system cannot reserve a file's blocks (no posix_fallocate)"
    path = os.path.join(shm, f"multigpu-{os.getpid()}-{secrets.token_hex(4)}")
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        return "", f"cannot create a segment in {shm}: {exc.strerror}"
    try:
        os.posix_fallocate(fd, 0, nbytes)  # EFBIG past the file-size limit (Python ignores SIGXFSZ)
    except OSError as exc:
        os.unlink(path)
        return "", f"cannot reserve {nbytes} bytes in {shm}: {exc.strerror}"
    finally:
        os.close(fd)
    return path, None


def attach(path: str, nbytes: int) -> np.ndarray:
    """The file at ``path`` mapped shared, as ``nbytes`` writable bytes (the mapping outlives
    the file's name)."""
    fd = os.open(path, os.O_RDWR)
    try:
        return np.frombuffer(mmap.mmap(fd, nbytes), dtype=np.uint8)
    finally:
        os.close(fd)


def _map_segment(comm, node, nbytes: int, timeout: float, shm: str) -> tuple[np.ndarray | None, str | None]:
    """This host's segment of ``nbytes``, made by its lowest rank (``node`` rank 0) and mapped by
    every rank of ``node``, or (None, why) where any rank of the job (``comm``) could not: every
    rank the same. The file's name goes once every rank has mapped it or failed to, and also
    when a wait here fails, so no file outlives the setup."""
    path, why = reserve(nbytes, shm) if node.Get_rank() == 0 else ("", None)
    made = bool(path)
    try:
        path = allgather_text(node, path or f"!{why}", timeout, "shared segment")[0]
        memory = None
        if path.startswith("!"):
            why = path[1:]
        else:
            try:
                memory = attach(path, nbytes)
            except OSError as exc:
                why = f"cannot map {path}: {exc.strerror}"
        why = agree(comm, why, timeout, "shared segment")
        return (None, why) if why else (memory, None)
    finally:
        if made:
            os.unlink(path)


def host_segment(comm, node, total: int, timeout: float, what: str = "shared segment",
                 why: str | None = None) -> tuple[np.ndarray | None, str | None]:
    """A segment of ``total`` bytes on every host (``_map_segment``, in ``MULTIGPU_SHM_DIR`` or
    /dev/shm), or (None, why not) where it would exceed ``MAX_SHARED_BYTES``, the directory
    cannot hold it, or making or mapping it fails: every rank of the job (``comm``) the same.
    ``why``: a reason this rank has already (every rank then goes without)."""
    shm = os.environ.get("MULTIGPU_SHM_DIR", SHM)
    if why is None:
        why = (f"the segment ({total} bytes) would exceed {MAX_SHARED_BYTES} bytes" if total > MAX_SHARED_BYTES
               else room(total, shm))
    why = agree(comm, why, timeout, what)
    if why:
        return None, why
    return _map_segment(comm, node, total, timeout, shm)


class SharedPieces:
    """The node-shared exchange backend: this host's ranks' slices of its shared segment, as numpy
    views; parts for ranks on other hosts go as messages (``composite``). ``make``
    gives (None, why) when no two ranks share a host, the segment would be too big, or a rank
    finds no room; it refuses (one line) ranks on several hosts where the user asked for
    ``--exchange shared``."""

    def __init__(self, comm, timeout: float, segments: dict[int, np.ndarray], slot: int, with_depth: bool,
                 slots: int = 2):
        self.comm, self.timeout, self.me = comm, timeout, comm.Get_rank()
        self.links: dict = {}  # the codec of each rank on another host whose messages travel compressed
        self.bits = 0  # colour bits the next frames drop on those links (a lossy frame)
        self.segments, self.slot, self.depth, self.slots = segments, slot, with_depth, slots
        self.host = frozenset(segments)  # the job ranks on this rank's host, itself included
        self.near = self.host - {self.me}
        self.name = "shared" if len(self.host) == comm.Get_size() else "shared + messages"

    @classmethod
    def make(cls, comm, size: tuple[int, int], with_depth: bool, timeout: float,
             asked: bool = True, slots: int = 2, layers: int = 1) -> "tuple[SharedPieces | None, str | None]":
        """The backend, or None and why not (every rank the same). ``asked``: the user chose
        ``--exchange shared``, so ranks on several hosts are an error, not a reason. ``slots``:
        frames a rank's segment holds at once (``core.inflight.slots``).
        ``layers``: how many times a rank's pieces may cover the display (the decomposition's)."""
        from mpi4py import MPI

        per_slot = cls.slot_bytes(size, with_depth, layers)
        K = comm.Get_size()
        node = comm.Split_type(MPI.COMM_TYPE_SHARED)
        try:
            n, at = node.Get_size(), node.Get_rank()
            most = np.zeros(1, dtype=np.int64)
            wait_all([comm.Iallreduce(np.array([n], dtype=np.int64), most, op=MPI.MAX)], timeout, "shared segment")
            if n != K and asked:  # every rank sees it: all refuse alike
                raise InputError.of("exchange", "shared needs every rank on one host, but the job spans "
                                    "several (use --exchange messages or auto)")
            if most[0] < 2:
                return None, "no two ranks share a host"
            memory, why = host_segment(comm, node, slots * per_slot * n, timeout)  # this host's segment
            if why:
                return None, why
            # every job rank's host (its host's lowest job rank) and node rank
            lead = np.zeros(1, dtype=np.int64)
            wait_all([node.Iallreduce(np.array([comm.Get_rank()], dtype=np.int64), lead, op=MPI.MIN)], timeout,
                     "shared segment")
            mine = np.array([lead[0], at], dtype=np.int64)
            every = np.zeros((K, 2), dtype=np.int64)
            wait_all([comm.Iallgather(mine, every)], timeout, "shared segment")
            places = {r: int(every[r, 1]) for r in range(K) if every[r, 0] == lead[0]}
            return cls.over(comm, timeout, memory, places, per_slot, with_depth, slots), None
        finally:
            node.Free()

    @staticmethod
    def slot_bytes(size: tuple[int, int], with_depth: bool, layers: int = 1) -> int:
        """Bytes of a rank's slot: its parts for its host's other ranks cover the display at most
        ``layers`` times, colour (and depth) per pixel."""
        return size[0] * size[1] * (7 if with_depth else 3) * layers

    @classmethod
    def over(cls, comm, timeout: float, memory: np.ndarray, places: dict[int, int], per_slot: int,
             with_depth: bool, slots: int) -> "SharedPieces":
        """The backend over a host's ``memory``: ``places`` maps each job rank on this host to its
        place on the host, whose ``slots`` slots of ``per_slot`` bytes are its slice."""
        span = slots * per_slot
        segments = {r: memory[at * span:(at + 1) * span] for r, at in places.items()}
        return cls(comm, timeout, segments, per_slot, with_depth, slots)

    def _base(self, frame: int) -> int:
        return (frame % self.slots) * self.slot

    def _publish(self, frame: int, me: int, rects, rendered: list, plan: list[Piece], with_depth: bool) -> None:
        """Copy the parts of this rank's rendered pieces ``(rgb, z or None)`` that tiles of this
        host's other ranks need into the frame's slot, in ``plan`` order (its own tile's parts
        stay where they are; parts for other hosts leave as messages)."""
        near = self.near
        out = [p for p in plan if p.sender == me and p.receiver in near]  # parts, not objects
        if out:
            _pack(self.segments[me][self._base(frame):], out, rects[me], rendered, with_depth)

    def start(self, frame: int, me: int, rects, rendered: list, plan: list[Piece], with_depth: bool):
        """The frame's parts published, its messages to other hosts posted, and a barrier that
        completes once every rank has published it (``wait``)."""
        self._publish(frame, me, rects, rendered, plan, with_depth)  # this frame's: the room may hold depth
        posted = post(self.comm, me, rects, rendered, plan, with_depth, self.near, frame, self.links, self.bits)
        return frame, plan, posted, self.comm.Ibarrier()

    def wait(self, started) -> None:
        """Until every rank has published the frame (bounded)."""
        wait_all([started[3]], self.timeout, "synchronization")

    def finish(self, started, tile, color: np.ndarray, depth: np.ndarray | None = None) -> Sent:
        """Compose rank ``me``'s tile (after ``wait``) from its own pieces, the parts this host's
        ranks published and messages from other hosts: the same result as messages alone,
        parts in ascending sender order. Returns the bytes others get from this rank (colour
        and depth, of which depth)."""
        frame, plan, posted, _ = started
        views = self._views(frame, self.me, plan, depth is not None)
        sent = posted.complete(tile, self.timeout, color, depth, lambda s, parts: views[s])
        return self._counted(plan, sent, depth is not None)

    def close(self, collective: bool = True) -> None:
        """Let the mapping go (the memory is the system's again once every rank on the host has)."""
        self.segments = {}

    def _counted(self, plan: list[Piece], sent: Sent, with_depth: bool) -> Sent:
        """Bytes others get from this rank: by message, and read from its segment (never on a wire)."""
        me, near = self.me, self.near
        px = sum(p.pixels for p in plan if p.sender == me and p.receiver in near)  # read by this host's ranks
        return sent._replace(bytes=sent.bytes + px * (7 if with_depth else 3),
                             depth=sent.depth + (4 * px if with_depth else 0))

    def _views(self, frame: int, me: int, plan: list[Piece], with_depth: bool) -> dict[int, list]:
        """Views ``(part, rgb, z)`` of the parts this host's other ranks published for rank
        ``me``, by sender: a sender's segment holds its parts for its host's other ranks in
        ``plan`` order."""
        host, near, per_px, base = self.host, self.near, 7 if with_depth else 3, self._base(frame)
        at: dict[int, int] = {}
        views: dict[int, list] = {}
        for p in plan:  # pieces x tiles, not objects
            s, r = p.sender, p.receiver
            if s in near and r in host and r != s:
                start = at.get(s, base)
                at[s] = start + p.pixels * per_px
                if r == me:
                    views.setdefault(s, []).extend(_unpack(self.segments[s][start:], [p], with_depth))
        return views
