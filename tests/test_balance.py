"""The GPU-tree strip balancer: tiling, loads, balRatio, extremes, bad arguments."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core.balance import partition, partition_tiles
from multigpu.core.regions import overlaps, pixel_spans, tile_regions

GRIDS = [(1, 1), (1, 2), (2, 1), (2, 2), (1, 3), (3, 1), (2, 3), (1, 5), (5, 1), (1, 7), (7, 1), (4, 4), (3, 3)]


def clustered(n, seed=0, spread=0.05, centre=(0.2, 0.3)):
    rng = np.random.default_rng(seed)
    c = rng.normal(centre, spread, (n, 2))
    s = rng.exponential(0.005, (n, 2))
    rects = np.concatenate([c - s, c + s], axis=1)
    tris = (rng.pareto(1.2, n) * 50 + 10).astype(np.int64)
    return rects, tris


def uniform(n, seed=0):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-0.1, 1.1, (n, 2))
    s = rng.exponential(0.02, (n, 2))
    return np.concatenate([c - s, c + s], axis=1), rng.integers(0, 1000, n)


def assert_tiles_exactly(regions, W, H):
    cover = np.zeros((H, W), dtype=np.int32)
    for x0, y0, x1, y1 in regions:
        assert 0 <= x0 < x1 <= W and 0 <= y0 < y1 <= H, regions
        cover[y0:y1, x0:x1] += 1
    assert (cover == 1).all()


def recount(rects, tris, regions, W, H):
    """Independent recount: an object is in a region when its pixel span touches it."""
    spans, on = pixel_spans(rects, (W, H))
    vis = np.array([on & overlaps(spans, r) for r in regions])
    return vis, np.array([int(tris[v].sum()) for v in vis])


@pytest.mark.parametrize("grid", GRIDS)
@pytest.mark.parametrize("workload", [clustered, uniform])
def test_regions_tile_and_loads_recount(grid, workload):
    rects, tris = workload(3000)
    W, H = 96 * grid[1], 64 * grid[0]
    p = partition(rects, tris, grid, (W, H), strips=256)
    assert p.regions.shape == (grid[0] * grid[1], 4)
    assert_tiles_exactly(p.regions, W, H)
    vis, loads = recount(rects, tris, p.regions, W, H)
    assert (p.visible == vis).all()
    assert (p.loads == loads).all()
    assert p.splits.shape == (grid[0] * grid[1] - 1,)
    assert ((p.splits > 0) & (p.splits < 1)).all()


@pytest.mark.parametrize("grid", [g for g in GRIDS if g != (1, 1)])
def test_balanced_beats_tiles_on_clustered(grid):
    rects, tris = clustered(5000, seed=3)
    W, H = 128 * grid[1], 128 * grid[0]
    p = partition(rects, tris, grid, (W, H), strips=4096)
    b = partition_tiles(rects, tris, grid, (W, H))
    assert p.imbalance <= b.imbalance
    vis, loads = recount(rects, tris, b.regions, W, H)
    assert (b.loads == loads).all() and (b.visible == vis).all()


@pytest.mark.parametrize("grid", [(1, 3), (3, 1), (2, 3), (1, 5)])
def test_uneven_splits_honour_balratio(grid):
    # many tiny objects spread uniformly: the balanced loads must be near equal per rank, so
    # the root split must follow balRatio (1:2, 2:3, ...), not 1:1
    rng = np.random.default_rng(1)
    n = 20000
    c = rng.uniform(0, 1, (n, 2))
    rects = np.concatenate([c, c], axis=1)
    tris = np.full(n, 10)
    W, H = 300 * grid[1], 300 * grid[0]
    p = partition(rects, tris, grid, (W, H), strips=W)
    assert p.imbalance < 1.05
    K = grid[0] * grid[1]
    assert np.allclose(p.loads, tris.sum() / K, rtol=0.05)


def test_splits_are_pixel_boundaries_of_strips():
    rects, tris = clustered(2000)
    p = partition(rects, tris, (1, 2), (1000, 10), strips=7)
    cuts = {(i * 1000) // 7 for i in range(1, 7)}
    assert int(p.split_pixels[0]) in cuts


def test_paper_figure4_example():
    # 16 strips, balRatio 1: objects whose weights balance exactly at strip boundary 8
    rects = np.array([[0.0, 0, 0.1, 1], [0.55, 0, 0.6, 1], [0.3, 0, 0.45, 1], [0.9, 0, 1.0, 1]])
    tris = np.array([30, 40, 10, 0])
    p = partition(rects, tris, (1, 2), (16, 4), strips=16)
    assert p.split_pixels[0] == 8 and p.splits[0] == 0.5
    assert list(p.loads) == [40, 40]


def test_empty_scene_falls_back_to_tiles():
    for grid in [(2, 2), (1, 3), (4, 4)]:
        W, H = 30 * grid[1], 20 * grid[0]
        p = partition(np.zeros((0, 4)), np.zeros(0, np.int64), grid, (W, H))
        assert (p.regions == tile_regions(*grid, 30, 20)).all()
        assert p.loads.sum() == 0 and p.imbalance == 1.0


def test_all_invisible_nan_and_offscreen():
    rects = np.array([[np.nan] * 4, [-2, -2, -1, -1], [1.5, 0, 2, 1], [0, 1.01, 1, 2]])
    p = partition(rects, np.array([5, 6, 7, 8]), (2, 2), (64, 64))
    assert not p.visible.any()
    assert (p.regions == tile_regions(2, 2, 32, 32)).all()


def test_everything_in_one_strip():
    rects = np.tile([0.5, 0.5, 0.5, 0.5], (100, 1))
    p = partition(rects, np.full(100, 3), (2, 2), (64, 64), strips=8)
    assert_tiles_exactly(p.regions, 64, 64)
    assert p.visible.sum(axis=0).min() >= 1  # every object still rendered by someone


def test_one_object_dominates():
    rects, tris = uniform(1000)
    tris = tris.astype(np.int64)
    tris[0] = int(tris[1:].sum() * 999)
    rects[0] = [0.4, 0.4, 0.42, 0.42]
    p = partition(rects, tris, (2, 2), (128, 128), strips=128)
    assert_tiles_exactly(p.regions, 128, 128)
    assert p.visible[:, 0].sum() >= 1
    assert (p.loads == recount(rects, tris, p.regions, 128, 128)[1]).all()


def test_zero_triangle_objects_and_boundary_rects():
    # rects exactly on strip boundaries (multiples of 1/8 on a 64-pixel axis with 8 strips)
    xs = np.arange(9) / 8
    rects = np.stack([xs, np.zeros(9), xs, np.ones(9)], axis=1)
    tris = np.array([0, 10, 0, 10, 10, 0, 10, 0, 10])
    p = partition(rects, tris, (1, 2), (64, 8), strips=8)
    vis, loads = recount(rects, tris, p.regions, 64, 8)
    assert (p.loads == loads).all() and (p.visible == vis).all()
    assert (p.visible.sum(axis=0) >= 1).all()  # the rect at x=1.0 lands in the last column


@pytest.mark.parametrize("strips", [2, 3, 64, 100_000])
def test_strip_counts_from_two_beyond_pixels(strips):
    rects, tris = clustered(2000)
    p = partition(rects, tris, (2, 2), (64, 48), strips=strips)
    assert_tiles_exactly(p.regions, 64, 48)
    if strips == 2:
        assert p.split_pixels[0] == 32


def test_totals_near_2_pow_40_and_beyond_2_pow_53():
    rects, _ = uniform(500)
    for big in (2**40 // 500, 2**54 // 500):
        tris = np.full(500, big, dtype=np.int64)
        tris[::7] += 1  # odd low bits that float64 sums would lose above 2**53
        p = partition(rects, tris, (2, 2), (64, 64), strips=64)
        _, loads = recount(rects, tris, p.regions, 64, 64)
        assert p.loads.dtype == np.int64 and (p.loads == loads).all()


def test_tiny_walls_one_pixel_per_rank():
    rects, tris = clustered(500)
    for grid in [(1, 16), (16, 1), (4, 4)]:
        W, H = grid[1], grid[0]
        p = partition(rects, tris, grid, (W, H), strips=2048)
        assert_tiles_exactly(p.regions, W, H)


@pytest.mark.parametrize("bad", [
    dict(grid=(0, 2)), dict(grid=(2, -1)), dict(strips=1), dict(strips=0),
    dict(rects=np.zeros((5, 3))), dict(tris=np.ones(4, np.int64)), dict(tris=-np.ones(5, np.int64)),
    dict(size=(1, 64)), dict(tris=np.array(["a"] * 5)), dict(size=(2**31, 64)),
])
def test_bad_arguments_raise_value_error(bad):
    args = dict(rects=np.zeros((5, 4)), tris=np.ones(5, np.int64), grid=(2, 2), size=(64, 64), strips=16)
    args.update(bad)
    with pytest.raises(ValueError):
        partition(**args)


def test_deterministic_bit_for_bit():
    rects, tris = clustered(20000, seed=9)
    a = partition(rects, tris, (2, 3), (600, 400), strips=600)
    b = partition(rects.copy(), tris.copy(), (2, 3), (600, 400), strips=600)
    assert (a.regions == b.regions).all() and (a.visible == b.visible).all()
    assert a.splits.tobytes() == b.splits.tobytes()


rect_st = st.tuples(st.floats(-0.5, 1.5), st.floats(-0.5, 1.5), st.floats(0, 0.6), st.floats(0, 0.6))


@settings(max_examples=60, deadline=None)
@given(
    objs=st.lists(st.tuples(rect_st, st.integers(0, 10**6)), max_size=60),
    grid=st.sampled_from(GRIDS),
    strips=st.integers(2, 300),
    tile=st.tuples(st.integers(1, 40), st.integers(1, 40)),
)
def test_property_tiling_and_recount(objs, grid, strips, tile):
    rects = np.array([[x, y, x + w, y + h] for (x, y, w, h), _ in objs]).reshape(-1, 4)
    tris = np.array([t for _, t in objs], dtype=np.int64)
    W, H = tile[0] * grid[1], tile[1] * grid[0]
    p = partition(rects, tris, grid, (W, H), strips=strips)
    assert_tiles_exactly(p.regions, W, H)
    vis, loads = recount(rects, tris, p.regions, W, H)
    assert (p.visible == vis).all() and (p.loads == loads).all()
    # every object that is on screen is rendered by at least one rank
    _, on = pixel_spans(rects, (W, H))
    assert (p.visible.any(axis=0) == on).all()


def test_huge_wall_balances_within_int32_spans():
    """A 2**30-pixel-wide wall (the limit) still tiles exactly and recounts."""
    rects, tris = clustered(2000)
    W, H = 2**30, 4096
    p = partition(rects, tris, (1, 4), (W, H), strips=4096)
    r = p.regions
    assert ((r[:, 0] < r[:, 2]) & (r[:, 1] < r[:, 3])).all()
    assert ((r[:, 0] >= 0) & (r[:, 1] >= 0) & (r[:, 2] <= W) & (r[:, 3] <= H)).all()
    areas = (r[:, 2] - r[:, 0]) * (r[:, 3] - r[:, 1])
    assert int(areas.sum()) == W * H  # inside the display and summing to it: with disjointness, a tiling
    for i in range(4):
        for j in range(i + 1, 4):
            assert max(r[i, 0], r[j, 0]) >= min(r[i, 2], r[j, 2]) or max(r[i, 1], r[j, 1]) >= min(r[i, 3], r[j, 3])
    _, loads = recount(rects, tris, p.regions, W, H)
    assert (p.loads == loads).all()


def _balancer(tiles: bool, compiled: bool):
    """The tree walk, or the ``none`` baseline's tiles (the same walk with fixed cuts)."""
    if tiles:
        return lambda r, t: partition_tiles(r, t, (2, 2), (64, 64), compiled=compiled)
    return lambda r, t: partition(r, t, (2, 2), (64, 64), 16, compiled=compiled)


