"""The compiled frame kernel (numba, nopython, ``cache=True``): the per-frame steps of balancing
as a few compiled calls where their numpy references (``bounds``, ``balance``, ``drawlist``...)
make hundreds of C-level calls.

* ``project.py``: box projection with frustum culling, near-plane clipping and coverage;
* ``walk.py``: the paper's balancer: pixel spans, GPU-tree walk with the strip chooser (Start/End
  arrays, prefix/postfix sums, the split nearest balRatio; the cost model's fill term too), T'
  masks and loads;
* ``pieces.py``: cross-segment balancing: segment profiles, shares and cuts, piece masks;
* ``draws.py``: a rank's mask to run-merged draw commands;
* ``parts.py``: a frame's transfers, every (piece, tile) overlap in message order;
* ``feedback.py``: Equalizer's time chooser (time feedback's cuts, which the walk then takes);
* ``seen.py``: the triangles of the objects in view (``auto``'s trial load);
* ``fit.py``: the cost model's least-squares fit and term selection;
* ``pixels.py``: the cost model's per-rank pixel feature;
* ``corrections.py``: ``adaptive``'s sums over the T' masks (per rank, per object).

Time feedback and the static tiles run the walk with cuts found without objects (time
feedback's by ``feedback.py``). Not compiled (numpy): ``adaptive``'s elementwise steps (its
weights, the exponential of its corrections: numpy's ``exp`` need not round as libm's does),
sphere bounds, and the ``db`` and ``bins`` decompositions.

Every kernel forms its values with the same operations in the same order as its reference, so
results are equal bit for bit (tests/test_kernel.py, hypothesis and extremes). ``warm()``
compiles (first run on a machine) or loads every signature at setup, never in a frame; without
numba the references run (``available()`` says which).
"""

from __future__ import annotations

import time

import numpy as np

from multigpu.core.kernel.jit import entry, numba
from multigpu.core.kernel.pieces import _cross
from multigpu.core.kernel.project import _project
from multigpu.core.kernel.seen import seen_triangles as _seen
from multigpu.core.kernel.walk import strip_partition, tree_arrays, tree_nodes


def available() -> bool:
    """Whether numba is installed (the kernels run compiled)."""
    return numba is not None


def use(compiled: bool | None) -> bool:
    """Whether to run a kernel: ``compiled`` None means where numba is installed; True insists."""
    if compiled and not available():
        raise ValueError("compiled=True needs numba (pip install numba)")
    return available() if compiled is None else bool(compiled)


def scratch_for(n: int) -> tuple:
    """``cross_partition``'s per-object scratch for ``n`` objects (the time model's spans, weights
    and on-screen objects), for a caller to keep between frames."""
    return np.empty((n, 4), dtype=np.int64), np.empty(n), np.empty(n, dtype=np.int64)


def cross_partition(pieces, mass, times, tiles, order, shares, damping: float, min_share: float, min_help: float,
                    join: bool, pixel_weight: float, object_weight: float, cover_weight: float, uniform: bool,
                    rects, tris, size,
                    out: np.ndarray | None = None, bound: dict | None = None, scratch: tuple | None = None):
    """``strategies.cross``: the new segment shares (into ``out`` where given, a (K,) float64
    array other than ``shares``), and the partition's fields (regions, loads, T' masks, splits,
    split pixels, no spans, pieces and their masks per rank, and the pieces flat for the next
    frame: ``{"pieces": (Q, 4), "owner": (Q,), "mass": (Q,)}``, their weights in the time model)
    from the last frame's pieces (that flat form, or per rank), their weights ``mass`` (None:
    weighed now; ignored where the flat form carries them) and measured ``times``; ``order``:
    the segments along the resource axis; ``join``: helpers cut from their own side and a rank's
    pieces joined; ``pixel_weight``, ``object_weight``, ``cover_weight``, ``uniform``: the time
    model's. One compiled call.
    ``bound``: a dict the caller keeps between calls that passes the same types every call
    (``times``, ``tiles``, ``order``, ``shares``, ``out``: C-contiguous float64, int64, int64,
    float64, float64 arrays; ``damping``, ``min_share``, ``min_help`` and the model's weights floats;
    ``join``, ``uniform`` bools; ``size`` ints): the kernel's entry point is kept there and
    called directly where the pieces are flat (``jit.entry``). ``scratch``: the time model's
    per-object arrays, ``scratch_for(len(tris))``, kept by the caller (None: made here)."""
    k = len(tiles)
    flat = isinstance(pieces, dict)
    if flat:  # the last frame's flat pieces, as this function returned them
        allp, owner, mass = pieces["pieces"], pieces["owner"], pieces["mass"]
    else:
        allp = np.concatenate([np.asarray(p, dtype=np.int64).reshape(-1, 4) for p in pieces])  # ranks, not objects
        owner = np.repeat(np.arange(k), [len(p) for p in pieces])
        mass = np.zeros(0) if mass is None else np.ascontiguousarray(mass, dtype=np.float64)
    new = np.empty(k) if out is None else out
    # (4, N) float64 rects (the projector's own array, transposed back: no copy) and int64 weights
    args = (allp, owner, times, tiles, order, shares, new, damping, min_share, min_help, join,
            np.ascontiguousarray(rects.T, dtype=np.float64),
            np.ascontiguousarray(tris, dtype=np.int64), size[0], size[1], mass, pixel_weight, object_weight,
            cover_weight, uniform,
            *(scratch if scratch is not None else scratch_for(len(tris))))
    call = _cross
    if flat and bound is not None:  # the entry point, bound at the first flat call
        call = bound.get("cross")
        if call is None:
            call = bound["cross"] = entry(_cross, args)
    ints, both, weights = call(*args)
    # views of the packed arrays (their layout: pieces._cross), split with few Python steps:
    # with the caches cold after rendering, every step costs microseconds
    at = ints[:k + 1].tolist()
    q = at[k]
    prects = ints[6 * k + 1:6 * k + 1 + 4 * q].reshape(q, 4)
    cuts = list(zip(at[:-1], at[1:]))
    none, none_px = _no_splits(k)
    return new, (ints[k + 1:5 * k + 1].reshape(k, 4), ints[5 * k + 1:6 * k + 1], both[q:], none, none_px, None,
                 tuple([prects[a:b] for a, b in cuts]), tuple([both[a:b] for a, b in cuts]),
                 {"pieces": prects, "owner": ints[6 * k + 1 + 4 * q:], "mass": weights})


