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


def hybrid_plan(balance="strips", seed=2, n=3000):
    from multigpu.core.drawlist import draw_order, wide_objects
    from multigpu.decompositions.hybrid import Hybrid
    from multigpu.strategies import make_strategy

    rects, tris = workload(n, seed)
    rng = np.random.default_rng(seed)
    centers = rng.random((n, 3))
    lo = centers - rng.exponential(0.02, (n, 1))
    hi = centers + rng.exponential(0.02, (n, 1))
    wide = wide_objects(tris, lo, hi)
    order = draw_order(centers, wide)
    size = (256, 128)
    h = Hybrid(make_strategy(balance, (2, 2), size, 16), (2, 2), size, order, wide)
    return h, h.plan(0, rects, tris), rects, tris, wide, order


@pytest.mark.parametrize("balance", ["strips", "cross"])
def test_hybrid_draws_every_visible_object_once_where_wide(balance):
    from multigpu.core.regions import pixel_spans

    h, work, rects, tris, wide, order = hybrid_plan(balance)
    on = pixel_spans(rects, (256, 128))[1]
    assert work.depth and work.front is not None and wide.any() and (on & wide).any()
    depth_owner = np.full(tris.size, -1)
    for k in range(4):
        front = work.front[k]
        regions = np.asarray(work.rects[k]).reshape(-1, 4)
        assert not np.asarray(work.masks[k])[:front][:, wide].any()  # no region draws a wide object
        assert len(regions) - front <= 1  # one depth piece at most
        for m in np.asarray(work.masks[k])[front:]:
            assert (depth_owner[m] == -1).all()
            depth_owner[m] = k
    assert ((depth_owner >= 0) == (on & wide)).all()  # every visible wide object, by one rank
    along = depth_owner[order][depth_owner[order] >= 0]
    assert (np.diff(along) >= 0).all()  # contiguous ascending ranges of the draw order: the tie rule
    screen = h.strategy.plan(np.where(wide[:, None], np.nan, rects), tris, None).loads
    assert work.loads.sum() == screen.sum() + tris[on & wide].sum()


def test_hybrid_regions_tile_the_display_and_win_ties():
    from multigpu.core.work import Work

    _, work, _, _, _, _ = hybrid_plan()
    regions = Work(tuple(np.asarray(r).reshape(-1, 4)[:f] for r, f in zip(work.rects, work.front)),
                   tuple(np.asarray(m)[:f] for m, f in zip(work.masks, work.front)), work.loads)
    assert pieces_tile_display(regions, (256, 128))
    for p in transfers(work, tile_regions(2, 2, 128, 64)):
        assert p.ties == (p.index < work.front[p.sender])


def test_fill_ranges_fill_the_light_ranks_first():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from multigpu.decompositions.hybrid import fill_ranges

    @settings(max_examples=200, deadline=None)
    @given(st.lists(st.integers(1, 500), min_size=0, max_size=300),
           st.lists(st.integers(0, 5000), min_size=1, max_size=16))
    def check(weight, loads):
        owner = fill_ranges(np.array(weight), np.array(loads))
        assert owner.size == len(weight) and (np.diff(owner) >= 0).all()
        assert owner.size == 0 or (0 <= owner.min() and owner.max() < len(loads))
        if len(weight) and sum(weight) >= 10 * max(weight) and len(loads) > 1:
            total = np.array(loads, float) + np.bincount(owner, weights=weight, minlength=len(loads))
            room_mean = (sum(loads) + sum(weight)) / len(loads)
            assert total.max() <= max(max(loads), room_mean) + max(weight)  # no rank past the mean by an item more

    check()


def test_merge_ties_go_to_the_region():
    from multigpu.core.merge import merge_part

    for first_region in (True, False):  # whatever the arrival order
        color = np.zeros((1, 2, 3), np.uint8)
        depth = np.ones((1, 2), np.float32)
        region = (np.full((1, 2, 3), 1, np.uint8), np.array([[0.5, 0.5]], np.float32), True)
        wide = (np.full((1, 2, 3), 2, np.uint8), np.array([[0.5, 0.25]], np.float32), False)
        for rgb, z, ties in (region, wide) if first_region else (wide, region):
            merge_part(color, depth, (0, 0), (0, 0, 2, 1), rgb, z, ties)
        assert color[0, :, 0].tolist() == [1, 2] and depth[0].tolist() == [0.5, 0.25]
