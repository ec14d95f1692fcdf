"""The compiled balancer (core/balance_kernel.py) against the numpy reference (core/balance.py): the same
regions, loads, T' masks, splits and spans, bit for bit, on random and extreme inputs."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core import balance_kernel as kernel
from multigpu.core import jit
from multigpu.core.balance import partition
from multigpu.strategies import REGISTRY

pytestmark = pytest.mark.skipif(not jit.available(), reason="numba is not installed (pip install numba)")
FIELDS = ("regions", "loads", "visible", "splits", "split_pixels", "spans")


def same(rects, tris, grid, size, strips):
    ref = partition(rects, tris, grid, size, strips, compiled=False)
    got = partition(rects, tris, grid, size, strips, compiled=True)
    for name in FIELDS:
        a, b = getattr(got, name), getattr(ref, name)
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert np.array_equal(a, b), f"{name} differs: {a} vs {b}"
    return got


coord = st.one_of(st.floats(-2.0, 3.0, allow_nan=False), st.sampled_from([0.0, 1.0, -0.0, 1e-300, 1 - 1e-16,
                                                                          -1e300, 1e300, np.nan]))


@settings(max_examples=300, deadline=None)
@given(data=st.data(), rows=st.integers(1, 4), cols=st.integers(1, 4), n=st.integers(0, 60),
       integer=st.booleans(), strips=st.sampled_from([2, 3, 7, 64, 2048, 100_000]))
def test_compiled_equals_the_reference(data, rows, cols, n, integer, strips):
    W = data.draw(st.integers(cols, 700))
    H = data.draw(st.integers(rows, 700))
    pts = np.array(data.draw(st.lists(st.tuples(coord, coord, coord, coord), min_size=n, max_size=n)),
                   dtype=np.float64).reshape(-1, 4)
    with np.errstate(invalid="ignore"):
        lo, hi = np.minimum(pts[:, :2], pts[:, 2:]), np.maximum(pts[:, :2], pts[:, 2:])
    rects = np.concatenate([lo, hi], axis=1)
    rects[np.isnan(rects).any(axis=1)] = np.nan
    if integer:
        tris = np.array(data.draw(st.lists(st.integers(0, 10**6), min_size=n, max_size=n)), dtype=np.int64)
    else:
        tris = np.array(data.draw(st.lists(st.floats(0, 1e6), min_size=n, max_size=n)), dtype=np.float64)
    same(rects, tris, (rows, cols), (W, H), strips)


def test_extremes_equal_the_reference():
    rng = np.random.default_rng(7)
    n = 5000
    lo = rng.uniform(-0.2, 1.0, (n, 2))
    rects = np.concatenate([lo, lo + rng.exponential(0.05, (n, 2))], axis=1)
    for tris in (rng.integers(0, 2**40, n),  # sums past 2**53: the reference splits weights into halves
                 np.zeros(n, dtype=np.int64),  # nothing to balance: area-proportional splits
                 np.full(n, 1e-300), rng.pareto(1.2, n) * 1e6):
        for grid, size in (((4, 4), (4096, 2048)), ((1, 16), (16, 5)), ((3, 1), (7, 3)), ((2, 2), (32768, 32768))):
            same(rects, tris, grid, size, 2048)
    same(np.full((10, 4), np.nan), np.ones(10, dtype=np.int64), (2, 2), (64, 64), 16)  # nothing visible
    same(np.zeros((0, 4)), np.zeros(0, dtype=np.int64), (2, 3), (64, 64), 16)


# -- the compiled box projection (core/bounds_kernel.py) against bounds.py's numpy reference

def same_rects(bmin, bmax, view, proj, dtype):
    from multigpu.core.bounds import BoxProjector

    n = len(bmin)
    ref_cov, got_cov = np.full(n, -1.0), np.full(n, -2.0)
    ref = BoxProjector(bmin, bmax, dtype, compiled=False)(view, proj, ref_cov)
    got = BoxProjector(bmin, bmax, dtype, compiled=True)(view, proj, got_cov)
    assert np.array_equal(ref, got, equal_nan=True), np.flatnonzero(~np.isclose(ref, got, equal_nan=True).all(1))
    assert np.array_equal(ref_cov, got_cov, equal_nan=True)
    plain = BoxProjector(bmin, bmax, dtype, compiled=True)(view, proj)  # without coverage: the same rects
    assert np.array_equal(plain, got, equal_nan=True)
    for order in (0, 1):  # the boxes always by groups (0), always in their own order (1): the same rects
        cov = np.full(n, -3.0)
        forced = BoxProjector(bmin, bmax, dtype, compiled=True, plain=order)(view, proj, cov)
        assert np.array_equal(forced, ref, equal_nan=True) and np.array_equal(cov, ref_cov), order


scale = st.sampled_from([1e-3, 1.0, 50.0, 1e4, 1e8])


@settings(max_examples=200, deadline=None)
@given(data=st.data(), n=st.integers(0, 40), s=scale, dtype=st.sampled_from([np.float32, np.float64]),
       near=st.sampled_from([1e-6, 0.1, 1.0]), fov=st.floats(5.0, 150.0))
def test_compiled_projection_equals_the_reference(data, n, s, dtype, near, fov):
    from multigpu.core.camera import look_at, perspective

    f = st.floats(-3.0, 3.0, allow_nan=False)
    c = np.array(data.draw(st.lists(st.tuples(f, f, f), min_size=n, max_size=n)), dtype=np.float64).reshape(-1, 3)
    h = np.abs(np.array(data.draw(st.lists(st.tuples(f, f, f), min_size=n, max_size=n)),
                        dtype=np.float64).reshape(-1, 3)) * data.draw(st.sampled_from([0.0, 1e-9, 0.1, 1.0]))
    eye = np.array(data.draw(st.tuples(f, f, f))) * s + data.draw(st.sampled_from([0.0, 1e7]))
    look = eye + np.array(data.draw(st.tuples(f, f, f))) + [1e-3, 0, 0]
    view = look_at(eye, look, [0, 0, 1] if abs(look[2] - eye[2]) < 1 else [0, 1, 0])
    proj = perspective(fov, data.draw(st.sampled_from([0.25, 1.0, 3.0])), near * s, 1e3 * s)
    centre = eye + c * s
    same_rects(centre - h * s, centre + h * s, view, proj, dtype)


@settings(max_examples=150, deadline=None)
@given(data=st.data(), n=st.integers(0, 30), s=scale, shift=st.sampled_from([0.0, 1e7]),
       along_up=st.booleans(), fov=st.floats(5.0, 150.0), size=st.tuples(st.integers(1, 4000), st.integers(1, 4000)))
def test_compiled_frame_forms_the_reference_matrices_and_rects(data, n, s, shift, along_up, fov, size):
    """``BoxProjector.frame`` compiled (the camera's matrices formed inside the projection
    kernel) against the reference's ``frame_matrices`` and numpy projection: view, projection,
    light, rects and coverage bit for bit; integer coordinates, a camera looking along its up
    vector, and a position on its target (refused alike)."""
    from multigpu.core.bounds import BoxProjector
    from multigpu.core.camera import Camera, look_at, perspective

    f = st.floats(-3.0, 3.0, allow_nan=False)
    c = np.array(data.draw(st.lists(st.tuples(f, f, f), min_size=n, max_size=n)), dtype=np.float64).reshape(-1, 3)
    h = np.abs(np.array(data.draw(st.lists(st.tuples(f, f, f), min_size=n, max_size=n)), dtype=np.float64)
               ).reshape(-1, 3)
    eye = tuple(float(v) * s + shift for v in data.draw(st.tuples(f, f, f)))
    up = data.draw(st.sampled_from([(0, 0, 1), (0, 1, 0), (0.3, -2.0, 0.7)]))
    step = tuple(2.0 * s * u for u in up) if along_up else \
        tuple(float(v) * s + 1e-3 * s for v in data.draw(st.tuples(f, f, f)))
    camera = Camera(eye, tuple(e + d for e, d in zip(eye, step)), up, fov, 0.1 * s, 1e3 * s)
    boxes = (np.array(eye) + c * s - h * s, np.array(eye) + c * s + h * s)
    ref_cov, got_cov = np.full(n, -1.0), np.full(n, -2.0)
    ref = BoxProjector(*boxes, compiled=False).frame(camera, size, ref_cov)
    got = BoxProjector(*boxes, compiled=True).frame(camera, size, got_cov)
    for a, b in zip(ref, got):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
    assert np.array_equal(ref_cov, got_cov, equal_nan=True)
    assert np.array_equal(ref[0], look_at(camera.position, camera.target, camera.up))
    assert np.array_equal(ref[1], perspective(fov, size[0] / size[1], camera.near, camera.far))
    on_target = Camera(eye, eye, (0, 0, 1), fov, 0.1 * s, 1e3 * s)
    for compiled in (False, True):
        with pytest.raises(ValueError, match="camera position and target coincide"):
            BoxProjector(*boxes, compiled=compiled).frame(on_target, size)


@settings(max_examples=60, deadline=None)
@given(data=st.data(), n=st.integers(0, 20), frames=st.integers(1, 40), s=scale, size=st.tuples(st.integers(1, 900),
                                                                                                 st.integers(1, 900)))
def test_compiled_frames_seen_equal_the_reference_frame_by_frame(data, n, frames, s, size):
    """``BoxProjector.frames_seen`` compiled (every camera in one call: a generated path's check)
    against the reference's ``frame`` a camera at a time: the same frames seeing some box, none,
    or refused (a position on its target, a camera far out of range)."""
    from multigpu.core.bounds import BoxProjector

    f = st.floats(-3.0, 3.0, allow_nan=False)
    c = np.array(data.draw(st.lists(st.tuples(f, f, f), min_size=n, max_size=n)), dtype=np.float64).reshape(-1, 3)
    h = np.abs(np.array(data.draw(st.lists(st.tuples(f, f, f), min_size=n, max_size=n)), dtype=np.float64)
               ).reshape(-1, 3)
    pos = np.array(data.draw(st.lists(st.tuples(f, f, f), min_size=frames, max_size=frames))) * 2 * s
    tgt = pos + np.array(data.draw(st.lists(st.tuples(f, f, f), min_size=frames, max_size=frames))) * s
    tgt[data.draw(st.integers(0, frames - 1))] = pos[0] if frames == 1 else tgt[0]  # (sometimes on its position)
    tgt[0] = pos[0] if data.draw(st.booleans()) else tgt[0]
    up = np.tile(data.draw(st.sampled_from([(0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (0.3, -2.0, 0.7)])), (frames, 1))
    fov = np.array(data.draw(st.lists(st.floats(5.0, 150.0), min_size=frames, max_size=frames)))
    near, far = np.full(frames, 0.1 * s), np.full(frames, 1e3 * s)
    boxes = (c * s - h * s, c * s + h * s)
    ref = BoxProjector(*boxes, compiled=False).frames_seen(pos, tgt, up, fov, near, far, size)
    got = BoxProjector(*boxes, compiled=True).frames_seen(pos, tgt, up, fov, near, far, size)
    assert ref.dtype == got.dtype == np.int8 and np.array_equal(ref, got), (ref, got)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 30))
def test_compiled_clip_matrix_and_rects_under_dense_matrices(seed, n):
    """A camera's matrices are sparse (two terms per entry of proj @ view: any order adds them
    alike); under dense ones the kernel's proj @ view must still add its four products in the
    reference's order, so the rects stay equal bit for bit."""
    from multigpu.core.bounds_kernel import _clip_matrix
    from multigpu.core.box_tables import clip_matrix
    from multigpu.core.camera import look_at, perspective

    rng = np.random.default_rng(seed)
    mix = np.eye(4) + rng.uniform(-0.3, 0.3, (4, 4))  # a dense clip-space map
    view = look_at([0, -6, 1], [0, 0, 0], [0, 0, 1]) + rng.uniform(-1e-3, 1e-3, (4, 4))
    proj = mix @ perspective(60, 1.0, 0.1, 100)
    np.testing.assert_array_equal(_clip_matrix(proj, view), clip_matrix(proj, view))
    np.testing.assert_allclose(clip_matrix(proj, view), proj @ view, rtol=1e-12, atol=1e-15)
    c = rng.uniform(-3, 3, (n, 3))
    h = rng.uniform(0, 1, (n, 3))
    same_rects(c - h, c + h, view, proj, np.float64)


