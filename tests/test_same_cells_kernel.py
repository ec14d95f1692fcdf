"""A step placed in its first step's layout, compiled (scene/same_cells_kernel.py) against the numpy
reference (same_cells.place_reference): the same vertices, normals, origin, object and part boxes and
farthest corners, bit for bit, on random layouts, degenerate triangles and extreme coordinates."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core import jit
from multigpu.scene.same_cells import _place_compiled, place_reference

pytestmark = pytest.mark.skipif(not jit.available(), reason="numba is not installed (pip install numba)")
NAMES = ("vertices", "origin", "bmin", "bmax", "far", "part_bmin", "part_bmax")


def layout(rng, n_points: int, n_vertices: int, n_tris: int, n_objects: int, parts: bool):
    """Vertex sources, triangles in runs of objects (each object's parts in runs of their own)."""
    point = rng.integers(0, n_points, n_vertices)
    tri = rng.integers(0, n_vertices, (n_tris, 3))
    cuts = np.sort(rng.choice(np.arange(1, n_tris), min(n_objects, n_tris) - 1, replace=False)) if n_tris > 1 \
        else np.zeros(0, dtype=np.int64)
    obj = np.repeat(rng.permutation(len(cuts) + 1), np.diff(np.r_[0, cuts, n_tris]))
    part = None
    if parts:
        part_cuts = np.unique(np.r_[cuts, rng.integers(1, max(2, n_tris), 3)]).astype(np.int64)
        part_cuts = part_cuts[(part_cuts > 0) & (part_cuts < n_tris)]
        part = np.repeat(np.arange(len(part_cuts) + 1), np.diff(np.r_[0, part_cuts, n_tris]))
    return point, tri, obj, part, len(cuts) + 1, 0 if part is None else int(part.max()) + 1


def same(points, point, tri, obj, part, n, p):
    ref = place_reference(points, point, tri, obj, part, n, p)
    got = _place_compiled(points, point, tri, obj, part, n, p)
    for name, a, b in zip(NAMES, got, ref):
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert np.array_equal(a, b, equal_nan=True), f"{name} differs at {np.argwhere(a != b)[:5].tolist()}"


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_points=st.integers(1, 40), n_vertices=st.integers(1, 60),
       n_tris=st.integers(1, 120), n_objects=st.integers(1, 8), parts=st.booleans(),
       scale=st.sampled_from([1.0, 1e-6, 1e3, 1e7]), flat=st.booleans())
def test_compiled_placing_equals_the_reference(seed, n_points, n_vertices, n_tris, n_objects, parts, scale, flat):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n_points, 3)) * scale + rng.normal(size=3) * scale * 10
    if flat:  # a plate: every normal +-z, many of them summing to zero where a vertex is shared oddly
        points[:, 2] = 0.25
    same(points, *layout(rng, n_points, n_vertices, n_tris, n_objects, parts))


def test_degenerate_triangles_get_the_up_normal_and_extremes_stay_equal():
    rng = np.random.default_rng(1)
    point, tri, obj, part, n, p = layout(rng, 5, 8, 30, 3, True)
    with np.errstate(all="ignore"):  # (the reference overflows where the kernel does)
        for points in (np.zeros((5, 3)), np.full((5, 3), 1e300), np.array([[1e-300, 0, 0]] * 5),
                       rng.normal(size=(5, 3)) * 1e150):
            same(points, point, tri, obj, part, n, p)
    got = _place_compiled(np.zeros((5, 3)), point, tri, obj, part, n, p)[0]
    assert (got[:, 3:] == [0, 0, 1]).all()  # no area anywhere: +z
