"""Stereo walls: the two eyes' canvases, where their pixels travel, and how a display shows them.

Three pixel spaces (origin bottom-left, rects half-open ``[x0, y0, x1, y1)``):

* each **eye's canvas**: the whole wall as one eye sees it, at the eye's resolution (half the
  tile's width side by side, half its height top and bottom, the whole tile for anaglyph), with
  the wall's bezels; every plan is made here and both eyes render the same plan;
* the **composed** space: every tile's two eye tiles side by side (left eye first), one rect per
  rank, so each rank composes exactly its own tile of both eyes in one exchange;
* the **display**: what a monitor shows, a tile packed from its composed tile (``pack``); a
  passive wall's tile has two outputs (two projectors, polarized or spectrally filtered), each
  showing one eye's whole tile: the composed tile itself, the left eye's output then the right's.

``compose`` cuts a frame's work (planned on the eye canvas) at the eye tiles' borders and moves
each part into the composed space once per eye, so the exchange, its backends and the merge of
depth are those of a mono wall. Pure numpy, no MPI, no GL.

How the ranks share the eyes (``--eyes``, ``EYE_PLANS``): ``joint``, every rank renders its region
for both eyes (one plan of K regions); ``split``, eye decomposition as Equalizer's eye compounds
do: the first half of the ranks (labels below K/2) renders the left eye, the second half the
right, each half the same K/2 regions of one plan (``halved``, ``doubled``), so a rank draws one
pass a frame over twice the pixels. ``auto`` (the default) splits where a wall can
(``splits``): measured faster in per-rank CPU time (docs/BENCHMARKS.md, "bench stereo"). ``own``, a
passive wall's Equalizer way: 2K ranks for K tiles, a rank for each eye of each tile (ranks 0..K-1
the left eyes', K..2K-1 the right eyes'), each eye's K ranks sharing one plan of K regions; the
composed space is then the left eyes' wall beside the right eyes' (``composed``), so each rank
composes and shows exactly its own eye's tile (its projector), about a mono frame's work.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from multigpu.core.canvas import Canvas
from multigpu.core.work import Work

#: the stereo modes a wall shows, packed per display (``--stereo``); ``mono`` is one eye; ``passive``:
#: two outputs a tile, one an eye
MODES = ("mono", "side-by-side", "top-bottom", "anaglyph", "passive")
#: modes that need what no presenter here has (a GL stereo visual), refused with this reason
UNSHOWN = {"quad": "frame-sequential stereo needs a quad-buffered GL visual, which neither EGL nor this X "
                   "server offers (use side-by-side, top-bottom or anaglyph)"}
EYES = ("left", "right")
#: how a stereo wall's ranks share the eyes (``--eyes``; see the module)
EYE_PLANS = ("auto", "joint", "split", "own")


def halved(grid: tuple[int, int]) -> tuple[int, int] | None:
    """The GPU tree of half a wall's ranks, as the tree's own first split makes it: half the
    columns where there are several, else half the rows (None: an odd count has no halves)."""
    rows, cols = grid
    if cols > 1:
        return (rows, cols // 2) if cols % 2 == 0 else None
    return (rows // 2, 1) if rows % 2 == 0 else None


def splits(stereo: str, grid: tuple[int, int], decomposition: str, partition: str,
           own: bool = False) -> str | None:
    """Why a wall cannot split its ranks by eye (None: it can): it needs stereo, the screen
    decomposition (each eye's half of the ranks splits the screen), an even count of columns (or,
    in one column, of rows), and a partition every rank plans itself. ``own`` (a rank for each eye
    of each tile): passive stereo, its ranks already two walls."""
    if own and stereo != "passive":
        return (f"own (a rank for each eye of each tile) drives a passive wall's projectors: --stereo passive, "
                f"not {stereo}")
    name = "own" if own else "split"
    if stereo == "mono":
        return f"{name} needs a stereo wall (--stereo), got --stereo mono"
    if decomposition != "screen":
        return f"{name} works with --decomposition screen, got --decomposition {decomposition}"
    if partition == "broadcast":
        return f"{name} plans every rank's partition itself: use --partition redundant (got --partition broadcast)"
    if not own and halved(grid) is None:
        return (f"split needs an even number of columns (or, in one column, of rows) to halve the ranks, got "
                f"--grid {grid[0]}x{grid[1]}")
    return None


def doubled(work: Work) -> Work:
    """A plan of K/2 ranks as K ranks' work for eye decomposition: ranks 0..K/2-1 the left eye,
    K/2..K-1 the right, rank ``k + K/2`` the same pieces as rank ``k`` (``Work.eyes`` says whose
    eye is whose; the partition stays the plan's, for its strategy to learn from)."""
    n = work.ranks
    twice = lambda t: None if t is None else tuple(t) + tuple(t)  # noqa: E731
    return Work(twice(work.rects), twice(work.masks), np.concatenate([work.loads, work.loads]), work.depth,
                work.partition, twice(work.front), twice(work.views), (0,) * n + (1,) * n)


@dataclass(frozen=True)
class Stereo:
    """A ``mode`` (not mono) on ``canvas`` (the displays' wall); ``own``: a rank for each eye of
    each tile (``--eyes own``: 2K ranks)."""

    mode: str
    canvas: Canvas
    own: bool = False

    @cached_property
    def eye_tile(self) -> tuple[int, int]:
        """(w, h) of one eye's picture of a tile (anaglyph and passive: the whole tile)."""
        tw, th = self.canvas.tile
        if self.mode == "side-by-side":
            return tw // 2, th
        return (tw, th // 2) if self.mode == "top-bottom" else (tw, th)

    @property
    def outputs(self) -> int:
        """Outputs a tile's display has: two on a passive wall (an eye each), else one."""
        return 2 if self.mode == "passive" else 1

    @cached_property
    def eye(self) -> Canvas:
        """One eye's canvas: the wall's grid of eye tiles, its bezels at the eye's pixel pitch."""
        (tw, th), (ew, eh), (mx, my) = self.canvas.tile, self.eye_tile, self.canvas.mullion
        return Canvas(self.canvas.grid, (ew, eh), (round(mx * ew / tw), round(my * eh / th)), self.canvas.dark)

    @cached_property
    def composed(self) -> Canvas:
        """The composed space: every tile's eye tiles side by side (``own``: the left eyes' wall
        beside the right eyes', a rank's tile one eye's)."""
        ew, eh = self.eye_tile
        if self.own:
            rows, cols = self.canvas.grid
            return Canvas((rows, 2 * cols), (ew, eh), (0, 0), self.canvas.dark)
        return Canvas(self.canvas.grid, (2 * ew, eh), (0, 0), self.canvas.dark)

    @cached_property
    def _shifts(self) -> np.ndarray:
        """(2, K, 2) offset from each eye tile on the eye canvas to its place in the composed space."""
        eye, comp = self.eye.tiles()[:, :2], self.composed.tiles()[:, :2]
        if self.own:  # tile t's left eye is composed tile t, its right eye tile K + t
            return np.stack([comp[:len(eye)] - eye, comp[len(eye):] - eye])
        return np.stack([comp - eye, comp - eye + np.array([self.eye_tile[0], 0])])

    def compose(self, work: Work) -> tuple[Work, list]:
        """``work`` on the eye canvas, as both eyes' parts in the composed space (each piece cut at
        the eye tiles it meets, its parts in piece order, each eye in turn: a hybrid's front
        pieces stay first), and each rank's ``picks``: for every composed rect, (eye, piece,
        x, y) of its lower-left pixel inside the eye piece it is cut from. Only the rects and the
        front of the composed work are used (the exchange's)."""
        tiles, K = self.eye.tiles(), work.ranks
        pieces = [np.asarray(r, dtype=np.int64).reshape(-1, 4) for r in work.rects]
        counts = np.array([len(r) for r in pieces], dtype=np.int64)
        R = np.concatenate(pieces)  # every rank's, rank by rank
        owner = np.repeat(np.arange(K), counts)
        local = np.arange(len(R)) - np.repeat(np.cumsum(counts) - counts, counts)  # a piece's index in its rank
        lo = np.maximum(R[:, None, :2], tiles[None, :, :2])
        hi = np.minimum(R[:, None, 2:], tiles[None, :, 2:])
        p, t = np.nonzero((hi > lo).all(axis=-1))  # (piece, tile) pairs, by piece (so by rank)
        cut = np.concatenate([lo[p, t], hi[p, t]], axis=1)
        inside = cut[:, :2] - R[p, :2]
        n = len(p)
        if work.eyes is None:  # every rank both eyes
            both, eyes = np.tile(np.arange(n), 2), np.repeat([0, 1], n)
        else:  # eye decomposition: each rank's own eye
            both = np.arange(n)
            eyes = np.asarray(work.eyes, dtype=np.int64)[owner[p]]
        order = np.lexsort((both, eyes, p[both]))  # by rank and piece, then eye, then cut
        eye, src = eyes[order], both[order]
        rank, piece = owner[p[src]], local[p[src]]
        cuts = np.cumsum(np.bincount(rank, minlength=K))[:-1]
        rects = tuple(np.split(cut[src] + np.tile(self._shifts[eye, t[src]], 2), cuts))
        picks = [part.tolist() for part in np.split(np.column_stack([eye, piece, inside[src]]), cuts)]
        front = None
        if work.front is not None:  # a hybrid's front pieces stay first
            ahead = piece < np.asarray(work.front, dtype=np.int64)[rank]
            front = tuple(int(c) for c in np.bincount(rank[ahead], minlength=K))
        return Work(rects, tuple(() for _ in rects), work.loads, work.depth, work.partition, front, None,
                    work.eyes), picks

    @staticmethod
    def parts(picks: list, rects: np.ndarray, rendered: list) -> list:
        """This rank's composed parts as ``(rgb, depth or None)`` views of its eyes' rendered pieces
        (``rendered[eye][piece]``; None for an eye it does not render), in the order of its
        composed ``rects``."""
        out = []
        for (eye, piece, x, y), (x0, y0, x1, y1) in zip(picks, rects.tolist()):  # parts, a few per rank
            rgb, z = rendered[eye][piece]
            rows, cols = slice(y, y + y1 - y0), slice(x, x + x1 - x0)
            out.append((rgb[rows, cols], None if z is None else z[rows, cols]))
        return out

    def eyes(self, tile: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A composed tile (bottom row first) as the (left, right) eye tiles (views)."""
        ew = self.eye_tile[0]
        return tile[:, :ew], tile[:, ew:]

    def pack(self, tile: np.ndarray) -> np.ndarray:
        """What the display shows of a composed tile: side by side as it is, the left eye above
        the right, or red from the left eye with green and blue from the right; passive: the
        left eye's output beside the right's, as it is (``outputs``)."""
        left, right = self.eyes(tile)
        if self.mode in ("side-by-side", "passive"):
            return tile
        if self.mode == "top-bottom":  # bottom row first: the right eye's rows, then the left's
            return np.concatenate([right, left], axis=0)
        out = right.copy()
        out[..., 0] = left[..., 0]
        return out


def right_eye_place(canvas: Canvas, place: tuple[int, int]) -> tuple[int, int]:
    """Where a passive tile's right-eye output sits by default, from its left one's ``place``
    (top-left, on a screen holding the canvas): as far right as the wall is wide, so the right
    eyes' outputs form a second wall beside the first (the wall file may place it:
    ``right_eye_position``)."""
    return place[0] + canvas.size[0], place[1]


def make_stereo(mode: str, canvas: Canvas, own: bool = False) -> Stereo | None:
    """The stereo of ``--stereo`` on ``canvas`` (None: mono); ``own``: ``--eyes own``. The door
    has checked the mode."""
    return None if mode == "mono" else Stereo(mode, canvas, own)


def eye_canvas(mode: str, canvas: Canvas) -> Canvas:
    """Where a wall's ranks render: one eye's canvas in stereo, else the wall's own."""
    return canvas if mode == "mono" else Stereo(mode, canvas).eye
