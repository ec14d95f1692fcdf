"""Object bounds to normalized screen rects: exactness, conservativeness, near-plane cases."""

import numpy as np
import pytest

from multigpu.core.bounds import BoxProjector, project_boxes
from multigpu.core.camera import look_at, perspective
from multigpu.core.spheres import SphereProjector, project_spheres

V = look_at([0, -10, 2], [0, 0, 0], [0, 0, 1])
P = perspective(60, 1.5, 0.1, 100)


def project_points(pts, view=V, proj=P):
    h = np.c_[pts, np.ones(len(pts))] @ (proj @ view).T
    return h[:, :2] / h[:, 3:4] * 0.5 + 0.5, h[:, 3]


def random_boxes(n, seed=0, spread=4.0):
    rng = np.random.default_rng(seed)
    c = rng.normal(0, spread, (n, 3))
    h = rng.exponential(0.5, (n, 3))
    return c - h, c + h


def dense_samples(bmin, bmax, k=6):
    t = np.linspace(0, 1, k)
    g = np.stack(np.meshgrid(t, t, t), -1).reshape(-1, 3)
    return bmin + g * (bmax - bmin)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_boxes_in_front_contain_samples_and_are_tight(dtype):
    bmin, bmax = random_boxes(300)
    rects = project_boxes(bmin, bmax, V, P, dtype=dtype)
    checked = 0
    for i in range(len(bmin)):
        pts = dense_samples(bmin[i], bmax[i])
        xy, w = project_points(pts)
        if (w <= 0.1).any():
            continue  # near-plane cases are tested separately
        inside = ((xy >= 0) & (xy <= 1)).all(1)
        if not inside.any():
            continue
        checked += 1
        r = rects[i]
        assert not np.isnan(r).any()
        q = xy[inside]
        assert (q[:, 0] >= r[0] - 1e-9).all() and (q[:, 0] <= r[2] + 1e-9).all()
        assert (q[:, 1] >= r[1] - 1e-9).all() and (q[:, 1] <= r[3] + 1e-9).all()
        # tight: the corners themselves reach the rect (when not clipped by the screen)
        cxy = np.clip(project_points(dense_samples(bmin[i], bmax[i], 2))[0], 0, 1)
        assert np.allclose([cxy[:, 0].min(), cxy[:, 1].min(), cxy[:, 0].max(), cxy[:, 1].max()], r, atol=1e-5)
    assert checked > 50


def test_outside_frustum_is_nan_and_never_inverted():
    bmin, bmax = random_boxes(2000, spread=30)
    rects = project_boxes(bmin, bmax, V, P)
    ok = ~np.isnan(rects[:, 0])
    assert ok.any() and (~ok).any()
    assert (rects[ok, 0] <= rects[ok, 2]).all() and (rects[ok, 1] <= rects[ok, 3]).all()
    assert ((rects[ok] >= 0) & (rects[ok] <= 1)).all()
    # a box wholly behind the eye
    r = project_boxes(np.array([[-1, -20, -1]]), np.array([[1, -15, 1]]), V, P)
    assert np.isnan(r).all()


def test_box_crossing_near_plane_is_conservative():
    # the eye sits inside this box: it covers the whole screen
    r = project_boxes(np.array([[-1, -11, 1]]), np.array([[1, -9, 3]]), V, P)[0]
    assert np.allclose(r, [0, 0, 1, 1])
    # a long box from behind the eye to far in front, off to the right: clipped, not inverted
    r = project_boxes(np.array([[1, -20, 1.5]]), np.array([[1.5, 20, 2.5]]), V, P)[0]
    assert r[0] <= r[2] and r[1] <= r[3] and r[2] == 1.0
    pts = dense_samples(np.array([1, -20, 1.5]), np.array([1.5, 20, 2.5]), 40)
    xy, w = project_points(pts)
    front = w > 0.1
    q = np.clip(xy[front], 0, 1)
    assert (q[:, 0] >= r[0] - 1e-9).all() and (q[:, 1] >= r[1] - 1e-9).all() and (q[:, 1] <= r[3] + 1e-9).all()


