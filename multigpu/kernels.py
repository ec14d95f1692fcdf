"""Every compiled kernel of the package, warmed at setup (numba, nopython, ``cache=True``).

Each kernel sits beside the code it serves, as ``<module>_kernel.py``, with its numpy reference in
``<module>.py`` and the choice between them made there once (``core.jit.use``):

* ``core/bounds_kernel.py``: box projection with frustum culling, near-plane clipping, coverage;
* ``core/balance_kernel.py``: the paper's balancer: pixel spans, the GPU-tree walk with the strip
  chooser (Start/End arrays, prefix/postfix sums, the split nearest balRatio), T' masks, loads;
* ``core/splits_kernel.py``: Equalizer's time chooser (time feedback's cuts, which the walk takes);
* ``core/drawlist_kernel.py``: a rank's mask to run-merged draw commands (of objects, or of parts);
* ``core/culling_kernel.py``: the parts of the objects a region needs that reach it;
* ``core/lod_kernel.py``: each object's level of detail from its distance and the pixel bound;
* ``core/motion_kernel.py``: a moving scene's objects posed: their boxes, spheres and GPU maps;
* ``scene/swarm_kernel.py``: the swarm's flight, every object's map;
* ``core/work_kernel.py``: a frame's transfers, every (piece, tile) overlap in message order;
* ``strategies/cross_kernel.py``: cross-segment balancing (profiles, shares, cuts, piece masks);
* ``strategies/cost_kernel.py``: the cost model's least-squares fit and term selection;
* ``strategies/base_kernel.py``: the cost model's per-rank pixel feature;
* ``strategies/adaptive_kernel.py``: ``adaptive``'s sums over the T' masks;
* ``strategies/auto_kernel.py``: the triangles of the objects in view (``auto``'s trial load);
* ``scene/labels_kernel.py``: connected components of a mesh's vertices (load time);
* ``scene/parts_kernel.py``: objects cut into parts, their triangles reordered (load time);
* ``scene/same_cells_kernel.py``: a series' step in its first step's layout (a live stream's keeper);
* ``core/octahedral_kernel.py``: the GL vertices' normals as octahedral codes (every upload).

Every kernel forms its values with the same operations in the same order as its reference, so
results are equal bit for bit (tests/test_kernel.py, hypothesis and extremes). ``warm()``
compiles (first run on a machine) or loads every signature at setup, never in a frame; without
numba the references run (``available()`` says which). This module sits above the strategies
and decompositions because warming plans frames with every registered strategy.
"""

from __future__ import annotations

import time

import numpy as np

from multigpu.core.balance_kernel import strip_partition
from multigpu.core.bounds import BoxProjector
from multigpu.core.camera import Camera, look_at, perspective
from multigpu.core.culling_kernel import _seen
from multigpu.core.drawlist_kernel import _commands, _part_commands
from multigpu.core.jit import available
from multigpu.core.lod_kernel import _choose
from multigpu.core.motion_kernel import _pose, _pose_span, _rotations
from multigpu.core.octahedral import encode, pack
from multigpu.core.tree import gpu_tree
from multigpu.core.work_kernel import _parts
from multigpu.scene.moves_kernel import _machine
from multigpu.scene.parts import with_parts
from multigpu.scene.plant import generate_plant
from multigpu.scene.same_cells import _place_compiled
from multigpu.scene.swarm_kernel import _fly
from multigpu.strategies import REGISTRY
from multigpu.strategies.base_kernel import rank_pixels
from multigpu.strategies.cost_kernel import fit_terms

#: every kernel module, for the tests that check them all (compiled, cached, no Python objects)
MODULES = ("multigpu.core.bounds_kernel", "multigpu.core.balance_kernel", "multigpu.core.splits_kernel",
           "multigpu.core.culling_kernel", "multigpu.core.lod_kernel", "multigpu.core.motion_kernel",
           "multigpu.scene.swarm_kernel",
           "multigpu.core.drawlist_kernel", "multigpu.core.work_kernel", "multigpu.strategies.cross_kernel",
           "multigpu.strategies.cost_kernel", "multigpu.strategies.base_kernel",
           "multigpu.strategies.adaptive_kernel", "multigpu.strategies.auto_kernel",
           "multigpu.scene.labels_kernel", "multigpu.scene.parts_kernel", "multigpu.scene.same_cells_kernel",
           "multigpu.core.octahedral_kernel")