def test_compiled_projection_on_a_walkthrough():
    from multigpu.core.camera import frame_matrices
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import generate

    scene, _ = load_scene(SceneSpec(triangles=20_000))
    path = generate("walkthrough", scene, 24)
    for f in range(len(path)):
        view, proj, _ = frame_matrices(path.camera(f), (512, 512))
        same_rects(scene.bmin, scene.bmax, view, proj, np.float32)


def test_compiled_projection_culls_groups_exactly_at_the_planes():
    """Clusters of boxes sitting on the frustum planes (inside, outside and straddling them by
    a few ulps to a tenth of their size), at every scale: the kernel culls whole groups of
    neighbours first, which must never change a rect."""
    from multigpu.core.bounds import _check
    from multigpu.core.camera import look_at, perspective

    rng = np.random.default_rng(11)
    for s in (1e-3, 1.0, 1e4, 1e8):
        for shift in (0.0, 1e7):
            eye = np.array([shift, -shift, 0.5 * shift])
            view = look_at(eye, eye + [1.0, 0.3, -0.2], [0, 0, 1])
            proj = perspective(60.0, 1.5, 0.1 * s, 100.0 * s)
            M = _check(view, proj)
            centres = []
            for plane in (M[3] + M[0], M[3] - M[0], M[3] + M[1], M[3] - M[1], M[3] + M[2]):
                normal = plane[:3] / np.linalg.norm(plane[:3])
                p0 = eye + rng.normal(size=(40, 3)) * 20 * s
                on = p0 - ((p0 @ plane[:3] + plane[3]) / (plane[:3] @ plane[:3]))[:, None] * plane[:3]
                for jitter in (0.0, 1e-12, 1e-6, 1e-1):  # clusters of 16 around points on the plane
                    side = rng.choice([-1.0, 1.0], (40, 1)) * jitter * s
                    centres.append(np.repeat(on + side * normal, 16, axis=0) + rng.normal(size=(640, 3)) * jitter * s)
            c = np.concatenate(centres)
            h = np.abs(rng.normal(size=c.shape)) * s * rng.choice([0.0, 1e-9, 1e-3, 0.05], (len(c), 1))
            same_rects(c - h, c + h, view, proj, np.float32)