_NO_SPLITS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _no_splits(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Read-only (K-1,) zero splits and split pixels of a partition with no tree (one pair per K)."""
    if k not in _NO_SPLITS:
        pair = np.zeros(max(k - 1, 0)), np.zeros(max(k - 1, 0), dtype=np.int64)
        for a in pair:
            a.setflags(write=False)
        _NO_SPLITS[k] = pair
    return _NO_SPLITS[k]


def project_boxes(grouped, plain_boxes, half, view, proj, widen, far_tol, out, coverage=None, plain: int = -1) -> bool:
    """``bounds.BoxProjector``'s rects (4, N) into ``out`` and, when given, silhouette coverage;
    ``grouped``: ``project.spatial_groups`` of the boxes (culled a group at a time);
    ``plain_boxes``: (centres, half extents) in object order, used where the groups cull
    fewer than half the boxes (an eighth up to ``project.SCATTER_FREE`` boxes; ``plain`` -1;
    1: always, 0: never; the same rects). False
    (nothing written) when ``view`` or ``proj`` has an entry that is not finite."""
    order, center, half64, starts, gbox = grouped
    cov = _NO_COVERAGE if coverage is None else coverage
    return _project(center, half, half64, order, starts, gbox, plain_boxes[0], plain_boxes[1], plain, view, proj,
                    widen, far_tol, out, cov, coverage is not None)


_NO_COVERAGE = np.empty(0)


def seen_triangles(rects: np.ndarray, tris: np.ndarray) -> float:
    """The triangles of the objects in view: ``tris`` summed over the (N, 4) ``rects`` that
    are not NaN, in one compiled pass (the projector's rects give a contiguous first column)."""
    return float(_seen(np.ascontiguousarray(rects[:, 0]), np.asarray(tris)))


def warm() -> float:
    """Compile (or load from numba's cache) every signature a run uses (every registered
    strategy plans a few frames); seconds it took. tests/test_kernel.py checks that frames
    planned afterwards, with every strategy and decomposition, compile nothing."""
    if not available():
        return 0.0
    from multigpu.core.bounds import BoxProjector
    from multigpu.core.camera import look_at, perspective
    from multigpu.core.tree import gpu_tree

    t0 = time.perf_counter()
    rects = np.array([[0.1, 0.1, 0.6, 0.7], [0.5, 0.2, 0.9, 0.9], [np.nan] * 4])
    for tris in (np.array([3, 5, 7], dtype=np.int64), np.array([3.0, 5.0, 7.0])):
        strip_partition(rects, tris, gpu_tree(2, 2), (64, 64), 16)
    view, proj = look_at([0, -5, 1], [0, 0, 0], [0, 0, 1]), perspective(60, 1.0, 0.1, 100)
    box = BoxProjector(np.array([[-1.0, -1, -1], [0, -6, 0]]), np.array([[1.0, 1, 1], [1, -4, 2]]), compiled=True)
    box(view, proj)
    box(view, proj, np.empty(2))
    from multigpu.core.camera import Camera

    camera = Camera((0.0, -5.0, 1.0), (0.0, 0.0, 0.0))
    box.frame(camera, (64, 48))
    box.frame(camera, (64, 48), np.empty(2))
    from multigpu.strategies import REGISTRY

    tris, coverage, times = np.array([3, 5, 7], dtype=np.int64), np.array([0.5, 1.0, 1.0]), np.arange(1.0, 5.0)
    for cls in REGISTRY.values():  # every strategy's plans, the ones that learn from measured times too
        strategy = cls((2, 2), (64, 64), 16, compiled=True)
        for f in range(4):
            strategy.observe(f, strategy.plan(rects, tris, coverage), times + f)
    from multigpu.core.kernel.fit import fit_terms
    from multigpu.core.kernel.pixels import rank_pixels

    rank_pixels(np.zeros((4, 2), dtype=np.int32), np.ones((1, 2), dtype=np.bool_), np.array([[0, 0, 4, 4]]),
                np.ones((1, 2)), np.empty((1, 1)))

    fit_terms(np.array([[1.0, 2.0, 3.0], [2.0, 1.0, 4.0], [3.0, 3.0, 5.0], [4.0, 1.0, 7.0]]), 0.05, 0.5, np.empty(10))
    from multigpu.core.kernel.draws import _commands

    _commands(np.ones(2, dtype=np.bool_), np.arange(2, dtype=np.int64), np.array([0, 3, 6], dtype=np.int64))
    from multigpu.core.kernel.parts import _parts

    _parts(np.array([[0, 0, 4, 4]]), np.array([1]), np.array([[0, 0, 2, 2]]))
    return time.perf_counter() - t0


__all__ = ["available", "use", "cross_partition", "scratch_for", "warm", "strip_partition", "tree_arrays", "tree_nodes",
           "project_boxes", "seen_triangles"]
