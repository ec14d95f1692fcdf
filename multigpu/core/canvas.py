"""The wall as people see it: display tiles separated by mullions (pixels hidden behind bezels).

Two pixel spaces, both origin bottom-left, rects half-open ``[x0, y0, x1, y1)``:

* the **canvas**, ``cols*tw + (cols-1)*MX`` by ``rows*th + (rows-1)*MY``: one camera frustum
  spans it, so a straight line stays straight across a bezel; tile (row, col) starts at
  ``x = col*(tw+MX)`` and, counted from the top, ``y = row*(th+MY)``;
* the **visible** space, ``cols*tw`` by ``rows*th``: the canvas with the mullions cut out.
  Balancers and decompositions plan here, so they split visible pixels only and a region may
  span a bezel without paying for it.

``to_visible`` maps projected object rects from the canvas into the visible space
(conservatively: an object keeps every visible pixel it may cover; one wholly behind a bezel
becomes invisible). ``to_canvas`` cuts a frame's work at the tile borders and moves each part
onto the canvas, so hidden pixels are never rendered. With zero mullions both are identities
and are skipped.

**Overlapping tiles** (a projector wall's, ``warp/layout.py``): a negative mullion is the
pixels neighbours share (the blend zone). The canvas is then the visible space itself (every pixel
is shown, some by two projectors): plans are made on it whole, each pixel rendered once, and the
exchange delivers a piece's part to every tile it meets.

**Dark tiles** (``dark``: the labels of tiles whose PC is gone, ``records/recovery.py``) hide
like mullions: an object that reaches no live tile is invisible, the parts of a plan on dark
tiles are cut away, and the mosaic shows them black; the balancers, planning loads of visible
objects, share the live tiles among all the ranks. Pure numpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from multigpu.core.regions import overlaps, pixel_spans, tile_regions
from multigpu.core.work import Work

#: the most tiles a wall may have (a rank each; its arrays are made per tile): more than any wall here
MOST_TILES = 4096

#: widening of mapped rects (normalized units) that absorbs the rounding of the
#: canvas -> visible -> pixel round trip; it can only add a pixel, never drop one
PAD = 1e-9


@dataclass(frozen=True)
class Canvas:
    """A ``grid`` = (rows, cols) wall of ``tile`` = (tw, th) pixels with ``mullion`` = (MX, MY)."""

    grid: tuple[int, int]
    tile: tuple[int, int]
    mullion: tuple[int, int] = (0, 0)
    dark: tuple[int, ...] = ()  # tile labels shown black, drawn by nobody

    def __post_init__(self):
        if min(self.mullion) < 0 and max(self.mullion) > 0:
            raise ValueError(f"a wall's tiles overlap or stand apart, not both (mullion {self.mullion})")
        if self.tile[0] + self.mullion[0] <= 0 or self.tile[1] + self.mullion[1] <= 0:
            raise ValueError(f"tiles of {self.tile} cannot overlap by {self.mullion}: each must start past the last")

    @property
    def overlapping(self) -> bool:
        """Whether neighbouring tiles share pixels (a projector wall's blend zones)."""
        return min(self.mullion) < 0

    @property
    def visible(self) -> tuple[int, int]:
        """(W, H) of the visible pixels: where every plan is made (overlapping tiles: the canvas)."""
        if self.overlapping:
            return self.size
        return self.grid[1] * self.tile[0], self.grid[0] * self.tile[1]

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) of the canvas: the camera's frustum, the renderers' framebuffer, the mosaic."""
        (rows, cols), (tw, th), (mx, my) = self.grid, self.tile, self.mullion
        return cols * tw + (cols - 1) * mx, rows * th + (rows - 1) * my

    @cached_property
    def bezels(self) -> bool:
        """Whether any pixels hide behind bezels (asked every frame: computed once)."""
        return max(self.mullion) > 0

    @cached_property
    def cuts(self) -> bool:
        """Whether plans need ``to_visible`` and ``to_canvas``: bezels or dark tiles."""
        return self.bezels or bool(self.dark)

    def tiles(self) -> np.ndarray:
        """(K, 4) canvas rect of every rank label's tile (column-major labels, row 0 on top)."""
        rows, cols = self.grid
        t = tile_regions(rows, cols, *self.tile)
        return t + np.tile(self._shift(), 2)  # both corners move by the tile's shift

    def _shift(self) -> np.ndarray:
        """(K, 2) canvas offset of each label's tile from its place in the visible space."""
        rows, cols = self.grid
        labels = np.arange(rows * cols)
        row, col = labels % rows, labels // rows
        return np.stack([col * self.mullion[0], (rows - 1 - row) * self.mullion[1]], axis=1).astype(np.int64)

    def hidden(self) -> np.ndarray:
        """(H, W) bool of the canvas, top row first (as a PNG): the pixels behind bezels and on
        dark tiles."""
        W, H = self.size
        mask = np.ones((H, W), dtype=bool)
        for k, (x0, y0, x1, y1) in enumerate(self.tiles()):  # K tiles
            if k not in self.dark:  # a pixel a live tile shows is shown, though a dark one shares it
                mask[H - y1:H - y0, x0:x1] = False
        return mask

    def _live_visible(self) -> np.ndarray:
        """(L, 4) normalized visible rects of the live tiles."""
        (VW, VH), live = self.visible, [k for k in range(self.grid[0] * self.grid[1]) if k not in self.dark]
        return self._visible_tiles()[live] / np.array([VW, VH, VW, VH], dtype=float)

    def _visible_tiles(self) -> np.ndarray:
        """(K, 4) every tile's rect in the visible space (overlapping: the canvas's)."""
        return self.tiles() if self.overlapping else tile_regions(self.grid[0], self.grid[1], *self.tile)

    def to_visible(self, rects: np.ndarray) -> np.ndarray:
        """(N, 4) normalized canvas rects -> normalized visible rects (NaN: no visible pixel)."""
        if self.dark:
            return self._on_live(self._squeezed(rects) if self.bezels else np.asarray(rects, dtype=np.float64))
        return self._squeezed(rects) if self.bezels else rects

    def _on_live(self, v: np.ndarray) -> np.ndarray:
        """Visible rects ``v`` with NaN for those that meet no live tile."""
        live = self._live_visible()
        with np.errstate(invalid="ignore"):
            meet = ((np.minimum(v[:, None, 2:], live[None, :, 2:]) > np.maximum(v[:, None, :2], live[None, :, :2]))
                    .all(axis=-1).any(axis=1))
        out = v.copy()
        out[~meet] = np.nan
        return out

    def _squeezed(self, rects: np.ndarray) -> np.ndarray:
        """The mullions closed up: canvas rects -> visible rects."""
        r = np.asarray(rects, dtype=np.float64)
        (W, H), (VW, VH) = self.size, self.visible
        (rows, cols), (tw, th), (mx, my) = self.grid, self.tile, self.mullion
        out = np.empty_like(r)
        gone = np.zeros(len(r), dtype=bool)
        for axis, (n, t, m, full, vis) in enumerate(((cols, tw, mx, W, VW), (rows, th, my, H, VH))):
            lo, lo_gap, lo_tile = _squeeze(r[:, axis] * full, n, t, m, low=True)
            hi, hi_gap, hi_tile = _squeeze(r[:, axis + 2] * full, n, t, m, low=False)
            gone |= lo_gap & hi_gap & (lo_tile == hi_tile)  # both ends behind the same bezel
            with np.errstate(invalid="ignore"):
                hi = np.maximum(hi, lo)  # a low end in a tile's last pixel, a high end in the gap after it
            out[:, axis] = lo / vis - PAD
            out[:, axis + 2] = hi / vis + PAD
        out[gone] = np.nan
        return out

    def to_canvas(self, work: Work, vrects: np.ndarray, tris: np.ndarray) -> Work:
        """``work`` planned in the visible space, cut at the tile borders and moved onto the
        canvas. A cut part draws only the objects whose visible span touches it, and the loads
        count what is drawn (a rank whose masks the plan left out keeps its planned load).
        ``vrects`` are this frame's normalized visible object rects. Parts on dark tiles go."""
        if not self.cuts:
            return work
        vtiles = self._visible_tiles()
        shift = np.zeros_like(self._shift()) if self.overlapping else self._shift()
        spans = None
        rects, masks, loads = [], [], np.zeros(work.ranks, dtype=np.int64)
        front = None if work.front is None else [0] * work.ranks
        for k in range(work.ranks):  # ranks, not objects
            R = np.asarray(work.rects[k], dtype=np.int64).reshape(-1, 4)
            lo = np.maximum(R[:, None, :2], vtiles[None, :, :2])
            hi = np.minimum(R[:, None, 2:], vtiles[None, :, 2:])
            meet = (hi > lo).all(axis=-1)
            if self.dark:
                meet[:, list(self.dark)] = False
            p, t = np.nonzero(meet)  # (piece, tile) that meet, by piece
            cut = np.concatenate([lo[p, t], hi[p, t]], axis=1)
            rects.append(cut + np.tile(shift[t], 2))
            if front is not None:  # the cuts of the front pieces come first
                front[k] = int(np.count_nonzero(p < work.front[k]))
            if len(work.masks[k]) != len(R):  # masks of this rank not computed here (bins: own rank only)
                masks.append(work.masks[k])
                loads[k] = work.loads[k]
                continue
            m = work.masks[k][p]
            split = np.bincount(p, minlength=len(R))[p] > 1
            if split.any():
                if spans is None:
                    spans = pixel_spans(vrects, self.visible)[0]
                m = m.copy()
                for i in np.flatnonzero(split):  # cut parts, a few per rank
                    m[i] &= overlaps(spans, cut[i])
            masks.append(m)
            loads[k] = int((m.astype(np.int64) @ np.asarray(tris, dtype=np.int64)).sum()) if len(m) else 0
        return Work(tuple(rects), tuple(masks), loads, work.depth, work.partition,
                    None if front is None else tuple(front))


def _squeeze(x: np.ndarray, n: int, t: int, m: int, low: bool):
    """Canvas pixel coordinates along one axis -> visible ones: the ``n`` tiles of ``t`` pixels
    close up over the ``m``-pixel gaps; a point in a gap goes to the next tile's first pixel
    (``low``) or the previous tile's last pixel. Outside the canvas the first and last tile
    extend. NaN stays NaN. Also returns which points lay in a gap, and their tile index."""
    with np.errstate(invalid="ignore"):
        c = np.clip(np.floor(x / (t + m)), 0, n - 1)
        local = x - c * (t + m)
        gap = (local >= t) & (c < n - 1)
        edge = (c + 1) * t - (0.0 if low else 0.5)
        return np.where(gap, edge, c * t + local), gap, c
