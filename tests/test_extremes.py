"""Stability at the extremes: cameras, coordinates, walls and sums (balancer and bounds only)."""

import numpy as np
import pytest

from multigpu.core.balance import partition, partition_tiles
from multigpu.core.bounds import BoxProjector
from multigpu.core.camera import look_at, perspective
from multigpu.core.spheres import SphereProjector
from multigpu.studies.synthetic import synthetic_objects

BMIN, BMAX, CENTERS, RADII, TRIS = synthetic_objects(3000, seed=9)
EYE, TARGET = np.array([-40.0, -60, 40]), np.array([100.0, 60, 0])


def assert_valid_rects(rects):
    vis = ~np.isnan(rects[:, 0])
    assert (np.isnan(rects[~vis]).all())
    r = rects[vis]
    assert np.isfinite(r).all()
    assert (r >= 0).all() and (r <= 1).all()
    assert (r[:, 0] <= r[:, 2]).all() and (r[:, 1] <= r[:, 3]).all()
    return vis


def assert_partition_valid(p, W, H):
    r = p.regions
    assert ((r[:, 0] < r[:, 2]) & (r[:, 1] < r[:, 3])).all()
    assert ((r[:, 2] - r[:, 0]) * (r[:, 3] - r[:, 1])).sum() == W * H
    assert r[:, 0].min() == 0 and r[:, 1].min() == 0 and r[:, 2].max() == W and r[:, 3].max() == H


@pytest.mark.parametrize("near,far", [(1e-6, 1.0), (1e-3, 1e4), (0.1, 1e6), (1.0, 1e7), (1e-6, 1e1)])
@pytest.mark.parametrize("kind", ["box", "sphere"])
def test_near_far_ratios(near, far, kind):
    view = look_at(EYE, TARGET, [0, 0, 1])
    proj = perspective(60, 1.0, near, far)
    proj_fn = BoxProjector(BMIN, BMAX) if kind == "box" else SphereProjector(CENTERS, RADII)
    rects = proj_fn(view, proj)
    vis = assert_valid_rects(rects)
    if far > 300:
        assert vis.sum() > 100  # the scene is in range: many objects seen
    p = partition(rects, TRIS, (2, 2), (512, 512))
    assert_partition_valid(p, 512, 512)


@pytest.mark.parametrize("fov", [1.0, 10.0, 90.0, 150.0, 170.0])
def test_field_of_view_1_to_170(fov):
    view = look_at(EYE, TARGET, [0, 0, 1])
    rects = BoxProjector(BMIN, BMAX)(view, perspective(fov, 16 / 9, 0.1, 1000))
    assert_valid_rects(rects)
    assert_partition_valid(partition(rects, TRIS, (3, 5), (1600, 900)), 1600, 900)


def test_eye_inside_a_box_covers_the_screen():
    bmin, bmax = np.array([[-5.0, -5, -5], [50, 50, 50]]), np.array([[5.0, 5, 5], [51, 51, 51]])
    view = look_at([0, 0, 0], [1, 1, 1], [0, 0, 1])
    for kind, proj_fn in (("box", BoxProjector(bmin, bmax)),
                          ("sphere", SphereProjector((bmin + bmax) / 2, np.linalg.norm(bmax - bmin, axis=1) / 2))):
        rects = proj_fn(view, perspective(60, 1.0, 0.1, 100))
        np.testing.assert_array_equal(rects[0], [0, 0, 1, 1], err_msg=kind)


def test_objects_wholly_behind_the_eye_are_invisible():
    view = look_at([0, 0, 0], [1, 0, 0], [0, 0, 1])
    bmin, bmax = np.array([[-20.0, -1, -1]]), np.array([[-10.0, 1, 1]])
    assert np.isnan(BoxProjector(bmin, bmax)(view, perspective(60, 1, 0.1, 100))).all()
    assert np.isnan(SphereProjector([[-15.0, 0, 0]], [2.0])(view, perspective(60, 1, 0.1, 100))).all()


