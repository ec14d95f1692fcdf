"""The hand-flown camera (core/navigate.py), in one process: moves scale with the scene and the
frame's duration, turning never reaches the poles, orbit keeps the centre in view, and every
camera it makes is valid at any scale."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core.camera import Camera, look_at
from multigpu.core.navigate import MAX_DT, MOVES, POLE, WALK, Input, Navigator


def nav(scale=1.0, offset=0.0):
    lo, hi = np.array([0.0, 0, 0]) * scale + offset, np.array([4.0, 2, 1]) * scale + offset
    start = Camera(tuple(np.array([-1.0, 1, 0.5]) * scale + offset), tuple(np.array([2.0, 1, 0.5]) * scale + offset),
                   (0, 0, 1), 60.0, 1e-4 * scale, 10.0 * scale)
    return Navigator(lo, hi, start), math.sqrt(21) * scale


def test_forward_moves_along_the_view_by_a_share_of_the_scene_per_second():
    for scale in (0.2 / math.sqrt(21), 2000.0 / math.sqrt(21)):  # a 0.2-unit dragon, a 2 km track
        n, diag = nav(scale)
        before = np.array(n.camera().position)
        cam = n.step(Input(moves=frozenset({"forward"})), 0.05)
        moved = np.array(cam.position) - before
        assert moved == pytest.approx([WALK * diag * 0.05, 0, 0], rel=1e-9, abs=1e-12 * diag)
        assert np.array(cam.target)[0] > cam.position[0]  # still looking along +x


def test_strafe_rise_and_the_frame_time_cap():
    n, diag = nav()
    p0 = np.array(n.camera().position)
    cam = n.step(Input(moves=frozenset({"right", "up"})), 10.0)  # a stalled frame moves as far as MAX_DT
    d = np.array(cam.position) - p0
    assert d == pytest.approx([0, -WALK * diag * MAX_DT, WALK * diag * MAX_DT])
    back = n.step(Input(moves=frozenset({"left", "down"})), 10.0)
    assert np.array(back.position) == pytest.approx(p0)
    fast = nav()[0].step(Input(moves=frozenset({"forward"}), fast=True), 0.01)
    slow = nav()[0].step(Input(moves=frozenset({"forward"}), speed_steps=-2), 0.01)
    assert fast.position[0] - p0[0] == pytest.approx(4 * WALK * diag * 0.01)
    assert slow.position[0] - p0[0] == pytest.approx(WALK * diag * 0.01 / 1.25 ** 2)


def test_dragging_turns_and_never_reaches_the_poles():
    n, _ = nav()
    cam = n.step(Input(drag=(360.0, 0.0)), 0.0)  # 90 degrees to the right: looking along -y
    f = np.array(cam.target) - np.array(cam.position)
    assert f / np.linalg.norm(f) == pytest.approx([0, -1, 0], abs=1e-9)
    for _ in range(5):  # keep pushing the mouse up: the view stops POLE degrees from straight up
        cam = n.step(Input(drag=(0.0, -1000.0)), 0.0)
    f = np.array(cam.target) - np.array(cam.position)
    angle = math.degrees(math.acos(f @ [0, 0, 1] / np.linalg.norm(f)))
    assert angle == pytest.approx(POLE, abs=1e-6)
    look_at(cam.position, cam.target, cam.up)  # a valid view


def test_orbit_looks_at_the_centre_and_keeps_its_distance_while_turning():
    n, diag = nav()
    cam = n.step(Input(orbit=True), 0.0)
    centre = np.array([2.0, 1, 0.5])
    dist = np.linalg.norm(np.array(cam.position) - centre)
    for inp in (Input(moves=frozenset({"right"})), Input(drag=(40.0, 25.0)), Input(moves=frozenset({"up"}))):
        cam = n.step(inp, 0.05)
        assert np.linalg.norm(np.array(cam.position) - centre) == pytest.approx(dist)
        f = np.array(cam.target) - np.array(cam.position)
        assert f / np.linalg.norm(f) == pytest.approx((centre - cam.position) / dist)
    closer = n.step(Input(moves=frozenset({"forward"})), 0.05)
    assert np.linalg.norm(np.array(closer.position) - centre) < dist
    walk = n.step(Input(orbit=True, moves=frozenset({"forward"})), 0.05)  # back to walking: flies on
    assert not n.orbiting and walk.position != closer.position


def test_reset_returns_to_the_start():
    n, _ = nav()
    start = n.camera()
    n.step(Input(moves=frozenset({"forward", "left"}), drag=(30.0, 10.0)), 0.1)
    assert n.step(Input(reset=True), 0.0).position == start.position


@settings(max_examples=150, deadline=None)
@given(scale=st.sampled_from([1e-6, 1e-3, 1.0, 1e3, 1e6]), offset=st.sampled_from([0.0, -3e3, 1e7]),
       steps=st.lists(st.tuples(st.sets(st.sampled_from(MOVES)), st.floats(-5e3, 5e3), st.floats(-5e3, 5e3),
                                st.booleans(), st.booleans(), st.integers(-3, 3), st.floats(0, 1.0)),
                      min_size=1, max_size=12))
def test_every_camera_is_valid_at_any_scale(scale, offset, steps):
    n, diag = nav(scale, offset)
    for moves, dx, dy, fast, orbit, speed, dt in steps:
        cam = n.step(Input(frozenset(moves), (dx, dy), fast, speed, orbit), dt)
        p, t = np.array(cam.position), np.array(cam.target)
        assert np.isfinite(p).all() and np.isfinite(t).all()
        assert np.linalg.norm(t - p) > 0 and 0 < cam.near < cam.far
        assert np.linalg.norm(p - n.centre) <= 100.0 * diag * (1 + 1e-9) + 1e-9
        v = look_at(cam.position, cam.target, cam.up)
        assert np.isfinite(v).all()