# -- every strategy (cross-segment: strategies/cross_kernel.py; time, none: fixed cuts) compiled and not

def same_partition(a, b):
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        if x is None or y is None:  # spans: None where a strategy keeps none (cross), in both
            assert x is None and y is None, name
            continue
        assert x.dtype == y.dtype and np.array_equal(x, y), name
    assert (a.pieces is None) == (b.pieces is None)
    if a.pieces is not None:
        for pa, pb, ma, mb in zip(a.pieces, b.pieces, a.piece_visible, b.piece_visible):
            assert np.array_equal(np.asarray(pa).reshape(-1, 4), np.asarray(pb).reshape(-1, 4))
            assert ma.shape == mb.shape and np.array_equal(ma, mb)


@pytest.mark.parametrize("name", list(REGISTRY))
@settings(max_examples=60, deadline=None)
@given(data=st.data(), rows=st.integers(1, 4), cols=st.integers(1, 4), n=st.integers(0, 50), frames=st.integers(2, 6))
def test_every_strategy_compiled_equals_the_reference(name, data, rows, cols, n, frames):
    """Several frames, each observing random measured times: the same partitions (and, for
    cross, the same segment shares) with the kernels and with the numpy references."""
    tw, th = data.draw(st.integers(1, 80)), data.draw(st.integers(1, 80))
    size = (cols * tw, rows * th)
    k = rows * cols
    options = {}
    if name == "cross":  # slivers of help kept (0), dropped (the default), a whole unit or more needed
        options = {"min_help": data.draw(st.sampled_from([0.0, 0.1, 0.5, 1.0])),
                   "layout": data.draw(st.sampled_from(["joined", "equalizer"])),
                   "model": data.draw(st.sampled_from(["weighted", "uniform"])),
                   "pixel_weight": data.draw(st.sampled_from([0.0, 0.5, 3.0])),
                   "object_weight": data.draw(st.sampled_from([0.0, 1.0, 2.5])),
                   "cover_weight": data.draw(st.sampled_from([0.0, 1.0, 2.5]))}
    ref = REGISTRY[name]((rows, cols), size, data.draw(st.sampled_from([2, 7, 2048])), compiled=False, **options)
    got = REGISTRY[name](ref.grid, size, ref.strips, compiled=True, **options)
    for f in range(frames):
        pts = np.array(data.draw(st.lists(st.tuples(coord, coord, coord, coord), min_size=n, max_size=n)),
                       dtype=np.float64).reshape(-1, 4)
        with np.errstate(invalid="ignore"):
            rects = np.concatenate([np.minimum(pts[:, :2], pts[:, 2:]), np.maximum(pts[:, :2], pts[:, 2:])], axis=1)
        rects[np.isnan(rects).any(axis=1)] = np.nan
        tris = np.array(data.draw(st.lists(st.integers(0, 10**6), min_size=n, max_size=n)), dtype=np.int64)
        a, b = ref.plan(rects, tris), got.plan(rects, tris)
        same_partition(a, b)
        assert np.array_equal(getattr(ref, "shares", 0), getattr(got, "shares", 0))
        if name == "cross" and f:  # the pieces' weights the next frame learns from
            assert np.array_equal(a.features["mass"], b.features["mass"])
        if name in ("cost", "adaptive"):  # what they learn from: features, predictions, corrections
            for key, value in a.features.items():
                assert np.array_equal(value, b.features[key]), key
            assert np.array_equal(getattr(ref, "corr", None), getattr(got, "corr", None))
        times = np.array(data.draw(st.lists(st.sampled_from([0.0, 1e-9, 0.5, 1.0, 3.0, 40.0]), min_size=k,
                                            max_size=k)))
        ref.observe(f, a, times)
        got.observe(f, b, times)


