"""Frames in flight (core/inflight.py, gpu/render.py's submit): every frame through its three
stages once, in order, with the lags ``--latency`` gives; a stop ends after the last frame
submitted; pieces drawn ahead are the pixels ``render`` gives."""

import numpy as np
import pytest

from multigpu.core.inflight import MOST, held_back_reach, read_lag, slots, step


def run(n, latency, stop_at=None):
    """The stage sequence of a loop of ``n`` frames (None: until stopped at step ``stop_at``)."""
    last = None if n is None else n - 1
    seen = {"submit": [], "send": [], "deliver": []}
    at = {}
    for k in range(1000):
        got = step(k, last, latency)
        if got is None:
            return seen, at, k
        for name, f in zip(seen, got):
            if f is not None:
                seen[name].append(f)
                at[(name, f)] = k
        if stop_at is not None and k == stop_at:
            last = k if last is None else min(last, k)
    raise AssertionError("the loop never ended")


@pytest.mark.parametrize("latency", range(MOST + 1))
@pytest.mark.parametrize("n", [1, 2, 5, 17])
def test_every_frame_passes_each_stage_once_in_order_with_its_lags(n, latency):
    seen, at, steps = run(n, latency)
    for name in seen:
        assert seen[name] == list(range(n))
    for f in range(n):
        assert at[("send", f)] - at[("submit", f)] == read_lag(latency)
        assert at[("deliver", f)] - at[("submit", f)] == latency
    assert steps == n + latency  # the last frame shown N steps after its submit


@pytest.mark.parametrize("latency", range(MOST + 1))
def test_a_stop_shows_every_frame_submitted_and_no_more(latency):
    seen, _, _ = run(None, latency, stop_at=6)
    assert seen["submit"] == seen["send"] == seen["deliver"] == list(range(7))


def furthest_sent_while_held(latency: int, f: int) -> int:
    """Walk the loop's schedule (``step``) on a fast rank while a peer is held reading frame f's
    parts (in ``deliver``, after its barrier, before its row is posted): the last frame the fast
    rank sends, and so writes to its shared slice, before one of the loop's waits stops it.
    The waits, as ``frames.deliver`` makes them: the row of frame d - 1 lands first (headless
    frames in flight; in the strict order a row lands as it is posted), then the exchange's
    barrier of frame d (every rank has sent d)."""
    held_at = f + latency  # the step of the peer's deliver of f: its submit and send of that step are done
    peer_sent = {g for k in range(held_at + 1) for g in [step(k, None, latency)[1]] if g is not None}
    peer_rows = set(range(f))  # rows posted by the held peer
    furthest = -1
    for k in range(held_at + 10 * (MOST + 2)):
        submit, send, deliver = step(k, None, latency)
        if send is not None:
            furthest = send
        if deliver is not None:
            if latency > 0 and deliver - 1 >= 0 and deliver - 1 not in peer_rows:
                return furthest  # lands the last row first
            if deliver not in peer_sent:
                return furthest  # the exchange's barrier
            if latency == 0 and deliver not in peer_rows:
                return furthest  # the strict order lands its row at once
    raise AssertionError("nothing stopped the fast rank")


@pytest.mark.parametrize("latency", range(MOST + 1))
@pytest.mark.parametrize("f", [0, 1, 5, 6, 7])
def test_a_held_back_rank_never_reads_a_slot_a_peer_overwrites(latency, f):
    """While a rank reads frame f's parts, a peer may send frames f + 1 .. f + reach, and none of
    them may land in f's slot of a ring of ``slots`` (frames at --latency 3 with three slots did:
    issue 69)."""
    reach = furthest_sent_while_held(latency, f) - f
    assert reach == held_back_reach(latency)
    assert reach < slots(latency)
    assert [slots(n) for n in range(MOST + 1)] == [2, 3, 3, 4]


def test_reads_wait_a_step_from_two_frames_in_flight():
    assert [read_lag(n) for n in range(4)] == [0, 0, 1, 1]


def test_pieces_drawn_ahead_read_as_render_gives_them(ctx):
    """Two frames in flight on the scissor method: frame f+1 drawn into the other framebuffer
    before frame f is read; the pixels equal ``render``'s, with depth and several pieces."""
    from multigpu.gpu.pending import _disjoint
    from multigpu.gpu.render import RegionRenderer

    scene, cams = ctx
    r = RegionRenderer(scene["ctx"], scene["scene"], (96, 64), "scissor")
    pieces = [((0, 0, 40, 64), None, None), ((40, 10, 96, 50), None, None)]
    want = [[(r.render(*cam, p[0], None, depth=True)) for p in pieces] for cam in cams]
    a = r.submit(*cams[0], pieces, depth=True, ahead=True)
    b = r.submit(*cams[1], pieces, depth=True, ahead=True)
    for pending, expect in ((a, want[0]), (b, want[1])):
        for (rgb, z), (wrgb, wz) in zip(pending.read(), expect):
            assert (rgb == wrgb).all() and (z == wz).all()
    c = r.submit(*cams[0], [((0, 0, 50, 64), None, None), ((40, 0, 96, 64), None, None)], ahead=True)  # overlapping
    assert c.done is not None  # read at once
    assert _disjoint([(0, 0, 1, 1), (1, 0, 2, 1)]) and not _disjoint([(0, 0, 2, 2), (1, 1, 3, 3)])
    r.release()


@pytest.fixture(scope="module")
def ctx():
    from multigpu.core.camera import Camera, frame_matrices
    from multigpu.gpu.render import EglUnavailable, create_context
    from multigpu.scene.models import SceneSpec, load_scene

    try:
        gl, _ = create_context()
    except EglUnavailable as exc:
        pytest.skip(str(exc))
    scene, _ = load_scene(SceneSpec(scene="plant", triangles=3000), use_cache=False)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.bounds)
    mid = (lo + hi) / 2
    cams = []
    for eye in (mid + (hi - lo) * [1.2, 0.9, 0.7], mid + (hi - lo) * [-1.0, 1.1, 0.5]):
        view, proj, light = frame_matrices(Camera(tuple(eye), tuple(mid), far=1e4), (96, 64))
        cams.append((view.copy(), proj.copy(), light.copy()))
    yield {"ctx": gl, "scene": scene}, cams
    gl.release()
