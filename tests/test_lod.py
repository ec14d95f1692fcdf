"""Levels of detail: built once (valid, coarser, errors non-decreasing), cached, drawn as chosen,
chosen within the pixel bound (the compiled choice equal to the numpy reference)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core.camera import Camera
from multigpu.core.drawlist import DrawList
from multigpu.core.lod import LevelChooser
from multigpu.scene.layout import Scene
from multigpu.scene.lod import cut_from_one, with_lods
from multigpu.scene.parts import with_parts
from multigpu.scene.plant import generate_plant

SCENE = with_lods(with_parts(generate_plant(triangles=20000, seed=3)))
DL = DrawList(SCENE)


def _level_tris(scene, i, lv):
    """Object ``i``'s level ``lv`` as absolute index triples, from the scene's arrays alone."""
    s, c = int(scene.lod_first[i, lv]), int(scene.lod_count[i, lv])
    return scene.indices[s:s + c].astype(np.int64).reshape(-1, 3) + int(scene.base_vertex[i])


def test_levels_are_coarser_valid_and_their_errors_grow():
    count, err = SCENE.lod_count, SCENE.lod_error
    assert count.shape == (SCENE.n_objects, 4) and (count[:, 0] == SCENE.index_count).all()
    assert (err[:, 0] == 0).all() and (err[:, 1:] >= err[:, :-1]).all()  # inf past an object's last level
    kept = np.isfinite(err)
    assert kept[:, 1].sum() > SCENE.n_objects // 10  # the plant's pipes simplify
    assert (count[~kept] == 0).all() and (count[kept] > 0).all()
    for lv in range(1, 4):
        rows = np.flatnonzero(kept[:, lv])
        assert (count[rows, lv] <= 0.75 * count[rows, lv - 1]).all()  # each kept level drops a quarter at least
    for i in np.flatnonzero(kept[:, 1])[:50]:  # a level uses only its object's own vertices
        own = _level_tris(SCENE, i, 0)
        for lv in np.flatnonzero(kept[i]):
            t = _level_tris(SCENE, i, lv)
            assert t.min() >= own.min() and t.max() <= own.max()
            assert (t[:, 0] != t[:, 1]).all()  # no collapsed triangles
    assert SCENE.meta["lods"]["locked_borders"] is False  # whole objects simplify freely


def test_cut_scenes_lock_their_borders():
    base = generate_plant(triangles=5000, seed=1)
    assert not cut_from_one(base)
    base.meta["objects"] = {"split": "grid:8", "cluster": 0}
    assert cut_from_one(base)
    base.meta["objects"] = {"split": "auto", "cluster": 512}
    assert cut_from_one(base)


def test_levels_survive_the_cache_and_object_picks(tmp_path):
    SCENE.save(tmp_path / "s.npz")
    back = Scene.load(tmp_path / "s.npz")
    for k in Scene.LODS:
        np.testing.assert_array_equal(getattr(back, k), getattr(SCENE, k))
    np.testing.assert_array_equal(np.asarray(back.indices), SCENE.indices)
    idx = np.array([5, 2, 9])
    picked = SCENE.objects(idx)
    np.testing.assert_array_equal(picked.lod_count, SCENE.lod_count[idx])
    assert picked.levels == 4


def _drawn(cmds):
    parts = [DL.indices[f:f + c].astype(np.int64) for c, _, f, _, _ in cmds]
    tri = np.concatenate(parts).reshape(-1, 3) if parts else np.zeros((0, 3), np.int64)
    return tri[np.lexsort(tri.T[::-1])]


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0, 1))
def test_leveled_commands_draw_each_masked_object_at_its_level(seed, density):
    rng = np.random.default_rng(seed)
    mask = rng.random(SCENE.n_objects) < density
    kept = np.isfinite(SCENE.lod_error).sum(axis=1)  # levels each object has
    levels = (rng.integers(0, 4, SCENE.n_objects) % kept).astype(np.int8)
    cmds = DL.leveled(mask, levels)
    want = [_level_tris(SCENE, i, levels[i]) for i in np.flatnonzero(mask)]
    want = np.concatenate(want) if want else np.zeros((0, 3), np.int64)
    np.testing.assert_array_equal(_drawn(cmds), want[np.lexsort(want.T[::-1])])
    np.testing.assert_array_equal(DL.leveled(mask, levels, compiled=False), cmds)


def _camera(rng):
    lo, hi = SCENE.bounds
    eye = lo + (hi - lo) * rng.uniform(-0.5, 1.5, 3)
    return Camera(tuple(eye), tuple((lo + hi) / 2), fov=float(rng.uniform(20, 90)), near=0.05)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.01, 50))
def test_choice_is_the_coarsest_within_the_bound_and_the_kernel_agrees(seed, bound):
    cam = _camera(np.random.default_rng(seed))
    chooser = LevelChooser(SCENE, 480)
    rects = np.random.default_rng(seed).random((SCENE.n_objects, 4))
    rects[::3] = np.nan  # unseen objects keep level 0
    got = chooser.choose(cam, bound, rects), chooser.choose(cam, bound, rects, compiled=False)
    for levels, tris in got:
        lv = np.zeros(SCENE.n_objects, np.int64) if levels is None else levels.astype(np.int64)
        assert (lv[::3] == 0).all() and (tris[::3] == SCENE.tris[::3]).all()
    np.testing.assert_array_equal(*(np.zeros(SCENE.n_objects) if g[0] is None else g[0] for g in got))
    np.testing.assert_array_equal(got[0][1], got[1][1])
    ref_levels, ref_tris = chooser.choose(cam, bound, compiled=False)
    levels, tris = chooser.choose(cam, bound)
    lv = np.zeros(SCENE.n_objects, np.int64) if levels is None else levels.astype(np.int64)
    ref = np.zeros(SCENE.n_objects, np.int64) if ref_levels is None else ref_levels.astype(np.int64)
    np.testing.assert_array_equal(lv, ref)
    np.testing.assert_array_equal(tris, ref_tris)
    # brute force, per object: the error in pixels at the sphere's nearest point to the eye
    focal = 480 / (2 * math.tan(math.radians(cam.fov) / 2))
    d = np.linalg.norm(SCENE.centers - np.asarray(cam.position), axis=1) - SCENE.radii
    px = SCENE.lod_error * (focal / np.maximum(d, cam.near))[:, None]
    rows = np.arange(SCENE.n_objects)
    assert (px[rows, lv] <= bound).all()
    coarser = np.minimum(lv + 1, 3)
    assert ((px[rows, coarser] > bound) | (coarser == lv)).all()
    np.testing.assert_array_equal(tris, SCENE.lod_count[rows, lv] // 3)


def test_a_zero_bound_draws_every_object_as_modelled():
    chooser = LevelChooser(SCENE, 480)
    levels, tris = chooser.choose(_camera(np.random.default_rng(0)), 0.0)
    assert levels is None and (tris == SCENE.tris).all()


@pytest.mark.parametrize("bound", [0.5, 4.0])
def test_nearer_objects_are_never_coarser(bound):
    """One object moved toward the eye never gets a coarser level."""
    chooser = LevelChooser(SCENE, 480)
    i = int(np.flatnonzero(np.isfinite(SCENE.lod_error[:, 3]))[0])
    c = SCENE.centers[i]
    got = []
    for dist in (200.0, 50.0, 10.0, 2.0):
        cam = Camera(tuple(c + np.array([dist, 0, 0])), tuple(c))
        levels, _ = chooser.choose(cam, bound, compiled=False)
        got.append(0 if levels is None else int(levels[i]))
    assert got == sorted(got, reverse=True)


def test_the_simplifier_benchmark_measures_distance_to_the_surface():
    """``bench simplify``'s error estimate: a point's distance to a triangle is never more than to
    any point on it (dense samples), and within their spacing of the nearest."""
    from scipy.spatial import cKDTree

    from multigpu.studies.simplify import _to_triangles, distances

    rng = np.random.default_rng(0)
    for _ in range(5):
        a, b, c = rng.random((3, 1, 3))
        p = rng.random((300, 3)) * 2 - 0.5
        d = _to_triangles(p, *(np.repeat(x, 300, 0) for x in (a, b, c)))
        u = rng.random((100_000, 2))
        u[u.sum(1) > 1] = 1 - u[u.sum(1) > 1]
        dense = a[0] + (b[0] - a[0]) * u[:, :1] + (c[0] - a[0]) * u[:, 1:]
        near = cKDTree(dense).query(p)[0]
        assert (d <= near + 1e-12).all() and (near - d).max() < 0.01
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    f = np.array([[0, 1, 2], [1, 3, 2]])
    assert max(distances(v, f, v, f)) < 1e-12
    h, mean = distances(v, f, v + [0, 0, 0.25], f)
    assert h == pytest.approx(0.25) and mean == pytest.approx(0.25)
