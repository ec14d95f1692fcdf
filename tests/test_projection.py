"""The bounds' projection in slices (``SharedProjection``, which ``--projection shared`` gives
each rank of a host): the slices' rects, put together, are ``Planner.frame``'s."""

import numpy as np
import pytest

from multigpu.config import WalkConfig
from multigpu.planner import Planner
from multigpu.rank.projection import SharedProjection
from multigpu.scene.models import SceneSpec, load_scene
from multigpu.scene.paths import generate


class _Node:
    """A host of ``n`` ranks, as far as a slice needs to know."""

    def __init__(self, n: int):
        self.n = n

    def Get_size(self):  # noqa: N802
        return self.n


@pytest.fixture(scope="module")
def plant():
    return load_scene(SceneSpec(triangles=20_000))[0]


def _slices(cfg, scene, parts: int, rects: np.ndarray) -> list[SharedProjection]:
    n = scene.n_objects
    return [SharedProjection(_Node(parts), Planner(cfg, scene, 0), rects, p * n // parts, (p + 1) * n // parts, 1.0)
            for p in range(parts)]


@pytest.mark.parametrize("mullion", [(0, 0), (12, 6)])
@pytest.mark.parametrize("parts", [1, 2, 3, 7])
def test_slices_make_the_whole_frames_rects_bit_for_bit(plant, mullion, parts):
    cfg = WalkConfig(grid=(2, 2), tile=(128, 96), mullion=mullion, balance="cross")
    whole = Planner(cfg, plant, 0)
    shared = np.full((2, 4, plant.n_objects), -7.0)  # the host's array: two frames
    ranks = _slices(cfg, plant, parts, shared)
    assert all(r.sliceable for r in ranks)
    path = generate("walkthrough", plant, 12)
    for f in range(len(path)):
        view, proj, light, rects = whole.frame(path.camera(f))
        for r in ranks:
            got = r.project_slice(f, path.camera(f))
            for a, b in zip(got, (view, proj, light)):
                assert np.array_equal(a, b)
        for r in ranks:
            assert np.array_equal(r.gathered(f), rects, equal_nan=True)
        if f:  # the last frame's rects stay as they were (the planner may still hold them)
            _, _, _, before = whole.frame(path.camera(f - 1))
            assert np.array_equal(ranks[0].gathered(f - 1), before, equal_nan=True)


def test_what_cannot_be_sliced(plant):
    """Coverage (the cost model) and sphere bounds are projected whole."""
    rects = np.zeros((2, 4, plant.n_objects))
    assert not _slices(WalkConfig(grid=(2, 2), balance="cost"), plant, 2, rects)[0].sliceable
    assert not _slices(WalkConfig(grid=(2, 2), bounds="sphere"), plant, 2, rects)[0].sliceable
