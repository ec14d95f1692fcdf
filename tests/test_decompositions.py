"""Decompositions in one process: what every rank draws, exact loads, the static patterns."""

import numpy as np
import pytest

from multigpu.core.bins import PATTERNS, bin_rects, owner
from multigpu.core.regions import tile_regions
from multigpu.core.work import pieces_tile_display, transfers
from multigpu.decompositions.bins import Bins
from multigpu.decompositions.db import ranges_by_weight


def workload(n=3000, seed=1):
    rng = np.random.default_rng(seed)
    lo = rng.random((n, 2)) * 1.1 - 0.05
    rects = np.c_[lo, lo + rng.exponential(0.05, (n, 2))]
    rects[::7] = np.nan
    return rects, rng.integers(1, 300, n)


@pytest.mark.parametrize("pattern", PATTERNS)
@pytest.mark.parametrize("bin_size,size", [(16, (512, 512)), (5, (21, 9)), (64, (300, 200))])
def test_bin_loads_and_masks(pattern, bin_size, size):
    """Loads from the 2-D difference array equal counting every (bin, object) pair; a rank's
    own-only plan has its masks and everyone's loads; the bins tile the display."""
    rects, tris = workload()
    full = Bins((2, 2), size, bin_size, pattern).plan(0, rects, tris)
    brute = np.array([int((m.astype(np.int64) @ tris).sum()) for m in full.masks])
    np.testing.assert_array_equal(full.loads, brute)
    assert pieces_tile_display(full, size)
    for k in range(4):
        own = Bins((2, 2), size, bin_size, pattern, rank=k).plan(0, rects, tris)
        np.testing.assert_array_equal(own.loads, full.loads)
        np.testing.assert_array_equal(own.masks[k], full.masks[k])
        assert all(len(m) == 0 for j, m in enumerate(own.masks) if j != k)


def test_patterns_use_every_rank_evenly():
    rects, bx, by = bin_rects((1024, 1024), 16)
    for pattern in PATTERNS:
        for k in (2, 3, 4, 8):
            counts = np.bincount(owner(pattern, bx, by, k), minlength=k)
            assert counts.min() > 0 and counts.max() / counts.min() <= 1.2, (pattern, k, counts)
    # Kerbl et al.: diagonal shifts each row by one; Van der Corput rows use each rank once per row
    assert owner("diagonal", np.arange(4), np.ones(4, int), 4).tolist() == [1, 2, 3, 0]
    row = owner("vandercorput", np.arange(8), np.full(8, 3), 8)
    assert sorted(row.tolist()) == list(range(8))


def test_db_ranges_are_contiguous_and_balanced():
    rng = np.random.default_rng(3)
    order = rng.permutation(1000)
    weight = rng.integers(1, 100, 1000)
    rank = ranges_by_weight(order, weight, 4)
    along = rank[order]
    assert (np.diff(along) >= 0).all()  # contiguous ascending ranges in draw order
    loads = np.bincount(rank, weights=weight, minlength=4)
    assert loads.max() / loads.mean() < 1.05


def test_transfers_deliver_every_tile_pixel_once():
    rects, tris = workload()
    size = (256, 128)
    work = Bins((2, 2), size, 16, "zcurve").plan(0, rects, tris)
    tiles = tile_regions(2, 2, 128, 64)
    got = np.zeros((4, 128, 256), dtype=np.int32)
    for p in transfers(work, tiles):
        x0, y0, x1, y1 = p.rect
        got[p.receiver, y0:y1, x0:x1] += 1
    for k, (x0, y0, x1, y1) in enumerate(tiles):
        assert (got[k, y0:y1, x0:x1] == 1).all() and got[k].sum() == (x1 - x0) * (y1 - y0)
