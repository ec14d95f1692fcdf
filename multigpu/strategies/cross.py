"""``cross``: cross-segment load balancing (Erol, Eilemann, Pajarola 2011; Equalizer's view
equalizer over per-segment load equalizers).

Each display tile is a segment. From the last frame's measured times and a per-pixel time model,
every segment's load is known: a pixel weighs ``pixel_weight`` times the mean triangles per
pixel on screen, plus every object over it: its triangles and ``object_weight`` times the mean
triangles per object on screen (its draw, its vertices set up whole), spread evenly over its
rect, and ``cover_weight`` times the triangles per pixel of all the objects' rects (the
fragments tested and shaded where objects overlap; ``multigpu bench imbalance`` found a rank's
objects and their rects' pixels behind much of the imbalance its triangles left). A rank's
measured time over its pieces' weight in the frame it rendered is its time per unit of weight;
this frame's weight along a segment's axis, at the rate of the last frame's pieces there, is
the segment's time profile. Where the camera moved, the weight moves with the objects before
any time is measured for it (Equalizer spreads a rank's time evenly over its pixels, one frame
late). Past ``SAMPLE`` objects on screen every k-th stands for
k in the profiles: they place a few cuts. The view equalizer gives segment t a share
``r_t = K * L_t / sum(L)`` of the K ranks (damped, and never zero), and lays the shares out
along one resource axis, the tiles in a serpentine order (along the first row,
back along the next, ...): the rank owning the p-th tile of that order is the unit ``[p, p+1)``
of the axis, so it helps the segments its unit overlaps, usually its own and a neighbour, by at
least ``min_help`` of its unit. Each segment is then split among its helpers by its own load
equalizer: cuts across the segment's longer axis where the measured time profile reaches each
helper's share, a helper from a neighbour along that axis taking the strip on its own side.

Beyond Equalizer's layout (tiles in label order, helpers from the low end), which gives a
rank helping a neighbour a second, separate piece: here the help along a row is the strip
beside the helper's own tile, and a rank's pieces that share a whole edge join into one rect,
one render pass. A pass draws every object its rect touches, whole, so a second one costs far
more than its pixels (a 3-pixel piece beside a city tile: ~1 ms of CPU against ~4 ms for the
tile, nothing when joined: ``multigpu bench passes``). ``min_help`` keeps slivers of help
away where they would not join. The pieces tile the display and travel to their tiles' owners.
Follows measured times, so not bit-reproducible between runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multigpu.core import jit
from multigpu.core.balance import Partition, partition
from multigpu.core.regions import pixel_spans, tile_regions
from multigpu.strategies import cross_kernel as kernel
from multigpu.strategies.base import Configured
from multigpu.strategies.cross_kernel import SAMPLE


def _seqsum(x: np.ndarray) -> float:
    """Sum in index order (numpy's ``sum`` pairs terms; the compiled kernel adds in order)."""
    return float(np.cumsum(x)[-1])


def _density(spans: np.ndarray, on: np.ndarray, tris: np.ndarray, size: tuple[int, int], pixel_weight: float,
             object_weight: float, cover_weight: float, uniform: bool):
    """The time model's weights from the frame's pixel spans and on-screen mask (``pixel_spans``):
    on-screen objects' inclusive spans (M, 4) int64, their weights per pixel of span (M,), and
    a pixel's own weight (``pixel_weight`` times the triangles on screen per display pixel).
    An object weighs its triangles plus ``object_weight`` times the mean triangles per on-screen
    object, spread over its span, plus ``cover_weight`` times the triangles per pixel of all the
    on-screen spans on every pixel of its own. ``uniform``: every pixel weighs 1, objects nothing."""
    s = spans[on].astype(np.int64)
    if uniform:
        return s, np.zeros(len(s)), 1.0
    t = np.asarray(tris, dtype=np.int64)[on]
    total = float(t.sum())
    beta = pixel_weight * total / (size[0] * size[1])
    if len(t) == 0:
        return s, np.zeros(0), beta
    area = (s[:, 2] - s[:, 0] + 1) * (s[:, 3] - s[:, 1] + 1)
    per_object = object_weight * total / len(t)
    per_pixel = cover_weight * total / float(area.sum())
    return s, (t + per_object) / area + per_pixel, beta


def _overlap(s: np.ndarray, lo: int, hi: int, c: int) -> np.ndarray:
    """Pixels of every inclusive span ``s[:, c]..s[:, c + 2]`` within ``[lo, hi)``."""
    return np.clip(np.minimum(s[:, c + 2] + 1, hi) - np.maximum(s[:, c], lo), 0, None)


def _mass(model, rect) -> float:
    """The weight of ``rect`` ``[x0, y0, x1, y1)`` under ``model`` (``_density``'s triple)."""
    s, d, beta = model
    x0, y0, x1, y1 = (int(v) for v in rect)
    acc = float(np.cumsum(d * _overlap(s, x0, x1, 0) * _overlap(s, y0, y1, 1))[-1]) if len(d) else 0.0
    return beta * ((x1 - x0) * (y1 - y0)) + acc


#: how segments are laid out on the resource axis and cut (``CrossSegment.layout``)
LAYOUTS = ("joined", "equalizer")
#: where a rank's time lies within its pieces (``CrossSegment.model``)
MODELS = ("weighted", "uniform")


def serpentine(rows: int, cols: int) -> np.ndarray:
    """Segments (tile labels, column-major, row 0 at the top) along the resource axis: along
    the first row, back along the next, and so on, so consecutive segments always share an
    edge, and mostly a vertical one: square or wide tiles are cut across x, and a rank helping
    its neighbour in a row takes the strip beside its own tile."""
    return np.array([c * rows + r for r in range(rows) for c in (range(cols) if r % 2 == 0 else range(cols)[::-1])],
                    dtype=np.int64)


def _join(rects: list) -> list[np.ndarray]:
    """A rank's pieces with any two that share a whole edge joined (the first such pair first,
    until none is left): one render pass draws an object both touch once, not twice, and a pass
    costs more than its pixels (a 3-pixel piece of a city tile: ~1 ms of CPU, ``bench passes``)."""
    rects = [list(r) for r in rects]
    i = 0
    while i < len(rects):  # pieces, not objects (at most a few)
        for j in range(i + 1, len(rects)):
            a, b = rects[i], rects[j]
            if a[1] == b[1] and a[3] == b[3] and (a[2] == b[0] or b[2] == a[0]):
                rects[i] = [min(a[0], b[0]), a[1], max(a[2], b[2]), a[3]]
            elif a[0] == b[0] and a[2] == b[2] and (a[3] == b[1] or b[3] == a[1]):
                rects[i] = [a[0], min(a[1], b[1]), a[2], max(a[3], b[3])]
            else:
                continue
            del rects[j]
            i = -1  # start again from the first piece
            break
        i += 1
    return [np.array(r, dtype=np.int64) for r in rects]


@dataclass
class CrossSegment(Configured):
    """Resources move between display segments by load, then each segment is split by time."""

    damping: float = 0.5
    min_share: float = 0.02  # a segment keeps at least this share of a rank
    # a rank helps a segment with at least this much of its unit, else the segment's other
    # helpers take that sliver: a piece that does not join the rank's others costs a render
    # pass of every object it touches, more than a sliver of share moves (0: every overlap helps)
    min_help: float = 0.1
    # "joined": the serpentine order, helpers cut from their own side, a rank's pieces that
    # share an edge joined; "equalizer": Equalizer's layout (tiles in label order, helpers from
    # a segment's low end, every piece its own pass), kept to measure the difference against
    layout: str = "joined"
    # a pixel's weight in the time model, as a multiple of the triangles on screen per display
    # pixel (its fill, clear and read-back beside its share of the geometry)
    pixel_weight: float = 0.5
    # an object's own weight, as a multiple of the mean triangles per object on screen (its
    # draw, and its vertices set up whole wherever it is drawn)
    object_weight: float = 1.0
    # a pixel of an object's rect weighs this times the triangles per pixel of all the on-screen
    # objects' rects (the fragments it tests and shades where objects overlap)
    cover_weight: float = 1.0
    # "weighted": the model above; "uniform": Equalizer's, a rank's time spread evenly over the
    # pixels it rendered (kept to measure the difference against)
    model: str = "weighted"

    name = "cross"
    summary = 'resources move between display segments by load, then each segment is split by time'
    reproducible = False  # it follows measured times

    def __post_init__(self):
        if not 0.0 <= self.min_help <= 1.0:
            raise ValueError(f"cross: min_help must lie in [0, 1], got {self.min_help}")
        for weight in ("pixel_weight", "object_weight", "cover_weight"):
            if not 0.0 <= getattr(self, weight) < float("inf"):
                raise ValueError(f"cross: {weight} must be a finite number >= 0, got {getattr(self, weight)}")
        if self.model not in MODELS:
            raise ValueError(f"cross: unknown model '{self.model}' (known: {', '.join(MODELS)})")
        if self.layout not in LAYOUTS:
            raise ValueError(f"cross: unknown layout '{self.layout}' (known: {', '.join(LAYOUTS)})")
        rows, cols = self.grid
        W, H = self.size
        self.tiles = tile_regions(rows, cols, W // cols, H // rows)
        # position on the resource axis -> segment (and its own rank)
        self.order = serpentine(rows, cols) if self.layout == "joined" else np.arange(rows * cols, dtype=np.int64)
        self._joined = self.layout == "joined"
        self._pieces: tuple | None = None
        self._flat: dict | None = None  # the same pieces flat, where the kernel planned them
        self._times: np.ndarray | None = None
        self._mass: np.ndarray | None = None
        self.shares = np.ones(len(self.tiles))
        self._spare = np.empty(len(self.tiles))  # the compiled kernel's new shares go here (no array to box)
        self._compiled = jit.use(self.compiled)  # once, not per frame
        self._integer = None  # the integer weights array last seen (checked once, not per frame)
        self._bound: dict = {}  # the kernel's entry point for this strategy's own argument types
        self._arrays: tuple | None = None  # the compiled time model's per-object scratch (``_scratch``)
        self.size = (int(W), int(H))  # the kernel's argument types, fixed here once
        self.damping, self.min_share, self.min_help = float(self.damping), float(self.min_share), float(self.min_help)
        self.pixel_weight, self.object_weight = float(self.pixel_weight), float(self.object_weight)
        self.cover_weight = float(self.cover_weight)
        self._uniform = self.model == "uniform"

    def plan(self, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Partition:
        if self._pieces is None:
            return partition(rects, tris, self.grid, self.size, self.strips, compiled=self.compiled)
        if self._compiled and (tris is self._integer or self._integers(tris)):
            old = self.shares  # the new shares go into the spare array; the old one is the next spare
            self.shares, part = kernel.cross_partition(self._flat or self._pieces, self._mass, self._times,
                                                       self.tiles, self.order, old, self.damping, self.min_share,
                                                       self.min_help, self._joined, self.pixel_weight,
                                                       self.object_weight, self.cover_weight, self._uniform,
                                                       rects, tris,
                                                       self.size, self._spare, self._bound, self._scratch(len(tris)))
            self._spare = old
            return Partition(*part)
        tris = np.asarray(tris)
        k = len(self.tiles)
        spans, onscreen = pixel_spans(rects, self.size)  # once: the model and the masks read them
        model = _density(spans, onscreen, tris, self.size, self.pixel_weight, self.object_weight, self.cover_weight,
                         self._uniform)
        profiles, loads = self._profiles(model)
        total = _seqsum(loads)
        new = k * loads / total if total > 0 else np.ones(k)
        shares = (1 - self.damping) * new + self.damping * self.shares
        shares = np.maximum(shares, self.min_share)
        self.shares = shares * (k / _seqsum(shares))
        pieces = self._split(profiles)
        return self._partition(pieces, spans, onscreen, tris, model)

    def _profiles(self, model):
        """Per segment: the time profile along its longer axis (the last frame's pieces at their
        rank's time per unit of weight, weighed with ``model``, this frame's), and its total."""
        allp = [np.asarray(p, np.int64).reshape(-1, 4) for p in self._pieces]
        mass = self._mass  # the pieces' weights in the frame they were rendered, else this frame's
        mass = [_mass(model, p) for ps in allp for p in ps] if mass is None else list(mass)
        rate, at = [], 0
        for r, ps in enumerate(allp):  # ranks, not objects
            w = sum(mass[at:at + len(ps)], 0.0)
            at += len(ps)
            rate.append(self._times[r] / w if w > 0 else 0.0)
        s, d, beta = model
        loads, profiles = np.zeros(len(self.tiles)), []
        for t, (x0, y0, x1, y1) in enumerate(self.tiles):  # segments, then the pieces: not objects
            ax = 0 if x1 - x0 >= y1 - y0 else 1
            (a0, a1), (c0, c1) = ((x0, x1), (y0, y1)) if ax == 0 else ((y0, y1), (x0, x1))
            rr = np.zeros(a1 - a0 + 1)  # the pieces' rates along the axis, each by its extent across
            for r, ps in enumerate(allp):
                for px0, py0, px1, py1 in ps.tolist():
                    q0, q1, q2, q3 = max(px0, x0), max(py0, y0), min(px1, x1), min(py1, y1)
                    if q2 > q0 and q3 > q1:
                        lo, hi, across = (q0, q2, q3 - q1) if ax == 0 else (q1, q3, q2 - q0)
                        rr[lo - a0] += rate[r] * across
                        rr[hi - a0] -= rate[r] * across
            step = max(len(d) // SAMPLE, 1)  # many objects: every step-th stands for step
            sd = s[::step]
            oc = _overlap(sd, c0, c1, 1 - ax)  # this frame's weight along the axis: each object's
            a = np.minimum(np.maximum(sd[:, ax], a0), a1)  # triangles over its span, by its extent across
            b = np.maximum(np.minimum(sd[:, ax + 2] + 1, a1), a0)
            hit = (oc > 0) & (b > a)
            v = (d[::step] * step * oc)[hit]
            g = np.zeros(a1 - a0 + 1)
            np.add.at(g, np.stack([a[hit] - a0, b[hit] - a0], axis=1).ravel(), np.stack([v, -v], axis=1).ravel())
            prof = np.cumsum(rr)[:-1] / (c1 - c0) * (np.cumsum(g)[:-1] + beta * (c1 - c0))
            loads[t] = _seqsum(prof)
            profiles.append((ax, a0, prof))
        return profiles, loads

    def _reverse(self, p: int, ax: int, helpers: list[int], used: np.ndarray) -> bool:
        """Whether segment ``order[p]``'s helpers run from the high end of its cut axis ``ax``:
        those from a neighbour along that axis (in the resource order; the one helping more
        where both do) get the strip on its side, so such a rank's pieces here and in its own
        segment meet along a whole edge and join."""
        if not self._joined:
            return False
        order, tiles, t = self.order, self.tiles, self.order[p]
        at = np.array(helpers)
        before, after = (float(np.cumsum(np.r_[0.0, used[m]])[-1]) for m in (at < p, at > p))  # added in order
        side = lambda q: 0 if tiles[q][1] == tiles[t][1] and tiles[q][3] == tiles[t][3] else 1  # same row: x
        prev = p > 0 and side(order[p - 1]) == ax
        nxt = p + 1 < len(order) and side(order[p + 1]) == ax
        if prev and (before >= after or not nxt):
            return bool(tiles[order[p - 1]][ax] > tiles[t][ax])
        if nxt:
            return bool(tiles[order[p + 1]][ax] < tiles[t][ax])
        return False

    def _split(self, profiles) -> list[list[np.ndarray]]:
        """The resource axis, unit by unit in the serpentine order, against each segment's share:
        cuts, then each rank's pieces in segment order with those that share an edge joined."""
        k, order = len(self.tiles), self.order
        start = np.zeros(k)
        start[order] = np.concatenate([[0.0], np.cumsum(self.shares[order])[:-1]])
        pieces: list[list] = [[] for _ in range(k)]
        for p, t in enumerate(order):  # segments along the resource axis
            lo_r, hi_r = start[t], start[t] + self.shares[t]
            over = np.array([min(q + 1, hi_r) - max(q, lo_r) for q in range(k)])  # units, not objects
            helpers = [q for q in range(k) if over[q] > 1e-12 and over[q] >= self.min_help]
            helpers = helpers or [int(np.argmax(over))]  # a sliver of one rank: that rank alone
            used = over[helpers]
            ax, a0, prof = profiles[t]
            rev = self._reverse(p, ax, helpers, used)
            prof = prof[::-1] if rev else prof
            n = prof.size
            cum = np.cumsum(prof) if prof.sum() > 0 else np.arange(1, n + 1, dtype=np.float64)
            targets = np.cumsum(used)[:-1] / _seqsum(used) * cum[-1]
            cuts = np.concatenate([[0], np.searchsorted(cum, targets, side="left") + 1, [n]])
            cuts = np.maximum.accumulate(np.minimum(cuts, n))
            x0, y0, x1, y1 = self.tiles[t]
            for q, c0, c1 in zip(helpers, cuts[:-1], cuts[1:]):
                if c1 <= c0:
                    continue
                c0, c1 = (n - c1, n - c0) if rev else (c0, c1)
                rect = [a0 + c0, y0, a0 + c1, y1] if ax == 0 else [x0, a0 + c0, x1, a0 + c1]
                pieces[order[q]].append((t, rect))
        ranked = [[r for _, r in sorted(mine, key=lambda x: x[0])] for mine in pieces]
        return [_join(mine) if self._joined else [np.array(r, dtype=np.int64) for r in mine] for mine in ranked]

    def _partition(self, pieces, spans, onscreen, tris, model) -> Partition:
        on = np.flatnonzero(onscreen)
        sp = spans.T
        lo_x, lo_y, hi_x, hi_y = (sp[i].take(on) for i in range(4))  # on-screen objects only
        tris = np.asarray(tris, dtype=np.int64)
        tris_on = tris.take(on)
        k, n = len(pieces), len(tris)
        prects, pvis, regions = [], [], np.zeros((k, 4), dtype=np.int64)
        loads, visible = np.zeros(k, dtype=np.int64), np.zeros((k, n), dtype=bool)
        for r, plist in enumerate(pieces):  # ranks, not objects
            pr = np.array(plist, dtype=np.int64).reshape(-1, 4)
            hit = (lo_x < pr[:, 2:3]) & (hi_x >= pr[:, 0:1]) & (lo_y < pr[:, 3:4]) & (hi_y >= pr[:, 1:2])
            m = np.zeros((len(pr), n), dtype=bool)
            m[:, on] = hit
            prects.append(pr)
            pvis.append(m)
            if len(pr):
                regions[r] = [pr[:, 0].min(), pr[:, 1].min(), pr[:, 2].max(), pr[:, 3].max()]
                visible[r, on] = hit.any(axis=0)
                loads[r] = int(np.broadcast_to(tris_on, hit.shape).sum(where=hit))
        mass = np.array([_mass(model, p) for pr in prects for p in pr], dtype=np.float64)  # pieces, not objects
        # no spans: only the cost model reads a partition's, from its own strips partitions
        return Partition(regions, loads, visible, np.zeros(max(k - 1, 0)), np.zeros(max(k - 1, 0), dtype=np.int64),
                         None, tuple(prects), tuple(pvis), {"mass": mass})

    def _scratch(self, n: int) -> tuple:
        """The compiled time model's per-object arrays for ``n`` objects, kept between frames."""
        if self._arrays is None or len(self._arrays[1]) != n:
            self._arrays = kernel.scratch_for(n)
        return self._arrays

    def _integers(self, tris) -> bool:
        """Whether ``tris`` holds integers (the compiled plan's weights), kept when it is an
        array: the planner passes the same array every frame, checked once."""
        if tris.__class__ is np.ndarray and tris.dtype.kind in "iu":
            self._integer = tris
            return True
        return np.asarray(tris).dtype.kind in "iu"

    def observe(self, frame: int, partition: Partition, times: np.ndarray) -> None:
        features = partition.features if partition.features is not None else {}
        self._flat = features if "owner" in features else None
        # the pieces' weights in the frame they were planned for (None: planned by another strategy)
        self._mass = features.get("mass")
        pieces = partition.pieces
        self._pieces = pieces if pieces is not None else tuple(partition.regions[:, None])  # one (1, 4) piece per rank
        self._times = np.array(times, dtype=np.float64)  # a copy: the caller's buffer changes

    def report(self) -> dict:
        return {"name": self.name, "segment_shares": [round(float(v), 3) for v in self.shares]}