@settings(max_examples=300, deadline=None)
@given(data=st.data(), rows=st.integers(1, 4), cols=st.integers(1, 4), strips=st.sampled_from([2, 3, 7, 64, 2048]),
       damping=st.sampled_from([0.0, 0.25, 0.5, 1.0]), damped=st.booleans())
def test_compiled_time_chooser_equals_the_reference(data, rows, cols, strips, damping, damped):
    """Time feedback's cuts (``splits.time_chooser``) in one compiled call equal the numpy
    chooser's at every node (``balance.node_cuts``): last regions anywhere (outside the display,
    empty, overlapping), times zero, tiny, huge or NaN, last cuts anywhere, damped or not."""
    from multigpu.core.balance import node_cuts
    from multigpu.core.splits import time_chooser
    from multigpu.core.tree import gpu_tree

    W, H = data.draw(st.integers(cols, 900)), data.draw(st.integers(rows, 900))
    k = rows * cols
    ends = st.integers(-50, 1000)
    regions = np.sort(np.array(data.draw(st.lists(st.tuples(ends, ends, ends, ends), min_size=k, max_size=k)),
                               dtype=np.int64).reshape(k, 2, 2), axis=1).reshape(k, 4)
    values = st.sampled_from([0.0, 1e-300, 1e-9, 0.5, 1.0, 3.0, 40.0, 1e300, np.inf, np.nan])
    times = np.array(data.draw(st.lists(values, min_size=k, max_size=k)))
    prev = np.array(data.draw(st.lists(st.integers(-10, 1000), min_size=k - 1, max_size=k - 1)), dtype=np.int64)
    tree = gpu_tree(rows, cols)
    choose = time_chooser(regions, times, prev if damped else None, damping)
    with np.errstate(invalid="ignore", over="ignore"):
        ref = node_cuts(tree, (W, H), strips, choose)
    got = choose.cuts(kernel.tree_nodes(tree), (W, H), strips)
    assert got.dtype == ref.dtype and np.array_equal(got, ref), f"{got} vs {ref}"