def test_spheres_contain_their_samples():
    rng = np.random.default_rng(2)
    c = rng.normal(0, 3, (300, 3))
    rad = rng.exponential(0.5, 300)
    rects = project_spheres(c, rad, V, P)
    u = rng.normal(size=(400, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    for i in range(300):
        xy, w = project_points(c[i] + rad[i] * u)
        if (w <= 0.1).any():
            continue
        inside = ((xy >= 0) & (xy <= 1)).all(1)
        if inside.any():
            r = rects[i]
            q = xy[inside]
            assert (q[:, 0] >= r[0] - 1e-9).all() and (q[:, 0] <= r[2] + 1e-9).all()
            assert (q[:, 1] >= r[1] - 1e-9).all() and (q[:, 1] <= r[3] + 1e-9).all()


def test_sphere_rect_within_its_box_rect():
    rng = np.random.default_rng(3)
    c = rng.normal(0, 2, (500, 3))
    rad = rng.uniform(0.05, 0.5, 500)
    s = project_spheres(c, rad, V, P)
    b = project_boxes(c - rad[:, None], c + rad[:, None], V, P, dtype=np.float64)
    ok = ~np.isnan(s[:, 0])
    assert (~np.isnan(b[ok, 0])).all()
    assert (s[ok, :2] >= b[ok, :2] - 1e-9).all() and (s[ok, 2:] <= b[ok, 2:] + 1e-9).all()


@pytest.mark.parametrize("offset", [1e6, 1e8])
def test_far_from_origin_keeps_precision(offset):
    bmin, bmax = random_boxes(200)
    o = np.array([offset, offset, 0.0])
    eye, tgt = np.array([0, -10, 2]) + o, o
    r0 = project_boxes(bmin, bmax, V, P, dtype=np.float64)
    r1 = project_boxes(bmin + o, bmax + o, look_at(eye, tgt, [0, 0, 1]), P, dtype=np.float64)
    both = ~np.isnan(r0[:, 0])
    assert (np.isnan(r1[:, 0]) == ~both).all()
    assert np.allclose(r0[both], r1[both], atol=1e-6)


def test_bad_matrices():
    with pytest.raises(ValueError):
        project_boxes(np.zeros((1, 3)), np.ones((1, 3)), np.eye(3), P)


def test_prepared_projectors_match_and_are_reusable():
    bmin, bmax = random_boxes(500, seed=3)
    boxes = BoxProjector(bmin, bmax, chunk=64)  # several blocks
    c, r = (bmin + bmax) / 2, np.linalg.norm(bmax - bmin, axis=1) / 2
    spheres = SphereProjector(c, r, chunk=64)
    for eye in ([0, -10, 2], [3, -6, 1], [0, 0.5, 0.2]):  # the last one is inside the cloud
        view = look_at(eye, [0, 0, 0], [0, 0, 1])
        np.testing.assert_array_equal(boxes(view, P), project_boxes(bmin, bmax, view, P, chunk=1 << 20))
        np.testing.assert_array_equal(spheres(view, P), project_spheres(c, r, view, P, chunk=1 << 20))


def test_projector_shape_errors():
    with pytest.raises(ValueError, match="bmin and bmax"):
        BoxProjector(np.zeros((2, 3)), np.ones((3, 3)))
    with pytest.raises(ValueError, match="centers"):
        SphereProjector(np.zeros((2, 3)), np.ones(3))


@pytest.mark.parametrize("env,want", [({}, "True True"), ({"MULTIGPU_MALLOC": "default"}, "False False")])
def test_keep_heap_applies_once_and_honours_the_opt_out(env, want):
    """In a fresh process (the setting is process-wide): glibc takes it, the opt-out skips it."""
    import os
    import subprocess
    import sys

    code = "from multigpu.core.memory import keep_heap; print(keep_heap(), keep_heap())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, **env}).stdout.strip()
    assert out == want


def test_silhouette_coverage_fraction():
    view = look_at([0, 0, 50], [0, 0, 0], [0, 1, 0])
    proj = perspective(30, 1, 0.1, 100)
    bp = BoxProjector(np.array([[-1, -1, -1.0], [-1, -1, -1]]), np.array([[1, 1, 1.0], [1, 1, 1]]))
    cov = np.zeros(2)
    bp(view, proj, cov)
    assert cov == pytest.approx([1.0, 1.0], abs=1e-3)  # face-on: the silhouette is the rect
    # seen along the diagonal from far away: a regular hexagon, 3/4 of its bounding rect
    view = look_at([300, 300, 300], [0, 0, 0], [0, 0, 1])
    bp(view, perspective(2, 1, 1, 1000), cov)
    assert cov == pytest.approx([0.75, 0.75], abs=0.02)
    bmin, bmax = random_boxes(200, seed=7)
    cov = np.full(200, -1.0)
    BoxProjector(bmin, bmax)(V, P, cov)
    assert ((cov > 0) & (cov <= 1)).all()


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("which", ["view", "proj"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_matrices_that_are_not_finite_are_refused_by_both_paths(compiled, which, bad):

    bmin, bmax = random_boxes(20)
    box = BoxProjector(bmin, bmax, compiled=compiled)
    view, proj = V.copy(), P.copy()
    (view if which == "view" else proj)[3, 1] = bad  # an entry the other matrix meets with a zero
    with pytest.raises(ValueError, match="must be finite"):
        box(view, proj)
    with pytest.raises(ValueError, match="4x4"):
        box(V[:3], P)
    assert np.array_equal(box(V, P), BoxProjector(bmin, bmax, compiled=not compiled)(V, P), equal_nan=True)
