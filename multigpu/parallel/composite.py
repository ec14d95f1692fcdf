"""Frame exchange and compositing for any decomposition: direct send, one message per pair
(the ``messages`` backend; ``shared.py`` is the other, both merging through ``core.merge``).

Every rank knows every rank's pieces (``core.work``), so both ends of a (sender, receiver)
pair compute the same list of piece parts (``core.work.transfers``) and pack or unpack one
contiguous buffer in that order: colour bytes of each part, then (sort-last) its float32
depth. Colour-only parts tile the display and are copied into the tile. Depth parts are
merged in ascending sender order, each fragment replacing the tile's only where it is
strictly nearer: ranks own ascending ranges of the draw order, so a tie keeps the lower rank's
fragment, as a one-rank GL_LESS render keeps the first drawn. IceT calls this strategy
"direct"; binary swap and radix-k pay off with many ranks per tile, not at one rank per tile.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.merge import merge_part
from multigpu.core.work import Piece
from multigpu.parallel.exchange import wait_all

TAG = 8


def _part(piece_px: np.ndarray, origin, rect) -> np.ndarray:
    """The ``rect`` part of a rendered piece whose lower-left pixel is ``origin``."""
    x0, y0, x1, y1 = rect
    ox, oy = origin
    return piece_px[y0 - oy:y1 - oy, x0 - ox:x1 - ox]


def composite(comm, me: int, rects, rendered: list, plan: list[Piece], tile, timeout: float, color: np.ndarray,
              depth: np.ndarray | None = None, near: frozenset = frozenset(), read=None) -> tuple[int, int]:
    """Compose rank ``me``'s tile into ``color`` (th, tw, 3) [and ``depth`` (th, tw)].

    ``rects`` are every rank's pieces (``Work.rects``), ``rendered[j]`` rank ``me``'s piece j
    as ``(rgb, z)`` (z None without depth), ``plan`` the frame's ``transfers``. With ``depth``
    the tile must hold the background at depth 1.0 on entry. ``near``: ranks whose parts this
    rank reads from shared memory instead of messages, ``read(sender, parts)`` giving their
    views (``shared.py``; its own host's ranks). Returns (bytes sent as messages, of which
    depth bytes). ``post`` and ``Posted.complete`` are its two halves, for frames in flight."""
    return post(comm, me, rects, rendered, plan, depth is not None, near).complete(tile, timeout, color, depth, read)


class Posted:
    """A frame's messages on their way: the sends and receives ``post`` started; ``complete``
    waits for them and composes the tile."""

    def __init__(self, me, rects, rendered, incoming, requests, keep, inbox, sent, zbytes, with_depth, near):
        self.me, self.rects, self.rendered, self.incoming = me, rects, rendered, incoming
        self.requests, self.keep, self.inbox = requests, keep, inbox
        self.sent, self.zbytes, self.with_depth, self.near = sent, zbytes, with_depth, near

    def complete(self, tile, timeout: float, color: np.ndarray, depth: np.ndarray | None = None,
                 read=None) -> tuple[int, int]:
        me, rects, rendered, incoming = self.me, self.rects, self.rendered, self.incoming
        # colour parts tile the display, so their order is free: this rank's own go in while the
        # messages travel (fewer polls of the wait); depth parts merge in ascending sender order
        early = me in incoming and not self.with_depth
        if early:
            _merge(color, depth, tile, [(p, *_local(p, rects[me], rendered)) for p in incoming[me]])
        wait_all(self.requests, timeout, "frame exchange")
        self.keep = None
        for s in sorted(incoming):  # ascending sender: the depth tie rule
            if s == me and early:
                continue
            parts = incoming[s]
            if s == me:
                views = [(p, *_local(p, rects[me], rendered)) for p in parts]
            else:
                views = read(s, parts) if s in self.near else _unpack(self.inbox[s], parts, self.with_depth)
            _merge(color, depth, tile, views)
        return self.sent, self.zbytes


def post(comm, me: int, rects, rendered: list, plan: list[Piece], with_depth: bool,
         near: frozenset = frozenset()) -> Posted:
    """Start a frame's exchange: this rank's parts for other ranks' tiles packed and sent, its
    receives posted (nothing for ``near`` ranks, read from shared memory)."""
    per_px = 7 if with_depth else 3
    outgoing: dict[int, list[Piece]] = {}
    incoming: dict[int, list[Piece]] = {}
    for p in plan:  # K*K pairs x pieces, not objects
        if p.sender == me:
            outgoing.setdefault(p.receiver, []).append(p)
        if p.receiver == me:
            incoming.setdefault(p.sender, []).append(p)
    away = near | {me}  # parts that travel by no message
    sends = {r: parts for r, parts in outgoing.items() if r not in away}
    recvs = {s: parts for s, parts in incoming.items() if s not in away}
    if sends or recvs:  # only then: a shared-memory exchange on one host stays MPI-free here
        from mpi4py import MPI
    requests, keep = [], []
    sent = zbytes = 0
    for r, parts in sends.items():
        buf = np.empty(sum(p.pixels for p in parts) * per_px, dtype=np.uint8)
        _pack(buf, parts, rects[me], rendered, with_depth)
        keep.append(buf)
        requests.append(comm.Isend([buf, MPI.BYTE], dest=r, tag=TAG))
        sent += buf.nbytes
        zbytes += 4 * sum(p.pixels for p in parts) if with_depth else 0
    inbox = {}
    for s, parts in recvs.items():
        buf = np.empty(sum(p.pixels for p in parts) * per_px, dtype=np.uint8)
        inbox[s] = buf
        requests.append(comm.Irecv([buf, MPI.BYTE], source=s, tag=TAG))
    return Posted(me, rects, rendered, incoming, requests, keep, inbox, sent, zbytes, with_depth, near)


def _merge(color, depth, tile, views) -> None:
    for p, rgb, z in views:  # parts, not pixels
        merge_part(color, depth, tile[:2], p.rect, rgb, z, p.ties)


class Messages:
    """The exchange backend of direct sends: nothing to publish before the barrier; after it,
    one message per (sender, receiver) pair (``composite``)."""

    name = "messages"

    def __init__(self, comm, timeout: float):
        self.comm, self.timeout = comm, timeout

    def publish(self, frame: int, me: int, rects, rendered: list, plan: list[Piece]) -> None:
        """Messages leave in ``compose``."""

    def compose(self, frame: int, me: int, rects, rendered: list, plan: list[Piece], tile, color: np.ndarray,
                depth: np.ndarray | None = None) -> tuple[int, int]:
        return composite(self.comm, me, rects, rendered, plan, tile, self.timeout, color, depth)

    def start(self, frame: int, me: int, rects, rendered: list, plan: list[Piece], with_depth: bool) -> Posted:
        """Frames in flight: the frame's messages leave as soon as its pixels are read."""
        return post(self.comm, me, rects, rendered, plan, with_depth)

    def wait(self, started: Posted) -> None:
        """Frames in flight: nothing to wait for before ``finish`` (the messages are)."""

    def finish(self, started: Posted, tile, color: np.ndarray, depth: np.ndarray | None = None) -> tuple[int, int]:
        """Frames in flight: wait for the frame's messages and compose its tile."""
        return started.complete(tile, self.timeout, color, depth)

    def close(self, collective: bool = True) -> None:
        """Nothing held."""


def _local(p: Piece, my_rects, rendered):
    rgb, z = rendered[p.index]
    origin = my_rects[p.index][:2]
    return _part(rgb, origin, p.rect), (None if z is None else _part(z, origin, p.rect))


def _pack(buf: np.ndarray, parts: list[Piece], my_rects, rendered, with_depth: bool) -> None:
    at = 0
    for p in parts:
        rgb, z = _local(p, my_rects, rendered)
        n = p.pixels
        buf[at:at + 3 * n] = rgb.reshape(-1)
        at += 3 * n
        if with_depth:
            buf[at:at + 4 * n] = np.ascontiguousarray(z, dtype=np.float32).view(np.uint8).reshape(-1)
            at += 4 * n


def _unpack(buf: np.ndarray, parts: list[Piece], with_depth: bool):
    at, out = 0, []
    for p in parts:
        x0, y0, x1, y1 = p.rect
        h, w = y1 - y0, x1 - x0
        n = h * w
        rgb = buf[at:at + 3 * n].reshape(h, w, 3)
        at += 3 * n
        z = None
        if with_depth:
            z = buf[at:at + 4 * n].view(np.float32).reshape(h, w)
            at += 4 * n
        out.append((p, rgb, z))
    return out
