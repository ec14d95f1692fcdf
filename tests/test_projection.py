"""The bounds' projection in slices (``Planner.frame_slice``, which ``--projection shared``
gives each rank of a host): the slices' rects, put together, are ``Planner.frame``'s."""

import numpy as np
import pytest

from multigpu.config import WalkConfig
from multigpu.planner import Planner
from multigpu.scene.models import SceneSpec, load_scene
from multigpu.scene.paths import generate


@pytest.fixture(scope="module")
def plant():
    return load_scene(SceneSpec(triangles=20_000))[0]


@pytest.mark.parametrize("mullion", [(0, 0), (12, 6)])
@pytest.mark.parametrize("parts", [1, 2, 3, 7])
def test_slices_make_the_whole_frames_rects_bit_for_bit(plant, mullion, parts):
    cfg = WalkConfig(grid=(2, 2), tile=(128, 96), mullion=mullion, balance="cross")
    whole, sliced = Planner(cfg, plant, 0), Planner(cfg, plant, 0)
    assert sliced.sliceable
    n = plant.n_objects
    path = generate("walkthrough", plant, 12)
    out = np.full((4, n), -7.0)
    for f in range(len(path)):
        view, proj, light, rects = whole.frame(path.camera(f))
        for p in range(parts):
            got = sliced.frame_slice(path.camera(f), p * n // parts, (p + 1) * n // parts, out)
            for a, b in zip(got, (view, proj, light)):
                assert np.array_equal(a, b)
        assert np.array_equal(sliced.rects_of(out), rects, equal_nan=True)


def test_what_cannot_be_sliced(plant):
    """Coverage (the cost model) and sphere bounds are projected whole."""
    assert not Planner(WalkConfig(grid=(2, 2), balance="cost"), plant, 0).sliceable
    assert not Planner(WalkConfig(grid=(2, 2), bounds="sphere"), plant, 0).sliceable