@pytest.mark.parametrize("grid", [(2, 2), (1, 3)])
def test_compiled_cross_equals_the_reference_past_its_sample(grid):
    """Past ``SAMPLE`` objects on screen the time profiles weigh every k-th object for k: the
    kernel and the reference still plan the same pieces, weights and shares, frame after frame."""
    from multigpu.strategies.cross_kernel import SAMPLE

    rng = np.random.default_rng(7)
    n = 3 * SAMPLE + 5
    size = (grid[1] * 90, grid[0] * 70)
    ref = REGISTRY["cross"](grid, size, 2048, compiled=False)
    got = REGISTRY["cross"](grid, size, 2048, compiled=True)
    for f in range(4):
        lo = rng.random((n, 2)) * 1.2 - 0.1
        rects = np.concatenate([lo, lo + rng.random((n, 2)) * 0.2], axis=1)
        tris = rng.integers(0, 5000, n)
        a, b = ref.plan(rects, tris), got.plan(rects, tris)
        same_partition(a, b)
        assert np.array_equal(ref.shares, got.shares)
        if f:
            assert np.array_equal(a.features["mass"], b.features["mass"])
        times = rng.random(grid[0] * grid[1]) * 10
        ref.observe(f, a, times)
        got.observe(f, b, times)
    assert not np.allclose(got.shares, 1.0)  # the shares moved: the profiles were used


