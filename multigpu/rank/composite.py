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

A message to a rank on another PC travels compressed where the link's codec says so
(``core/wire.py``): packed for the codec (every part's colour, then its depth as byte planes),
framed, and checked where it lands. Composing never sees a compressed buffer; a message that does
not decode ends the job (``CorruptPiece``: the rank, the frame and the sender, exit 2).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from multigpu.core import wire
from multigpu.core.merge import merge_part
from multigpu.core.work import Piece
from multigpu.rank.exchange import wait_all
from multigpu.rank.fault import FAULT_SPEC, corrupt

TAG = 8


class CorruptPiece(RuntimeError):
    """A compressed piece that does not decode: the job ends with this line, exit 2."""


class Sent(NamedTuple):
    """What a frame's exchange cost this rank: the bytes others get from it (colour and depth,
    of which depth: raw, as composed), the bytes its messages took on the wire (framed and
    compressed), the CPU ms it spent compressing and decompressing, and the colour bits a lossy
    frame dropped."""

    bytes: int
    depth: int
    wire: int = 0
    compress_ms: float = 0.0
    decompress_ms: float = 0.0
    bits: int = 0


def _part(piece_px: np.ndarray, origin, rect) -> np.ndarray:
    """The ``rect`` part of a rendered piece whose lower-left pixel is ``origin``."""
    x0, y0, x1, y1 = rect
    ox, oy = origin
    return piece_px[y0 - oy:y1 - oy, x0 - ox:x1 - ox]


class Posted:
    """A frame's messages on their way: the sends and receives ``post`` started; ``complete``
    waits for them and composes the tile."""

    def __init__(self, me, rects, rendered, incoming, requests, keep, inbox, sent: Sent, with_depth, near,
                 frame: int = 0, links: dict | None = None, recv_order: tuple = ()):
        self.me, self.rects, self.rendered, self.incoming = me, rects, rendered, incoming
        self.requests, self.keep, self.inbox = requests, keep, inbox
        self.sent, self.with_depth, self.near = sent, with_depth, near
        self.frame, self.links = frame, links or {}
        # where each framed message's receive sits in ``requests`` (its byte count is checked)
        self.recv_at = {s: i for i, s in enumerate(recv_order, len(requests) - len(recv_order)) if s in self.links}
        self.received: dict[int, int] = {}

    def complete(self, tile, timeout: float, color: np.ndarray, depth: np.ndarray | None = None,
                 read=None) -> Sent:
        """Compose rank ``me``'s tile into ``color`` (th, tw, 3) [and ``depth`` (th, tw), which
        must hold the background at depth 1.0 on entry]: its own parts, the messages once they
        are in, and the parts of ``near`` ranks as ``read(sender, parts)`` gives their views
        (``shared.py``: its own host's ranks). Returns what the messages cost (``Sent``)."""
        me, rects, rendered, incoming = self.me, self.rects, self.rendered, self.incoming
        # colour parts tile the display, so their order is free: this rank's own go in while the
        # messages travel (fewer polls of the wait); depth parts merge in ascending sender order
        early = me in incoming and not self.with_depth
        if early:
            _merge(color, depth, tile, [(p, *_local(p, rects[me], rendered)) for p in incoming[me]])
        statuses = [] if self.recv_at else None  # what each framed message's receive got
        wait_all(self.requests, timeout, "frame exchange", statuses=statuses)
        if statuses:
            self.received = {s: statuses[i].Get_count() for s, i in self.recv_at.items()}
        self.keep = None
        spent = 0.0
        for s in sorted(incoming):  # ascending sender: the depth tie rule
            if s == me and early:
                continue
            parts = incoming[s]
            if s == me:
                views = [(p, *_local(p, rects[me], rendered)) for p in parts]
            elif s in self.near:
                views = read(s, parts)
            elif s in self.links:
                views, took = self._decoded(s, parts)
                spent += took
            else:
                views = _unpack(self.inbox[s], parts, self.with_depth)
            _merge(color, depth, tile, views)
        return self.sent._replace(decompress_ms=spent * 1e3) if spent else self.sent

    def _decoded(self, s: int, parts: list[Piece]) -> tuple[list, float]:
        """Views of the parts in rank ``s``'s compressed message, and the CPU seconds decoding it
        took; CorruptPiece where it does not decode."""
        raw = sum(p.pixels for p in parts) * (7 if self.with_depth else 3)
        what = f"rank {self.me}: frame {self.frame}: the pieces from rank {s}"
        packed, bits, took = decoded(self.inbox[s], raw, what, self.received.get(s))
        return _unpack_planar(packed, parts, self.with_depth, bits), took


def decoded(message: np.ndarray, raw: int, what: str, received: int | None = None) -> tuple[np.ndarray, int, float]:
    """``wire.decode`` of a message that must hold ``raw`` bytes (``received`` of them arrived),
    with the CPU seconds it took; CorruptPiece beginning with ``what`` (the rank, the frame, the
    sender) where it does not decode."""
    t0 = time.thread_time()
    try:
        packed, bits = wire.decode(message, raw, received)
    except wire.WireError as exc:
        raise CorruptPiece(f"{what}: {exc}") from None
    return packed, bits, time.thread_time() - t0


def post(comm, me: int, rects, rendered: list, plan: list[Piece], with_depth: bool,
         near: frozenset = frozenset(), frame: int = 0, links: dict | None = None, bits: int = 0) -> Posted:
    """Start a frame's exchange: this rank's parts for other ranks' tiles packed and sent, its
    receives posted (nothing for ``near`` ranks, read from shared memory). ``rects`` are every
    rank's pieces (``Work.rects``), ``rendered[j]`` rank ``me``'s piece j as ``(rgb, z)`` (z
    None without depth), ``plan`` the frame's ``transfers``. ``links``: the codec of each peer
    whose messages travel framed and compressed (``core/wire.py``; the others raw); ``bits``: the
    colour bits a lossy frame drops on those links."""
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
    links = links or {}
    requests, keep = [], []
    sent = zbytes = onwire = 0
    spent = 0.0
    for r, parts in sends.items():
        px = sum(p.pixels for p in parts)
        buf = np.empty(px * per_px, dtype=np.uint8)
        if r in links:
            _pack_planar(buf, parts, rects[me], rendered, with_depth)
            t0 = time.thread_time()
            msg = wire.encode(buf, links[r], 3 * px, bits)
            spent += time.thread_time() - t0
            if FAULT_SPEC:
                msg = corrupt(me, frame, msg)
        else:
            _pack(buf, parts, rects[me], rendered, with_depth)
            msg = buf
        keep.append(msg)
        requests.append(comm.Isend(msg, dest=r, tag=TAG))
        sent += buf.nbytes
        onwire += msg.nbytes
        zbytes += 4 * px if with_depth else 0
    inbox = {}
    for s, parts in recvs.items():
        raw = sum(p.pixels for p in parts) * per_px
        buf = np.empty(wire.bound(raw) if s in links else raw, dtype=np.uint8)
        inbox[s] = buf
        requests.append(comm.Irecv(buf, source=s, tag=TAG))
    cost = Sent(sent, zbytes, onwire, spent * 1e3, 0.0, bits if any(r in links for r in sends) else 0)
    return Posted(me, rects, rendered, incoming, requests, keep, inbox, cost, with_depth, near, frame, links,
                  tuple(inbox))  # the receives come last in ``requests``, in the inbox's order


def _merge(color, depth, tile, views) -> None:
    for p, rgb, z in views:  # parts, not pixels
        merge_part(color, depth, tile[:2], p.rect, rgb, z, p.ties)


class Messages:
    """The exchange backend of direct sends: one message per (sender, receiver) pair, sent as
    soon as the frame's pixels are read (``start``), composed once in (``finish``). ``sync``:
    ``wait`` is a barrier every rank reaches once its frame is read (the paper's GPU-GPU
    synchronization, ``--latency 0``); with frames in flight the messages alone pace the ranks."""

    name = "messages"

    def __init__(self, comm, timeout: float, sync: bool = True, links: dict | None = None):
        self.comm, self.timeout, self.sync, self.links = comm, timeout, sync, links or {}
        self.bits = 0  # colour bits the next frames drop on compressed links (a lossy frame)

    def start(self, frame: int, me: int, rects, rendered: list, plan: list[Piece], with_depth: bool):
        """The frame's messages on their way (and the barrier posted, where there is one)."""
        return (post(self.comm, me, rects, rendered, plan, with_depth, frame=frame, links=self.links, bits=self.bits),
                self.comm.Ibarrier() if self.sync else None)

    def wait(self, started) -> None:
        """Until every rank has read its frame (``sync``; else at once: the messages are the wait)."""
        if started[1] is not None:
            wait_all([started[1]], self.timeout, "synchronization")

    def finish(self, started, tile, color: np.ndarray, depth: np.ndarray | None = None) -> Sent:
        """Wait for the frame's messages and compose its tile (``Posted.complete``)."""
        return started[0].complete(tile, self.timeout, color, depth)

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


def _pack_planar(buf: np.ndarray, parts: list[Piece], my_rects, rendered, with_depth: bool) -> None:
    """``_pack`` laid out for a codec: every part's colour, then every part's depth as four byte
    planes (byte 0 of every pixel's float, then byte 1, ...)."""
    total = sum(p.pixels for p in parts)
    planes = buf[3 * total:].reshape(4, total) if with_depth else None
    at = 0
    for p in parts:
        rgb, z = _local(p, my_rects, rendered)
        n = p.pixels
        buf[3 * at:3 * (at + n)] = rgb.reshape(-1)
        if with_depth:
            planes[:, at:at + n] = np.ascontiguousarray(z, dtype=np.float32).view(np.uint8).reshape(n, 4).T
        at += n


def _unpack_planar(buf: np.ndarray, parts: list[Piece], with_depth: bool, bits: int = 0):
    """The parts ``_pack_planar`` packed, as ``(part, rgb, z)``; ``bits``: the colour bits the
    sender dropped, given back as the middle of the range they span."""
    total = sum(p.pixels for p in parts)
    planes = buf[3 * total:].reshape(4, total) if with_depth else None
    at, out = 0, []
    for p in parts:
        x0, y0, x1, y1 = p.rect
        h, w = y1 - y0, x1 - x0
        n = h * w
        rgb = buf[3 * at:3 * (at + n)].reshape(h, w, 3)
        if bits:
            rgb = rgb | np.uint8(1 << (bits - 1))
        z = None
        if with_depth:  # plane by plane: 4x numpy's transposing copy (bench network, the pixel path)
            back = np.empty((n, 4), np.uint8)
            for b in range(4):
                back[:, b] = planes[b, at:at + n]
            z = back.view(np.float32).reshape(h, w)
        at += n
        out.append((p, rgb, z))
    return out
