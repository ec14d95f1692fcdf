"""Splitting big objects into clusters: same triangles, compact bounds, same images, less overlap."""

import numpy as np
import pytest

from multigpu.core.balance import partition
from multigpu.core.bounds import BoxProjector
from multigpu.core.camera import frame_matrices
from multigpu.core.triangles import triangle_objects
from multigpu.errors import InputError
from multigpu.gpu.render import RegionRenderer, create_context
from multigpu.scene.cluster import split_objects
from multigpu.scene.models import SceneSpec, load_scene
from multigpu.scene.paths import walkthrough


@pytest.fixture(scope="module")
def plant():
    scene, _ = load_scene(SceneSpec(triangles=20_000))
    return scene


def test_clusters_keep_every_triangle_and_bound_it(plant):
    c = split_objects(plant, 32)
    assert c.n_triangles == plant.n_triangles and c.tris.max() <= 32
    assert c.n_objects > plant.n_objects
    a, _ = triangle_objects(plant)
    b, obj = triangle_objects(c)
    # the same triangles (as vertex triples), in another order
    key = lambda t: np.sort(t, axis=1)[np.lexsort(np.sort(t, axis=1).T[::-1])]
    np.testing.assert_array_equal(key(a), key(b))
    world = c.world_positions()[b]  # (T, 3, 3)
    assert (world.min(axis=1) >= c.bmin[obj] - 1e-9).all() and (world.max(axis=1) <= c.bmax[obj] + 1e-9).all()
    d = np.linalg.norm(world - c.centers[obj][:, None, :], axis=2)
    assert (d <= c.radii[obj][:, None] + 1e-9).all()
    assert c.meta["modelled_objects"] == plant.n_objects


def test_small_objects_are_untouched_and_bad_sizes_refused(plant):
    assert split_objects(plant, int(plant.tris.max())) is plant
    with pytest.raises(InputError, match="cluster must be >= 1"):
        split_objects(plant, 0)
    with pytest.raises(InputError, match="cluster must be >= 0"):
        SceneSpec(cluster=-1)


def test_clusters_cut_overlap_and_render_the_same_wall(plant):
    path = walkthrough(plant, frames=40)
    c = split_objects(plant, 32)
    size = (160, 120)
    over = {}
    for name, s in (("whole", plant), ("clusters", c)):
        bp = BoxProjector(s.bmin, s.bmax)
        tot = vis = 0
        for f in range(0, 40, 4):
            view, proj, _ = frame_matrices(path.camera(f), size)
            r = bp(view, proj)
            tot += partition(r, s.tris, (2, 2), size).loads.sum()
            vis += s.tris[~np.isnan(r[:, 0])].sum()
        over[name] = tot / vis
    assert over["clusters"] < over["whole"]
    ctx, _ = create_context()
    r0, r1 = RegionRenderer(ctx, plant, size, "scissor"), RegionRenderer(ctx, c, size, "scissor")
    bp = BoxProjector(c.bmin, c.bmax)
    for f in (10, 30):
        view, proj, light = frame_matrices(path.camera(f), size)
        want = r0.render(view, proj, light, (0, 0, *size), None)
        part = partition(bp(view, proj), c.tris, (2, 2), size)
        img = np.zeros_like(want)
        for k, (x0, y0, x1, y1) in enumerate(part.regions):
            img[y0:y1, x0:x1] = r1.render(view, proj, light, (x0, y0, x1, y1), part.visible[k])
        assert (img != r1.render(view, proj, light, (0, 0, *size), None)).any(axis=2).sum() == 0
        assert (img != want).any(axis=2).sum() <= 0.002 * size[0] * size[1]  # draw order inside objects only
    r0.release()
    r1.release()