@settings(max_examples=100, deadline=None)
@given(data=st.data(), n=st.integers(1, 60))
def test_compiled_draw_commands_equal_the_reference(data, n):
    """The draw list: the same run-merged commands from any mask, zero-triangle objects included."""
    from types import SimpleNamespace

    from multigpu.core.drawlist import DrawList

    counts = np.array(data.draw(st.lists(st.sampled_from([0, 3, 6, 30]), min_size=n, max_size=n)), dtype=np.int64)
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    verts = max(int(counts.sum()), 1)
    centers = rng.random((n, 3))
    scene = SimpleNamespace(n_objects=n, index_count=counts, centers=centers, bmin=centers - rng.random((n, 1)),
                            bmax=centers + rng.random((n, 1)),
                            indices=rng.integers(0, verts, int(counts.sum())).astype(np.uint32),
                            base_vertex=np.zeros(n, dtype=np.int64),
                            first_index=np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64),
                            vertices=np.zeros((verts, 3), dtype=np.float32))
    draws = DrawList(scene)
    mask = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    for m in (mask, None, np.zeros(n, dtype=bool)):
        ref, got = draws.commands(m, compiled=False), draws.commands(m, compiled=True)
        assert ref.dtype == got.dtype and np.array_equal(ref, got)


@settings(max_examples=100, deadline=None)
@given(data=st.data(), n=st.integers(0, 60), integer=st.booleans())
def test_compiled_trial_load_equals_the_reference(data, n, integer):
    """``auto``'s trial load (the triangles of the objects in view, NaN rects unseen): the same
    value compiled as numpy's masked sum, integer or float weights, C or transposed rects."""
    from multigpu.strategies.auto import Auto

    x0 = np.array(data.draw(st.lists(coord, min_size=n, max_size=n)), dtype=np.float64)
    rects = np.stack([x0, x0, x0 + 0.1, x0 + 0.1], axis=1)
    values = st.integers(0, 10**9) if integer else st.floats(0, 1e6, allow_nan=False)
    tris = np.array(data.draw(st.lists(values, min_size=n, max_size=n)), dtype=np.int64 if integer else np.float64)
    ref = Auto((2, 2), (64, 64), compiled=False)._load(rects, tris)
    for r in (rects, np.ascontiguousarray(rects.T).T):
        got = Auto((2, 2), (64, 64), compiled=True)._load(r, tris)
        assert got == ref or (not integer and got == pytest.approx(ref, rel=1e-12)), (got, ref)


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 6), most=st.integers(0, 30), grid=st.booleans())
def test_compiled_transfers_equal_the_reference(seed, k, most, grid):
    """A frame's transfers: the same parts in the same (sender, receiver, index) order from any
    pieces (ranks with none, empty and overlapping rects) and tiles (a grid, or any rects)."""
    from unittest import mock

    from multigpu.core import work as work_module
    from multigpu.core.regions import tile_regions
    from multigpu.core.work import Work, transfers

    rng = np.random.default_rng(seed)

    def rects(m):
        lo = rng.integers(-20, 100, (m, 2))
        return np.concatenate([lo, lo + rng.integers(0, 60, (m, 2))], axis=1).astype(np.int64)

    tiles = tile_regions(1, k, 40, 50) if grid else rects(k)
    work = Work(tuple(rects(int(rng.integers(0, most + 1))) for _ in range(k)), (), np.zeros(k, dtype=np.int64))
    ref = transfers(work, tiles, compiled=False)  # the plain loop at any size
    with mock.patch.object(work_module, "SMALL", -1):  # the compiled pass at any size
        got = transfers(work, tiles, compiled=True)
    assert got == ref
    assert all(type(v) is int for p in got for v in (p.sender, p.receiver, p.index, *p.rect))


@settings(max_examples=200, deadline=None)
@given(data=st.data(), rows=st.integers(1, 4), cols=st.integers(1, 4), n=st.integers(0, 60),
       integer=st.booleans(), strips=st.sampled_from([2, 3, 7, 64, 2048]), scalar=st.booleans())
def test_compiled_fill_chooser_equals_the_reference(data, rows, cols, n, integer, strips, scalar):
    """The cost model's fill term (``partition(..., fill=)``): the same partition compiled and
    with ``splits.fill_prefix``, per-object or one scalar density, zeros included."""
    W = data.draw(st.integers(cols, 700))
    H = data.draw(st.integers(rows, 700))
    pts = np.array(data.draw(st.lists(st.tuples(coord, coord, coord, coord), min_size=n, max_size=n)),
                   dtype=np.float64).reshape(-1, 4)
    with np.errstate(invalid="ignore"):
        rects = np.concatenate([np.minimum(pts[:, :2], pts[:, 2:]), np.maximum(pts[:, :2], pts[:, 2:])], axis=1)
    rects[np.isnan(rects).any(axis=1)] = np.nan
    if integer:
        tris = np.array(data.draw(st.lists(st.integers(0, 10**6), min_size=n, max_size=n)), dtype=np.int64)
    else:
        tris = np.array(data.draw(st.lists(st.floats(0, 1e6), min_size=n, max_size=n)), dtype=np.float64)
    values = st.sampled_from([0.0, 1e-12, 0.25, 1.0, 3.0, 1e6])
    fill = data.draw(values) if scalar else np.array(data.draw(st.lists(values, min_size=n, max_size=n)))
    ref = partition(rects, tris, (rows, cols), (W, H), strips, fill=fill, compiled=False)
    got = partition(rects, tris, (rows, cols), (W, H), strips, fill=fill, compiled=True)
    for name in FIELDS:
        a, b = getattr(got, name), getattr(ref, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), f"{name} differs: {a} vs {b}"


