"""Run-merged draw commands draw exactly the triangles of the masked objects."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core.drawlist import DrawList, morton_order
from multigpu.scene.plant import generate_plant


def _triangles(scene, mask):
    """Independent reference: the masked objects' triangles as sorted absolute index triples."""
    out = []
    for i in np.flatnonzero(mask):
        s, c, b = scene.first_index[i], scene.index_count[i], scene.base_vertex[i]
        out.append(scene.indices[s:s + c].astype(np.int64) + b)
    tri = np.concatenate(out).reshape(-1, 3) if out else np.zeros((0, 3), np.int64)
    return tri[np.lexsort(tri.T[::-1])]


def _drawn(dl, cmds):
    parts = [dl.indices[f:f + c].astype(np.int64) for c, _, f, _, _ in cmds]
    tri = np.concatenate(parts).reshape(-1, 3) if parts else np.zeros((0, 3), np.int64)
    return tri[np.lexsort(tri.T[::-1])]


SCENE = generate_plant(triangles=6000, seed=5)
DL = DrawList(SCENE)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0, 1))
def test_commands_cover_exactly_the_masked_objects(seed, density):
    mask = np.random.default_rng(seed).random(SCENE.n_objects) < density
    cmds = DL.commands(mask)
    assert cmds.dtype == np.uint32 and cmds.shape[1] == 5
    assert (cmds[:, 1] == 1).all() and (cmds[:, 0] > 0).all()
    np.testing.assert_array_equal(_drawn(DL, cmds), _triangles(SCENE, mask))


def test_all_visible_is_one_command_and_none_is_empty():
    assert len(DL.commands(None)) == 1
    assert len(DL.commands(np.zeros(SCENE.n_objects, bool))) == 0


def test_vertex_object_ids_and_layout():
    counts = np.bincount(DL.vertex_object, minlength=SCENE.n_objects)
    for i in (0, SCENE.n_objects // 2, SCENE.n_objects - 1):
        b = SCENE.base_vertex[i]
        used = np.unique(SCENE.indices[SCENE.first_index[i]:SCENE.first_index[i] + SCENE.index_count[i]]) + b
        assert (DL.vertex_object[used] == i).all()
    assert counts.sum() == SCENE.vertices.shape[0]
    assert sorted(DL.order) == list(range(SCENE.n_objects))


def test_morton_order_keeps_neighbours_together():
    g = np.stack(np.meshgrid(np.arange(8), np.arange(8), np.arange(8), indexing="ij"), -1).reshape(-1, 3)
    order = morton_order(g.astype(float))
    # each consecutive group of 8 in Z-order is one 2x2x2 cell
    cells = g[order].reshape(-1, 8, 3) // 2
    assert (cells == cells[:, :1]).all()
    assert morton_order(np.zeros((0, 3))).size == 0


def test_built_in_blocks_equals_the_whole_buffer_at_once(monkeypatch):
    """The buffer is built a block of indices at a time (small temporaries at any scale): with
    blocks that cut objects anywhere and vertices shared between objects, it equals the direct
    whole-array construction (last object's id on a shared vertex)."""
    import multigpu.core.drawlist as drawlist
    from multigpu.scene.cluster import split_objects

    scene = split_objects(generate_plant(triangles=6000, seed=3), 16)  # parts share their parent's vertices
    count = scene.index_count.astype(np.int64)
    absolute = scene.indices.astype(np.int64) + np.repeat(scene.base_vertex.astype(np.int64), count)
    owner = np.zeros(scene.vertices.shape[0], np.uint32)
    owner[absolute] = np.repeat(np.arange(scene.n_objects, dtype=np.uint32), count)
    for chunk in (1, 7, 997, 1 << 20):
        monkeypatch.setattr(drawlist, "CHUNK", chunk)
        dl = DrawList(scene)
        want = np.concatenate([absolute[scene.first_index[i]:scene.first_index[i] + count[i]] for i in dl.order])
        np.testing.assert_array_equal(dl.indices, want)
        np.testing.assert_array_equal(dl.vertex_object, owner)
    objects = np.repeat(np.arange(scene.n_objects), count)
    pairs = np.unique(np.stack([absolute, objects]), axis=1)
    assert len(np.unique(pairs[0])) < pairs.shape[1]  # vertices shared between objects were there to test


def test_wide_objects_are_drawn_last_in_morton_order():
    from multigpu.core.drawlist import WIDE_SHARE, draw_order, morton_codes, wide_objects

    rng = np.random.default_rng(5)
    n = 500
    centers = rng.random((n, 3))
    half = rng.exponential(0.05, (n, 1))
    tris = rng.integers(1, 400, n)
    wide = wide_objects(tris, centers - half, centers + half)
    size = tris * np.linalg.norm(2 * half, axis=1)
    assert size[wide].min() >= size[~wide].max()  # the biggest by triangles x world size
    held = tris[wide].sum() / tris.sum()
    assert WIDE_SHARE <= held <= WIDE_SHARE + tris.max() / tris.sum()  # just enough of the triangles
    order = draw_order(centers, wide)
    assert sorted(order.tolist()) == list(range(n)) and not wide[order[:n - wide.sum()]].any()
    for part in (order[~wide[order]], order[wide[order]]):
        assert (np.diff(morton_codes(centers)[part].astype(np.int64)) >= 0).all()
    assert not wide_objects(tris, centers, centers, 0.0).any()
    assert not wide_objects(np.full(3, 2), centers[:3], centers[:3] + 1).any()  # none stands out
    assert (draw_order(centers) == morton_order(centers)).all()