@pytest.mark.parametrize("tiles", [False, True])
@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("bad", [[0.5, 0.1, 0.4, 0.2], [0.1, 0.6, 0.2, 0.5]])
def test_an_inverted_rect_is_refused_by_either_path(compiled, bad, tiles):
    """The compiled walk checks inverted rows in its own pass over the rects, the numpy
    reference before it starts: the same refusal, wherever the row is, NaN rows allowed
    (the balancer and the tiles of ``none`` alike)."""

    run = _balancer(tiles, compiled)
    rects = np.array([[0.1, 0.1, 0.3, 0.3], [np.nan] * 4, [0.2, 0.2, 0.9, 0.8]] * 50)
    tris = np.arange(1, len(rects) + 1)
    run(rects, tris)  # NaN rows are unseen, not inverted
    rects[77] = bad
    with pytest.raises(ValueError, match="inverted rows"):
        run(rects, tris)


@pytest.mark.parametrize("tiles", [False, True])
@pytest.mark.parametrize("compiled", [False, True])
def test_bad_weights_are_refused_by_either_path_in_the_same_order(compiled, tiles):
    """The compiled walk checks the weights in its pass over the objects, the numpy reference
    before it starts: the same refusal for a weight that is negative or not finite, for a
    total past 2**62, and the weights' refusal before an inverted row's."""

    rects = np.array([[0.1, 0.1, 0.3, 0.3], [np.nan] * 4, [0.2, 0.2, 0.9, 0.8]] * 20)
    n = len(rects)
    run = _balancer(tiles, compiled)
    run(rects, np.arange(n))
    cases = [(np.r_[np.ones(n - 1), np.nan], "must be finite"), (np.r_[np.ones(n - 1), -np.inf], "must be finite"),
             (np.r_[np.arange(n - 1), -1], "non-negative"), (np.r_[np.ones(n - 1), -0.5], "non-negative"),
             (np.r_[np.zeros(n - 2, dtype=np.int64), 2**61, 2**61], "exceeds 2\\*\\*62"),
             (np.r_[np.inf, np.ones(n - 1)], "must be finite")]
    for tris, message in cases:
        with pytest.raises(ValueError, match=message):
            run(rects, tris)
        bad = rects.copy()
        bad[5] = [0.5, 0.1, 0.4, 0.2]
        with pytest.raises(ValueError, match=message):  # the weights first, as the reference
            run(bad, tris)
    run(rects, np.r_[np.zeros(n - 2, dtype=np.int64), 2**61, 2**61 - 1])  # just below: accepted