def test_compiled_fill_chooser_on_wide_displays_and_weights_that_differ():
    """Displays wider than the fill line's table (cells of several pixels) and a fill that
    moves the cut: compiled and reference agree, and the fill changes the partition."""
    rng = np.random.default_rng(5)
    n = 3000
    lo = rng.uniform(-0.1, 1.0, (n, 2))
    rects = np.concatenate([lo, lo + rng.exponential(0.04, (n, 2))], axis=1)
    tris = rng.integers(1, 5000, n)
    fill = np.where(rects[:, 0] < 0.3, 50.0, 0.01)
    moved = False
    for grid, size in (((2, 2), (1024, 512)), ((1, 4), (200_000, 64)), ((4, 4), (70_000, 90_000))):
        for f in (0.5, fill):
            ref = partition(rects, tris, grid, size, 2048, fill=f, compiled=False)
            got = partition(rects, tris, grid, size, 2048, fill=f, compiled=True)
            for name in FIELDS:
                assert np.array_equal(getattr(got, name), getattr(ref, name)), (grid, name)
        plain = partition(rects, tris, grid, size, 2048, compiled=True)
        moved |= not np.array_equal(plain.regions, got.regions)  # by the per-object fill
    assert moved


@pytest.mark.parametrize("size", [(1024, 512), (200_000, 64), (70_000, 90_000)])
def test_compiled_fill_line_equals_fill_prefix(size):
    """The fill cost below every candidate cut of the root node, value for value, where the
    line is per pixel and where it is in cells of several pixels (displays past 2**16)."""
    from multigpu.core.balance import _task
    from multigpu.core.balance_kernel import _fill_line
    from multigpu.core.regions import pixel_spans
    from multigpu.core.splits import fill_prefix
    from multigpu.core.tree import gpu_tree

    rng = np.random.default_rng(9)
    n = 2000
    lo = rng.uniform(-0.1, 1.0, (n, 2))
    rects = np.concatenate([lo, lo + rng.exponential(0.03, (n, 2))], axis=1)
    density = rng.uniform(0.0, 3.0, n)
    tris = np.ones(n, dtype=np.int64)
    spans, on = pixel_spans(rects, size)
    spans = np.ascontiguousarray(spans.T)
    tree = gpu_tree(2, 2)
    reg = np.array([0, 0, *size], dtype=np.int64)
    task, _, _ = _task(0, tree.internal[0], reg, 2048, *size, np.flatnonzero(on), spans, tris)
    want, want_total = fill_prefix(task, spans, density)
    got, got_total = _fill_line(task.idx, spans, density, reg, task.axis, task.a, task.b, task.cuts)
    assert np.array_equal(got, want) and got_total == want_total


# -- the cost model's least-squares fit (cost_kernel.py) against its numpy predecessor

@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(4, 120), pixels=st.booleans(), has_tris=st.booleans(),
       noise=st.sampled_from([0.0, 1e-6, 0.01, 0.5]))
def test_compiled_fit_keeps_the_terms_and_coefficients_of_numpys(seed, rows, pixels, has_tris, noise):
    """Random samples (a pixel term or not, triangles or none, noise from none to large): the
    compiled fit and its uncompiled self agree bit for bit; against numpy's inverse-based fit
    the same terms are kept and the coefficients agree to rounding; a singular system (no
    triangles, no pixels) is solved by numpy's pseudo-inverse as before."""
    from multigpu.strategies.cost import CostModel

    rng = np.random.default_rng(seed)
    tri = rng.uniform(0, 1e5, rows) * has_tris
    px = rng.uniform(0, 3e5, rows) * (rng.random() < 0.8)
    y = 1e-4 * tri + (2e-6 * px if pixels else 0.0) + 0.5 + rng.normal(0, noise, rows) if noise else \
        1e-4 * tri + (2e-6 * px if pixels else 0.0) + 0.5
    data = np.column_stack([tri, px, y])
    fitted = []
    for how in ("compiled", "plain", "numpy"):
        m = CostModel((2, 2), (64, 64), 8, compiled=how == "compiled")
        m._fit_numpy(data) if how == "numpy" else m._fit(data)
        fitted.append(m)
    a, b, ref = fitted
    assert np.array_equal(a.coef, b.coef) and a.kept == b.kept and a.why == b.why
    assert a.kept == ref.kept
    np.testing.assert_allclose(a.coef, ref.coef, rtol=1e-6, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 80), k=st.integers(1, 6), weightings=st.sampled_from([0, 1, 2]))