@pytest.mark.parametrize("offset", [1e6, 1e8])
def test_scene_far_from_origin_partitions_like_at_origin(offset):
    o = np.array([offset, -offset, 0.0])
    proj = perspective(60, 1.0, 0.1, 1000)
    a = BoxProjector(BMIN, BMAX, dtype=np.float64)(look_at(EYE, TARGET, [0, 0, 1]), proj)
    b = BoxProjector(BMIN + o, BMAX + o, dtype=np.float64)(look_at(EYE + o, TARGET + o, [0, 0, 1]), proj)
    vis = assert_valid_rects(b)
    assert (vis == ~np.isnan(a[:, 0])).all()
    # the float64 centre transform keeps rects to well under a pixel of a 16384-pixel wall
    assert np.abs(a[vis] - b[vis]).max() < 1 / 16384 / 4
    pa, pb = partition(a, TRIS, (2, 2), (2048, 2048)), partition(b, TRIS, (2, 2), (2048, 2048))
    assert np.abs(pa.split_pixels - pb.split_pixels).max() <= 1


@pytest.mark.parametrize("grid", [(1, 16), (16, 1), (1, 3), (1, 5), (7, 1), (4, 4)])
@pytest.mark.parametrize("tile", [1, 2, 8])
def test_narrow_tiles_and_long_walls(grid, tile):
    view = look_at(EYE, TARGET, [0, 0, 1])
    rects = BoxProjector(BMIN, BMAX)(view, perspective(60, 1.0, 0.1, 1000))
    W, H = grid[1] * tile, grid[0] * tile
    p = partition(rects, TRIS, grid, (W, H))
    assert_partition_valid(p, W, H)


@pytest.mark.parametrize("W", [16384, 65536, 1 << 20])
def test_walls_of_16384_pixels_and_more_balancer_only(W):
    view = look_at(EYE, TARGET, [0, 0, 1])
    rects = BoxProjector(BMIN, BMAX)(view, perspective(60, W / 1024, 0.1, 1000))
    p = partition(rects, TRIS, (1, 16), (W, 1024), strips=W)
    assert_partition_valid(p, W, 1024)
    assert p.imbalance <= partition_tiles(rects, TRIS, (1, 16), (W, 1024)).imbalance


def test_ranks_agree_bit_for_bit_near_2_pow_53():
    rng = np.random.default_rng(1)
    x, y = np.sort(rng.random((500, 2)), axis=1), np.sort(rng.random((500, 2)), axis=1)
    rects = np.c_[x[:, 0], y[:, 0], x[:, 1], y[:, 1]]
    tris = rng.integers(2**43, 2**44, 500)  # total near 2**53
    assert tris.sum() > 2**52
    runs = [partition(rects.copy(), tris.copy(), (2, 3), (1920, 1080)) for _ in range(3)]
    for p in runs[1:]:
        np.testing.assert_array_equal(p.regions, runs[0].regions)
        np.testing.assert_array_equal(p.loads, runs[0].loads)
    assert runs[0].loads.dtype == np.int64 and runs[0].loads.sum() >= tris.sum()


def test_needle_and_zero_area_rects_land_in_one_pixel_column_or_row():
    rng = np.random.default_rng(4)
    n = 2000
    x = rng.random(n)
    y = rng.random(n)
    needles_v = np.stack([x, np.zeros(n), x, np.ones(n)], axis=1)  # zero width, full height
    needles_h = np.stack([np.zeros(n), y, np.ones(n), y], axis=1)  # full width, zero height
    points = np.stack([x, y, x, y], axis=1)  # zero area
    rects = np.concatenate([needles_v, needles_h, points])
    tris = rng.integers(1, 50, len(rects))
    for grid in [(2, 2), (1, 4), (4, 1), (3, 3)]:
        W, H = 64 * grid[1], 48 * grid[0]
        p = partition(rects, tris, grid, (W, H))
        assert_partition_valid(p, W, H)
        assert (p.visible.sum(axis=0) >= 1).all()  # every rect drawn by someone
        # a point lies in exactly one region
        assert (p.visible[:, 2 * n:].sum(axis=0) == 1).all()
