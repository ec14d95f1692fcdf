"""Parts and sub-object culling: a scene's objects cut inside themselves (scene/parts.py), the
parts a region needs (core/culling.py) against a per-triangle reference, and their draw commands."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core.camera import look_at, perspective
from multigpu.core.culling import PartCuller
from multigpu.core.drawlist import DrawList
from multigpu.core.regions import overlaps, pixel_spans
from multigpu.core.triangles import triangle_objects, triangle_rects
from multigpu.scene.parts import with_parts
from multigpu.scene.plant import generate_plant


@pytest.fixture(scope="module")
def scene():
    return with_parts(generate_plant(20_000, seed=3), 16)  # small parts: many objects cut


def _triangles(scene):
    tri, obj = triangle_objects(scene)
    return tri, obj


def test_parts_cover_every_object_and_bound_their_triangles(scene):
    base = generate_plant(20_000, seed=3)
    n = np.diff(scene.part_start)
    assert (n >= 1).all() and scene.meta["parts"]["objects_cut"] == int((n > 1).sum()) > 10
    per_object = np.add.reduceat(scene.part_count, scene.part_start[:-1])
    assert np.array_equal(per_object, scene.index_count)  # an object's parts fill its range exactly
    assert (scene.part_count[np.repeat(n > 1, n)] <= 16 * 3).all()
    # the same triangles per object, only reordered inside it
    for s in (base, scene):
        tri, obj = _triangles(s)
        s.key = sorted(zip(obj.tolist(), map(tuple, np.sort(tri, axis=1).tolist())))
    assert base.key == scene.key
    # every part's box holds its triangles (world space; a whole object's box, like the objects',
    # is made from the float64 positions the float32 vertices round: within their rounding)
    world = scene.world_positions()
    tri, _ = _triangles(scene)
    part = np.repeat(np.arange(scene.n_parts), scene.part_count // 3)
    corners = world[tri]
    tol = np.abs(world).max() * 2.0**-22
    assert (corners.min(axis=1) >= scene.part_bmin[part] - tol).all()
    assert (corners.max(axis=1) <= scene.part_bmax[part] + tol).all()


def test_parts_compiled_equal_the_numpy_reference_whatever_the_block(monkeypatch):
    import multigpu.scene.parts as parts

    base = generate_plant(30_000, seed=4)
    want = with_parts(base, 16, compiled=False)
    for block in (parts.BLOCK_TRIS, 1000, 97):  # objects grouped into blocks, or one per block
        monkeypatch.setattr(parts, "BLOCK_TRIS", block)
        for compiled in (True, False):
            got = with_parts(base, 16, compiled=compiled)
            for k in ("indices", "part_start", "part_count", "part_bmin", "part_bmax"):
                assert np.array_equal(getattr(got, k), getattr(want, k)), (block, compiled, k)


def test_a_scene_s_objects_keep_their_parts(scene):
    idx = np.array([5, 0, 17, 3])
    sub = scene.objects(idx)
    for j, i in enumerate(idx):
        a, b = scene.part_start[i], scene.part_start[i + 1]
        c, d = sub.part_start[j], sub.part_start[j + 1]
        assert np.array_equal(sub.part_count[c:d], scene.part_count[a:b])
        assert np.array_equal(sub.part_bmin[c:d], scene.part_bmin[a:b])
    moved = scene.translated((1e6, 0, 0))
    assert np.allclose(moved.part_bmin - scene.part_bmin, [1e6, 0, 0])


camera = st.tuples(st.floats(-150, 350), st.floats(-100, 250), st.floats(1, 80), st.floats(0, 200),
                   st.floats(0, 120), st.floats(60, 90))
region = st.tuples(st.integers(0, 127), st.integers(0, 95), st.integers(1, 128), st.integers(1, 96))


@settings(max_examples=40, deadline=None)
@given(camera=camera, box=region)
def test_the_cull_keeps_every_part_with_a_triangle_in_the_region(scene, camera, box):
    """Conservative against the per-triangle ground truth: a triangle whose exact rect touches
    the region always belongs to a part the cull keeps; compiled and numpy give the same parts."""
    ex, ey, ez, tx, ty, fov = camera
    x0, y0 = box[0], box[1]
    reg = (x0, y0, max(x0 + 1, box[2]), max(y0 + 1, box[3]))
    size = (128, 96)
    view, proj = look_at([ex, ey, ez], [tx, ty, 0.0], [0, 0, 1]), perspective(fov, size[0] / size[1], 0.5, 2000)
    cull, ref = PartCuller(scene, compiled=True), PartCuller(scene, compiled=False)
    for c in (cull, ref):
        c.frame(view, proj, size)
    got = cull.seen(reg).copy()
    assert np.array_equal(got, ref.seen(reg))
    tri, _ = _triangles(scene)
    rects = triangle_rects(scene.world_positions(), tri, view, proj)
    spans, onscreen = pixel_spans(rects, size)
    needed = onscreen & overlaps(spans, reg)
    part = np.repeat(np.arange(scene.n_parts), scene.part_count // 3)
    assert got[part[needed]].all()


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), keep=st.floats(0, 1), seen=st.floats(0, 1))
def test_part_commands_compiled_equal_numpy_and_draw_exactly_the_kept_parts(scene, seed, keep, seen):
    draws = DrawList(scene)
    rng = np.random.default_rng(seed)
    mask = rng.random(scene.n_objects) < keep
    vis = rng.random(scene.n_parts) < seen
    got = draws.part_commands(mask, vis, compiled=True)
    assert np.array_equal(got, draws.part_commands(mask, vis, compiled=False))
    drawn = np.zeros(int(draws.part_offsets[-1]), dtype=bool)
    for count, _, first, _, _ in got:  # commands, not objects
        assert not drawn[first:first + count].any()  # no index twice
        drawn[first:first + count] = True
    want = np.zeros_like(drawn)
    kept = mask[draws.part_obj] & vis
    for p in np.flatnonzero(kept):
        at = int(np.flatnonzero(draws.part_order == p)[0])
        want[draws.part_offsets[at]:draws.part_offsets[at + 1]] = True
    assert np.array_equal(drawn, want)
    everything = draws.part_commands(np.ones(scene.n_objects, bool), np.ones(scene.n_parts, bool))
    assert np.array_equal(everything, draws.commands(None))  # all parts: the objects' one command