def test_compiled_rank_pixels_equal_the_reference(seed, n, k, weightings):
    """The cost model's pixel feature: the same sums, bit for bit, with no coverage, one
    coverage and two stacked (adaptive's), objects off screen and ranks with nothing visible."""
    from multigpu.strategies.base import rank_pixels

    rng = np.random.default_rng(seed)
    lo = rng.uniform(-0.2, 1.0, (n, 2))
    rects = np.c_[lo, lo + rng.exponential(0.2, (n, 2))]
    rects[rng.random(n) < 0.1] = np.nan
    size = (int(rng.integers(1, 300)), int(rng.integers(1, 300)))
    visible = rng.random((k, n)) < 0.6
    edges = np.sort(rng.integers(0, size[0] + 1, (k, 2)), axis=1)
    regions = np.c_[edges[:, 0], np.zeros(k, np.int64), edges[:, 1], np.full(k, size[1])]
    cov = [None, rng.random(n), rng.random((2, n)) * 3][weightings]
    got = rank_pixels(rects, visible, regions, size, cov, compiled=True)
    ref = rank_pixels(rects, visible, regions, size, cov, compiled=False)
    assert got.shape == ref.shape and np.array_equal(got, ref)



#: run in a fresh interpreter: in the test process, earlier tests may have compiled a signature warm() misses
_AFTER_WARM = """
import importlib, json, pkgutil, sys
import numpy as np
from multigpu.config import WalkConfig
from multigpu import kernels
from multigpu.core.drawlist import DrawList
from multigpu.core.jit import numba
from multigpu.planner import Planner
from multigpu.decompositions import REGISTRY as DECOMPOSITIONS
from multigpu.scene.models import SceneSpec, load_scene
from multigpu.scene.paths import generate
from multigpu.strategies import REGISTRY

def dispatchers():
    found = {}
    for module_name in kernels.MODULES:
        module = importlib.import_module(module_name)
        for name, value in vars(module).items():
            if isinstance(value, numba.core.dispatcher.Dispatcher):
                found[f"{module_name}.{name}"] = value
    return found

kernels.warm()
before = {name: len(d.signatures) for name, d in dispatchers().items()}
scene, _ = load_scene(SceneSpec(scene=sys.argv[1], triangles=20_000))
path = generate("walkthrough", scene, 6)
draws = DrawList(scene)
times = np.random.default_rng(0).random((len(path), 4)) + 1.0
for decomposition in DECOMPOSITIONS:
    for balance in REGISTRY if decomposition == "screen" else ["strips"]:
        cfg = WalkConfig(grid=(2, 2), tile=(64, 64), balance=balance, decomposition=decomposition)
        for rank in (0, None):
            planner = Planner(cfg, scene, rank=rank)
            for f in range(len(path)):
                if f:
                    planner.observe(f - 1, times[f - 1])
                work, _ = planner.plan(f, path.camera(f))
                for mask in work.masks[0]:
                    draws.commands(mask)
print(json.dumps({name: [str(s) for s in d.signatures[before[name]:]] for name, d in dispatchers().items()
                  if len(d.signatures) != before[name]}))
"""


@pytest.mark.parametrize("scene_name", ["plant", "city"])
def test_frames_after_warm_compile_nothing(scene_name):
    """``kernels.warm()`` at setup covers every signature a run uses: in a fresh interpreter,
    frames planned afterwards with every strategy and decomposition, for one rank and for all,
    add none (a signature missed costs its compile, or its load from numba's cache, inside the
    first frame: 26-40 ms of CPU for ``none``'s read-only tile cuts before warm() planned it)."""
    import json
    import subprocess
    import sys

    got = subprocess.run([sys.executable, "-c", _AFTER_WARM, scene_name], capture_output=True, text=True,
                         timeout=600)
    assert got.returncode == 0, got.stderr[-2000:]
    assert json.loads(got.stdout.strip().splitlines()[-1]) == {}