def warm() -> float:
    """Compile (or load from numba's cache) every signature a run uses (every registered
    strategy plans a few frames); seconds it took. tests/test_kernel.py checks that frames
    planned afterwards, with every strategy and decomposition, compile nothing."""
    if not available():
        return 0.0
    t0 = time.perf_counter()
    rects = np.array([[0.1, 0.1, 0.6, 0.7], [0.5, 0.2, 0.9, 0.9], [np.nan] * 4])
    for tris in (np.array([3, 5, 7], dtype=np.int64), np.array([3.0, 5.0, 7.0])):
        strip_partition(rects, tris, gpu_tree(2, 2), (64, 64), 16)
    view, proj = look_at([0, -5, 1], [0, 0, 0], [0, 0, 1]), perspective(60, 1.0, 0.1, 100)
    box = BoxProjector(np.array([[-1.0, -1, -1], [0, -6, 0]]), np.array([[1.0, 1, 1], [1, -4, 2]]), compiled=True)
    box(view, proj)
    box(view, proj, np.empty(2))
    camera = Camera((0.0, -5.0, 1.0), (0.0, 0.0, 0.0))
    box.frame(camera, (64, 48))
    box.frame(camera, (64, 48), np.empty(2))
    one = np.ones(1)  # a generated path's check of its frames
    box.frames_seen(np.array([[0.0, -5.0, 1.0]]), np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), 60 * one, 0.1 * one,
                    100 * one, (64, 48))
    tris, coverage, times = np.array([3, 5, 7], dtype=np.int64), np.array([0.5, 1.0, 1.0]), np.arange(1.0, 5.0)
    for cls in REGISTRY.values():  # every strategy's plans, the ones that learn from measured times too
        strategy = cls((2, 2), (64, 64), 16, compiled=True)
        for f in range(4):
            strategy.observe(f, strategy.plan(rects, tris, coverage), times + f)
    rank_pixels(np.zeros((4, 2), dtype=np.int32), np.ones((1, 2), dtype=np.bool_), np.array([[0, 0, 4, 4]]),
                np.ones((1, 2)), np.empty((1, 1)))
    fit_terms(np.array([[1.0, 2.0, 3.0], [2.0, 1.0, 4.0], [3.0, 3.0, 5.0], [4.0, 1.0, 7.0]]), 0.05, 0.5, np.empty(10))
    _commands(np.ones(2, dtype=np.bool_), np.arange(2, dtype=np.int64), np.array([0, 3, 6], dtype=np.int64))
    _part_commands(np.ones(2, dtype=np.bool_), np.ones(3, dtype=np.bool_), np.array([0, 0, 1], dtype=np.int64),
                   np.arange(3, dtype=np.int64), np.array([0, 3, 6, 9], dtype=np.int64))
    _parts(np.array([[0, 0, 4, 4]]), np.array([1]), np.array([[0, 0, 2, 2]]))
    _seen(np.zeros((4, 1)), 64.0, 64.0, 0, 0, 64, 64, np.zeros(1, dtype=np.int64), np.ones(1, dtype=np.bool_))
    with_parts(generate_plant(2000, seed=0), 16)  # the parts kernels, as a scene's first load runs them
    _choose(np.zeros((1, 3)), np.ones(1), np.zeros((1, 2)), np.ones((1, 2), dtype=np.int64), np.zeros((1, 1)),
            np.zeros(1, dtype=np.int64), 0.0, 0.0, 5.0, 100.0, 0.1, 1.0, np.empty(1, dtype=np.int8),
            np.empty(1, dtype=np.int64))
    one, idx = np.zeros((1, 3)), np.zeros(1, dtype=np.int64)
    _rotations(one, np.zeros(1), np.empty((1, 3, 3)))
    _fly(0.5, 0.0, 0.0, 0.0, 0, one, one, np.zeros(3), np.ones((1, 8), dtype=np.float32), 2.0, 12.0, 16.0,
         np.empty((1, 3, 3)), np.empty((1, 3)))
    _pose_span(np.zeros((1, 3, 3)), one, 0, one, one, one, np.ones(1), np.zeros(3), 1e-12, True, np.empty((3, 1)),
               np.empty((3, 1)), np.empty((1, 3)), np.empty(1), np.empty((1, 12), dtype=np.float32))
    _machine(0.5, idx, one, np.zeros(1), one, one, np.zeros(1), np.zeros(1), np.empty((1, 3, 3)), np.empty((1, 3)))
    _pose(np.zeros((1, 3, 3)), one, idx, idx, one, one, one, np.ones(1), np.zeros(3), 1e-12, True, np.empty((3, 1)),
          np.empty((3, 1)), np.empty((1, 3)), np.empty(1), np.empty((1, 12), dtype=np.float32), 0)
    tri = np.zeros((1, 3), dtype=np.int64)  # a live stream's steps, made by rank 0's keeper
    _place_compiled(np.zeros((1, 3)), idx, tri, idx, None, 1, 0)
    encode(np.zeros((1, 3)), compiled=True)  # every vertex upload's normals
    pack(np.zeros((1, 6), dtype=np.float32), compiled=True)
    return time.perf_counter() - t0


__all__ = ["MODULES", "available", "warm"]
