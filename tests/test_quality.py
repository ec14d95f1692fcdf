"""Speed for accuracy, pure: the render scale's pixel maps, the widened masks, the frame-rate
controller (settles, does not oscillate, leaves a met target alone) and the still-camera rule."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core.camera import Camera
from multigpu.core.canvas import Canvas
from multigpu.core.quality import WARMUP, Controller, Fidelity
from multigpu.core.regions import overlaps, pixel_spans
from multigpu.core.resample import MIN_SCALE, Widen, covered, footprint, scaled_size, upscale
from multigpu.scene.lod import with_lods
from multigpu.scene.plant import generate_plant

SCENE = with_lods(generate_plant(triangles=8000, seed=2))


@settings(max_examples=60, deadline=None)
@given(st.integers(8, 300), st.integers(8, 300), st.floats(MIN_SCALE, 1.0), st.integers(0, 2**32 - 1))
def test_regions_upscaled_make_the_whole_upscaled(W, H, scale, seed):
    """Any cut of the canvas into regions, each upscaled from its footprint, gives the canvas
    upscaled from the whole scaled image: the picture does not depend on the partition."""
    rng = np.random.default_rng(seed)
    ssize = scaled_size((W, H), scale)
    small = rng.integers(0, 255, (ssize[1], ssize[0], 3), dtype=np.uint8)
    whole = upscale(small, (0, 0, W, H), (W, H), ssize)
    assert whole.shape == (H, W, 3)
    xs = np.unique(np.r_[0, np.sort(rng.integers(1, W, 2)), W])
    ys = np.unique(np.r_[0, np.sort(rng.integers(1, H, 2)), H])
    for x0, x1 in zip(xs[:-1], xs[1:]):
        for y0, y1 in zip(ys[:-1], ys[1:]):
            sx0, sy0, sx1, sy1 = footprint((x0, y0, x1, y1), (W, H), ssize)
            assert 0 <= sx0 < sx1 <= ssize[0] and 0 <= sy0 < sy1 <= ssize[1]
            part = upscale(small[sy0:sy1, sx0:sx1], (x0, y0, x1, y1), (W, H), ssize)
            np.testing.assert_array_equal(part, whole[y0:y1, x0:x1])
            cx0, cy0, cx1, cy1 = covered((x0, y0, x1, y1), (W, H), ssize)
            assert cx0 <= x0 and cy0 <= y0 and cx1 >= x1 and cy1 >= y1  # a superset of the region
            # every footprint pixel's sample (its centre on the canvas) lies in the covered area
            for sx in (sx0, sx1 - 1):
                assert cx0 <= (sx + 0.5) * W / ssize[0] <= cx1
            for sy in (sy0, sy1 - 1):
                assert cy0 <= (sy + 0.5) * H / ssize[1] <= cy1


def test_scale_one_is_the_identity():
    img = np.arange(5 * 7 * 3, dtype=np.uint8).reshape(5, 7, 3)
    assert footprint((2, 1, 7, 5), (7, 5), (7, 5)) == (2, 1, 7, 5)
    np.testing.assert_array_equal(upscale(img[1:5, 2:7], (2, 1, 7, 5), (7, 5), (7, 5)), img[1:5, 2:7])


@pytest.mark.parametrize("mullion", [(0, 0), (6, 4)])
def test_widened_masks_hold_every_object_reaching_the_covered_area(mullion):
    canvas = Canvas((2, 3), (50, 40), mullion)
    rng = np.random.default_rng(1)
    lo = rng.random((3000, 2)) * 0.99
    vrects = np.concatenate([lo, lo + rng.random((3000, 2)) * 0.01], axis=1)
    vrects[::17] = np.nan  # unseen objects
    spans, on = pixel_spans(vrects, canvas.visible)
    tiles = canvas.tiles()
    masks = [on & overlaps(spans, t - np.tile(canvas._shift()[k], 2)) for k, t in enumerate(tiles)]
    wide = Widen(canvas).masks(tiles, masks, vrects, 0.37)
    size, ssize = canvas.size, scaled_size(canvas.size, 0.37)
    if not any(mullion):  # more at this scale (with bezels the covered area may lie behind them: nothing more)
        assert sum(int(w.sum()) for w in wide) > sum(int(m.sum()) for m in masks)
    for k, (m, w) in enumerate(zip(masks, wide)):
        assert (w >= m).all()  # a superset
        if not any(mullion):  # no bezels: exactly the objects reaching the covered area
            np.testing.assert_array_equal(w, m | (on & overlaps(spans, covered(tiles[k], size, ssize))))


class Plant:
    """A frame's period from the load asked for: a fixed part (the plant walk at 4 ranks here: a
    quarter to a third of the full frame at the smallest scale) and a part that scales, a lag of
    ``lag`` frames before a frame's time is measured, and noise."""

    def __init__(self, full_ms, fixed=0.3, lag=2, noise=0.05, seed=0):
        self.full_ms, self.fixed, self.lag, self.noise = full_ms, fixed, lag, noise
        self.rng = np.random.default_rng(seed)

    def run(self, ctl, frames, jump_at=None, jump=1.0):
        periods, pending = [], []
        for f in range(frames):
            full = self.full_ms * (jump if jump_at is not None and f >= jump_at else 1.0)
            t = full * (self.fixed + (1 - self.fixed) * ctl.load) * (1 + self.noise * self.rng.standard_normal())
            periods.append(t)
            pending.append(t)
            if len(pending) > self.lag:
                ctl.observe(pending.pop(0))
        return np.array(periods)