def test_shares_set_each_split_s_balratio():
    """Per-rank shares (a faster GPU a larger one): equal shares are the paper's nl / nr, the
    compiled walk equals the reference, and a rank of share 2 gets about twice the triangles."""
    from multigpu.core.balance import node_ratios, partition
    from multigpu.core.tree import gpu_tree

    rng = np.random.default_rng(11)
    n = 4000
    lo = rng.random((n, 2))
    rects = np.c_[lo, lo + rng.exponential(0.004, (n, 2))]
    tris = rng.integers(1, 50, n)
    for grid in ((1, 2), (2, 2), (3, 4)):
        k = grid[0] * grid[1]
        plain = partition(rects, tris, grid, (640, 480), 256)
        same = partition(rects, tris, grid, (640, 480), 256, shares=np.full(k, 3.0))
        assert (plain.regions == same.regions).all()
        shares = rng.uniform(0.5, 2.0, k)
        ref = partition(rects, tris, grid, (640, 480), 256, compiled=False, shares=shares)
        fast = partition(rects, tris, grid, (640, 480), 256, compiled=True, shares=shares)
        assert (ref.regions == fast.regions).all() and (ref.loads == fast.loads).all()
        tree = gpu_tree(*grid)
        assert np.allclose(node_ratios(tree, np.ones(k)), [nd.low.count / nd.high.count for nd in tree.internal])
    two = partition(rects, tris, (1, 2), (640, 480), 256, shares=[2.0, 1.0])
    assert abs(two.loads[0] / two.loads[1] - 2.0) < 0.1
    with pytest.raises(ValueError, match="shares must be 2 positive"):
        partition(rects, tris, (1, 2), (640, 480), 256, shares=[1.0, 0.0])
