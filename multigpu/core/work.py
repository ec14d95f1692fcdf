"""One frame's work, whatever the decomposition: who renders which pixels with which objects,
and where the pixels go. Pure numpy (the transfers compiled where numba is installed).

A rank renders one or more pixel rects ("pieces"), each with its own object mask: one rect per
rank for the paper's screen partition, a rank's bins for static bin patterns, a rect per
display segment it helps for cross-segment balancing, and for sort-last (database)
decomposition the rect where its objects project, rendered with depth. Every piece is cut by
the display tiles it overlaps, and each part travels to the tile's owner (``transfers``).
Colour-only pieces tile the display exactly and are copied; depth pieces overlap and the
owner keeps the nearest fragment. A hybrid's ranks each render a screen region and a depth piece
of the wide objects: the regions (a rank's first ``front`` pieces) win depth ties, the depth
pieces lose them (``core/merge.py``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from multigpu.core import jit
from multigpu.core.balance import Partition
from multigpu.core.work_kernel import _parts


class Work(NamedTuple):
    """rects[k] : (M_k, 4) int64 ``[x0, y0, x1, y1)`` pieces rank k renders.
    masks[k] : (M_k, N) bool  objects each piece draws.
    loads : (K,) int64  triangles each rank processes (an object drawn in two pieces counts twice).
    depth : whether pieces carry depth and are composited by the nearest fragment (sort-last).
    partition : the screen strategy's partition (for its ``observe`` and reports), if any.
    front : (K,) how many of each rank's first pieces are screen regions that win depth ties
        (a hybrid's; None: none do).
    views : (K,) lists, each piece's screen on a wall whose displays lie in several planes (a
        CAVE's: each screen its own frustum); None: one.
    eyes : (K,) the eye (0 left, 1 right) each rank renders on a stereo wall split by eye
        (``core/stereo.doubled``); None: every rank renders both.

    Immutable, and a named tuple rather than a frozen dataclass: one is made every frame, and
    a frozen dataclass sets each field through ``object.__setattr__`` (~8 us of CPU more with
    the caches cold after rendering; ad hoc timing)."""

    rects: tuple
    masks: tuple
    loads: np.ndarray
    depth: bool = False
    partition: Partition | None = None
    front: tuple | None = None
    views: tuple | None = None  # per rank, each piece's screen (a wall of several planes; None: one)
    eyes: tuple | None = None  # per rank, the one eye it renders (stereo split by eye; None: both)

    @property
    def ranks(self) -> int:
        return len(self.rects)

    def bounds(self, k: int) -> np.ndarray:
        """(4,) bounding box of rank k's pieces (zeros when it renders nothing)."""
        r = self.rects[k]
        if len(r) == 0:
            return np.zeros(4, dtype=np.int64)
        return np.array([r[:, 0].min(), r[:, 1].min(), r[:, 2].max(), r[:, 3].max()], dtype=np.int64)

    def objects(self, k: int) -> int:
        """Distinct objects rank k draws."""
        m = self.masks[k]
        return int(m.any(axis=0).sum()) if len(m) else 0

    @property
    def load_cv(self) -> float:
        """Coefficient of variation of the per-rank loads, std/mean (Kerbl et al.'s c_v)."""
        mean = float(np.mean(self.loads))
        return float(np.std(self.loads)) / mean if mean > 0 else 0.0


def from_partition(part: Partition, tris: np.ndarray) -> Work:
    """A screen partition as work: one piece per rank, or the partition's own pieces."""
    if part.pieces is not None:  # the partition's loads already count an object once per piece
        return Work(tuple(part.pieces), tuple(part.piece_visible), np.asarray(part.loads), False, part)
    # rank k's (1, 4) rect and (1, N) mask: views, split off by one C-level iteration each
    return Work(tuple(part.regions[:, None]), tuple(part.visible[:, None]), np.asarray(part.loads), False, part)


class Piece(NamedTuple):
    """Part ``rect`` of sender's piece ``index`` that lands on receiver's tile (a named tuple:
    a frame makes a few, built at C speed); ``ties``: it wins depth ties (a hybrid's region)."""

    sender: int
    receiver: int
    index: int
    rect: tuple[int, int, int, int]
    ties: bool = False

    @property
    def pixels(self) -> int:
        x0, y0, x1, y1 = self.rect
        return (x1 - x0) * (y1 - y0)


#: up to this many (piece, tile) pairs a frame's transfers are found by a plain loop, cheaper
#: than any array call with the caches cold (every screen strategy on walls of up to 16 tiles);
#: bins and bigger walls take the compiled pass
SMALL = 64


def transfers(work: Work, tiles: np.ndarray, compiled: bool | None = None) -> list[Piece]:
    """Every non-empty (piece, tile) intersection, sorted by (sender, receiver, piece index):
    the order both ends pack and unpack one pair's message in. Past ``SMALL`` pairs the
    compiled pass (``work_kernel.py``, the same parts) where numba is installed
    (``compiled`` None) or asked for; ``compiled=False`` always loops."""
    pieces = [np.asarray(r, dtype=np.int64).reshape(-1, 4).tolist() for r in work.rects]  # ranks, not objects
    T = np.asarray(tiles, dtype=np.int64).tolist()
    counts = [len(p) for p in pieces]
    if sum(counts) * len(T) > SMALL and jit.use(compiled):
        R = np.array([rect for mine in pieces for rect in mine], dtype=np.int64).reshape(-1, 4)
        rows = _parts(R, np.array(counts, dtype=np.int64), np.array(T, dtype=np.int64).reshape(-1, 4))
        out = [Piece(s, r, i, (x0, y0, x1, y1)) for s, r, i, x0, y0, x1, y1 in rows.tolist()]
        return out if work.front is None else _fronted(out, work.front)
    out = []
    for s, mine in enumerate(pieces):  # senders, tiles, the sender's pieces: the sorted order
        for r, (a0, b0, a1, b1) in enumerate(T):
            for i, (x0, y0, x1, y1) in enumerate(mine):
                lx, hx = (x0 if x0 > a0 else a0), (x1 if x1 < a1 else a1)  # no builtin calls: ~4x fewer C calls
                if hx > lx:
                    ly, hy = (y0 if y0 > b0 else b0), (y1 if y1 < b1 else b1)
                    if hy > ly:
                        out.append(Piece(s, r, i, (lx, ly, hx, hy)))
    return out if work.front is None else _fronted(out, work.front)


def _fronted(parts: list[Piece], front) -> list[Piece]:
    """``parts`` with ``ties`` set on those of a rank's first ``front[sender]`` pieces."""
    return [p._replace(ties=True) if p.index < front[p.sender] else p for p in parts]  # parts, not objects


def pieces_tile_display(work: Work, size) -> bool:
    """Whether colour pieces cover the display exactly once (the screen/bins invariant)."""
    W, H = size
    cover = np.zeros((H, W), dtype=np.int32)
    for rects in work.rects:
        for x0, y0, x1, y1 in np.asarray(rects, dtype=np.int64).reshape(-1, 4):
            cover[y0:y1, x0:x1] += 1
    return bool((cover == 1).all())