@pytest.mark.parametrize("seed,lag", [(s, lag) for s in range(3) for lag in (1, 2, 3, 4)])
def test_controller_holds_a_target_twice_the_full_rate_and_settles_after_a_jump(seed, lag):
    ctl = Controller(target_fps=100.0, lag=lag)  # 10 ms; the full frame takes 20 ms
    periods = Plant(20.0, lag=lag, seed=seed).run(ctl, 300, jump_at=150, jump=1.4)  # the full frame 40 % dearer
    settled = lambda p: np.abs(p / 10.0 - 1) <= 0.10 + 1e-12
    assert settled(periods[30:150]).mean() >= 0.85  # the noise alone (5 %) keeps ~5 % outside
    after = periods[150:]
    run = np.convolve(settled(after).astype(float), np.ones(10) / 10, mode="valid")
    assert np.argmax(run >= 0.8) <= 30  # back within the band within 30 frames of the jump
    loads = []
    ctl2 = Controller(target_fps=100.0)
    Plant(20.0, noise=0.0, seed=seed).run(ctl2, 200)
    for _ in range(40):  # noise-free: a fixed point, no oscillation
        loads.append(ctl2.load)
        Plant(20.0, noise=0.0).run(ctl2, 1)
    assert max(loads) - min(loads) < 1e-9


def test_a_target_already_met_never_leaves_full_quality():
    ctl = Controller(target_fps=30.0)  # 33 ms; frames take 20-30 ms
    Plant(25.0, noise=0.1).run(ctl, 500)
    assert ctl.load == 1.0 and ctl.quality(1.0, 0.0).full


def test_quality_falls_with_load_and_stays_in_range():
    ctl = Controller(target_fps=60.0)
    last = (1.0, 0.0)
    for load in (0.8, 0.4, 0.1, 1e-3, 1e-9):
        ctl.load = max(load, (MIN_SCALE ** 4))
        q = ctl.quality(1.0, 0.0)
        assert not q.full and MIN_SCALE <= q.scale <= last[0] and q.lod_px >= last[1]
        last = (q.scale, q.lod_px)
    assert math.isclose(last[0], MIN_SCALE)


def test_a_still_camera_renders_full_quality_and_teaches_nothing():
    fid = Fidelity(SCENE, 240, target_fps=1000.0)
    fid.controller.load = 0.05  # well below full
    a = Camera((30.0, 20.0, 10.0), (0.0, 0.0, 0.0))
    b = Camera((31.0, 20.0, 10.0), (0.0, 0.0, 0.0))
    got = [fid.frame(f, cam) for f, cam in enumerate([a, b, b, b, a])]
    assert [q.full for q, _, _ in got] == [False, False, True, True, False]
    assert got[2][1] is None and (got[2][2] == SCENE.tris).all()  # full quality: every object as modelled
    assert got[1][1] is not None and got[1][2].sum() < SCENE.tris.sum()
    assert set(fid.chosen) == {f for f in (2, 3, 4) if f >= WARMUP} - {2, 3}
    before = fid.controller.load
    fid.landed(2, 1.0)  # a still frame's time: not observed
    assert fid.controller.load == before


def test_without_a_target_every_frame_is_the_configured_quality():
    fid = Fidelity(SCENE, 240, target_fps=None, scale=0.5, lod_error=2.0)
    for f in range(4):
        q, _, _ = fid.frame(f, Camera((30.0 + f, 20.0, 10.0), (0.0, 0.0, 0.0)))
        assert q.full and q.scale == 0.5 and q.lod_px == 2.0
    assert not fid.chosen and not Fidelity(SCENE, 240, None).active and fid.active
