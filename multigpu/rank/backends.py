"""The frame loop's two swappable edges, declared (as IceT puts transport behind its
communicator): how pieces travel to their tile owners (``Exchange``: direct messages in
``composite.Messages``, a host-shared segment in ``shared.SharedPieces``) and how a frame's
object bounds become screen rects (``Projection``: every rank all of them in ``projection.EachRank``,
a host's ranks a slice each in ``projection.SharedProjection``). ``Frames`` holds one of each and
knows nothing of which; a new transport or projection is one class that satisfies these."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from multigpu.core.work import Piece


@runtime_checkable
class Exchange(Protocol):
    """Pieces to their tile owners, in three calls a frame: ``start`` as soon as the frame's
    pixels are read (parts out), ``wait`` until every peer's parts are there (the frame's
    ``sync``), ``finish`` to compose the tile (copy or depth-merge into ``color``/``depth``;
    returns what it cost: ``composite.Sent``); ``close`` at the end (``collective``: every rank
    together). Strictly in order (``--latency 0``) the three run back to back; frames in
    flight run them a stage apart."""

    name: str
    links: dict  # the codec (``core.wire.Codec``) of each peer whose messages travel compressed
    bits: int  # colour bits the frames started from now on drop on those links (a lossy frame)

    def start(self, frame: int, me: int, rects, rendered: list, plan: list[Piece], with_depth: bool): ...

    def wait(self, started) -> None: ...

    def finish(self, started, tile, color: np.ndarray, depth: np.ndarray | None = None) -> tuple[int, int]: ...

    def close(self, collective: bool = True) -> None: ...


@runtime_checkable
class Projection(Protocol):
    """A frame's (view, proj, light, rects) for the planner, timed in the ``project`` phase (and
    ``sync`` where ranks wait for each other's slices); ``close`` lets what it holds go
    (``collective``: every rank together)."""

    name: str

    def project(self, frame: int, camera, timer) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...

    def close(self, collective: bool = True) -> None: ...
