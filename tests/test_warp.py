"""Projector walls tested without projectors: a simulated rig of three projectors on a flat and on
a cylindrical screen (18 % overlap), each output warped and blended as the wall does, then the
projection simulated (each screen point's light summed over the projectors reaching it, through a
2.2 display gamma and a black floor) and compared with the content shown straight."""

import numpy as np
import pytest

from multigpu.core.warpblend import blend, decode, encode, map_values, output, resample, sample, upsample
from multigpu.warp.rig import flat_rig

#: the warp grid the outputs read (a sample every ~8 output pixels, as calibration files hold)
GRID = (25, 33)


@pytest.fixture(scope="module", params=["flat", "cylinder"])
def rig(request):
    return flat_rig(3, 0.18, kind=request.param)


def screen_samples(rig):
    """Content points across the screen (clear of its very edge, where a projector's last pixel
    is half on it), the world points there and how many projectors reach each."""
    s, t = np.meshgrid(np.linspace(0.01, 0.99, 480), np.linspace(0.02, 0.98, 200))
    points = rig.screen.point(s, t)
    return s, t, points, rig.covering(points)


def outputs(rig, content, linear=True, beta=True):
    """Each projector's final picture: ``content`` through its warp (from the coarse grid) and blend."""
    out = []
    for i, p in enumerate(rig.projectors):
        alpha, lift = rig.blend_maps(i)
        out.append(output(content, upsample(rig.warp(i, GRID), p.size), alpha, lift if beta else 0.0,
                          linear=linear))
    return out


def test_the_rig_covers_its_screen_with_overlaps(rig):
    _, _, _, n = screen_samples(rig)
    assert n.min() == 1 and rig.most() == 2
    assert 0.08 < (n == 2).mean() < 0.3  # two overlaps of ~18 % of an image each


def test_geometric_error_is_under_half_a_projector_pixel(rig):
    """The warp read from its coarse grid against the exact warp of every pixel, in pixels."""
    worst = 0.0
    for i, p in enumerate(rig.projectors):
        exact, got = rig.warp(i), upsample(rig.warp(i, GRID), p.size)
        on = ((exact >= 0) & (exact <= 1)).all(axis=-1)
        per_pixel = np.stack([np.gradient(exact[..., 0], axis=1), np.gradient(exact[..., 1], axis=0)], axis=-1)
        worst = max(worst, float(np.abs((got - exact)[on] / per_pixel[on]).max()))
    assert worst <= 0.5


@pytest.mark.parametrize("level", [128, 255])
def test_overlaps_give_the_same_light_as_the_rest(rig, level):
    """A flat field through the blended outputs: within 2 % of the content shown straight, in the
    overlaps and out of them (8-bit outputs: darker fields lose more to rounding)."""
    s, t, _, n = screen_samples(rig)
    light = rig.light(outputs(rig, np.full((300, 800, 3), level, np.uint8)), s, t)[..., 0]
    want = rig.most() * rig.black + (1 - rig.black) * decode(level)
    err = np.abs(light / want - 1)
    assert err[n >= 2].max() <= 0.02 and np.sqrt((err[n >= 2] ** 2).mean()) <= 0.01
    assert err[n == 1].max() <= 0.02


def test_a_blend_in_gamma_space_dims_the_overlaps_centre_by_more_than_half(rig):
    """What the simulation is for: blending encoded values (no gamma taken off) gives the overlap's
    centre 2 x 0.5 ** 2.2 = 0.44 of the light: a dip of about 56 %."""
    s, t, points, n = screen_samples(rig)
    centre = (n == 2) & (np.abs(rig.shares(points).max(axis=0) - 0.5) < 0.02)
    assert centre.sum() > 50
    white = np.full((300, 800, 3), 255, np.uint8)
    want = rig.most() * rig.black + (1 - rig.black)
    dip = 1 - rig.light(outputs(rig, white, linear=False), s, t)[..., 0][centre] / want
    assert 0.5 < dip.mean() < 0.6
    right = 1 - rig.light(outputs(rig, white), s, t)[..., 0][centre] / want
    assert np.abs(right).max() <= 0.02


def test_beta_lifts_the_black_outside_the_overlaps(rig):
    """A black frame: the overlaps against the rest, with the black-level lift (within 5 %) and
    without it (twice as bright: two black floors)."""
    s, t, _, n = screen_samples(rig)
    black = np.zeros((300, 800, 3), np.uint8)
    ratio = {}
    for lift in (True, False):
        light = rig.light(outputs(rig, black, beta=lift), s, t)[..., 0]
        ratio[lift] = light[n == 2].mean() / light[n == 1].mean()
    assert ratio[True] <= 1.05 and 1.9 <= ratio[False] <= 2.1


def test_a_picture_comes_through_the_rig(rig):
    """A smooth picture, not a flat field: the simulated screen's PSNR against the picture shown
    straight (both through the same gamma), and its error where neighbours overlap."""
    s, t, _, n = screen_samples(rig)
    yy, xx = np.mgrid[0:300, 0:800]
    content = (150 + 90 * np.sin(xx / 60.0) * np.cos(yy / 45.0)).astype(np.uint8)[..., None].repeat(3, axis=2)
    light = rig.light(outputs(rig, content), s, t)[..., 0]
    want = rig.most() * rig.black + (1 - rig.black) * decode(sample(content, np.stack([s, t], axis=-1))[..., 0])
    top = want.max()
    mse = np.mean((encode(light / top).astype(float) - encode(want / top).astype(float)) ** 2)
    assert 10 * np.log10(255 ** 2 / mse) >= 40
    assert np.abs(light / want - 1)[n == 2].max() <= 0.05


def test_blend_is_mpcdis_formula_in_linear_light():
    p = np.array([[[255, 128, 0]]], np.uint8)
    got = blend(p, np.full((1, 1), 0.5), np.full((1, 1), 0.1))
    want = encode(decode(p) * 0.5 * 0.9 + 0.1)
    assert np.array_equal(got, want)
    # alpha maps: gamma-embedded values are made linear; a map of another size is resampled
    assert map_values(np.array([255, 0, 128]), 8, 2.2) == pytest.approx([1.0, 0.0, (128 / 255) ** 2.2])
    small = np.array([[0.0, 1.0], [0.0, 1.0]])
    big = resample(small, (4, 2))
    assert big.shape == (2, 4) and np.allclose(big[0], [0.0, 0.25, 0.75, 1.0])


def test_upsample_keeps_nan_cells_dark_and_sample_blacks_outside_the_content():
    grid = np.zeros((3, 3, 2))
    grid[..., 0], grid[..., 1] = np.linspace(0, 1, 3)[None, :], np.linspace(0, 1, 3)[:, None]
    grid[0, 0] = np.nan
    up = upsample(grid, (6, 6))
    assert np.isnan(up[0, 0, 0]) and np.isfinite(up[5, 5]).all()
    img = np.full((4, 4, 3), 200.0)
    got = sample(img, np.array([[[0.5, 0.5], [1.2, 0.5], [np.nan, 0.1]]]))
    assert got[0, 0, 0] == 200.0 and not got[0, 1:].any()


def test_a_content_to_output_mesh_reads_as_the_output_to_content_warp(tmp_path):
    """Paul Bourke's mesh (nodes placed on the output for a regular grid of content) read back
    gives every output pixel the content the rig's geometry gives it (under half a pixel)."""
    from multigpu.errors import InputError
    from multigpu.warp import bourke

    rig = flat_rig(3, 0.18)
    p = rig.projectors[1]
    w, h = p.size
    s, t = np.meshgrid(np.linspace(0, 1, 81), np.linspace(0, 1, 31))
    uv = p.pixel(rig.screen.point(s, t))  # where each content node lands on this projector's output
    seen = np.isfinite(uv[..., 0])
    x = np.where(seen, (uv[..., 0] / w * 2 - 1) * (w / h), 0.0)
    y = np.where(seen, 1 - uv[..., 1] / h * 2, 0.0)
    rows = [f"{a:.9f} {b:.9f} {c:.9f} {d:.9f} {e:g}" for a, b, c, d, e in
            zip(x.ravel(), y.ravel(), s.ravel(), 1 - t.ravel(), np.where(seen, 1.0, -1.0).ravel())]
    path = tmp_path / "p2.data"
    path.write_text("2\n81 31\n" + "\n".join(rows) + "\n")
    out = bourke.read(path, (w, h))
    exact = rig.warp(1)
    both = np.isfinite(out.warp).all(axis=-1) & ((exact >= 0) & (exact <= 1)).all(axis=-1)
    assert both.mean() > 0.6 and out.alpha[both].min() == 1.0 and out.alpha[~np.isfinite(out.warp[..., 0])].max() == 0
    per_pixel = np.stack([np.gradient(exact[..., 0], axis=1), np.gradient(exact[..., 1], axis=0)], axis=-1)
    assert np.abs((out.warp - exact)[both] / per_pixel[both]).max() <= 0.5
    path.write_text("2\n81 31\n0 0 0 0 1\n")
    with pytest.raises(InputError, match=r"p2.data: 81 x 31 nodes promised, 1 of 5 values found"):
        bourke.read(path, (w, h))
    path.write_text("7\n2 2\n" + "0 0 0 0 1\n" * 4)
    with pytest.raises(InputError, match=r"mesh type 7"):
        bourke.read(path, (w, h))


def test_a_bare_pfm_and_alpha_png_read_as_nDisplay_takes_them(tmp_path):
    from PIL import Image

    from multigpu.errors import InputError
    from multigpu.warp import bare, pfm

    rig = flat_rig(3, 0.18)
    p = rig.projectors[0]
    grid = rig.warp(0, GRID)
    (tmp_path / "p1.pfm").write_bytes(pfm.write(np.concatenate([grid, np.zeros(grid.shape[:2] + (1,))], axis=2)))
    alpha, _ = rig.blend_maps(0)
    h, w = alpha.shape
    small = alpha.reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3))  # half size (each pixel four's mean)
    half = np.round(small ** (1 / 2.2) * 255).astype(np.uint8)  # 8 bits, gamma-embedded
    Image.fromarray(half).save(tmp_path / "p1_alpha.png")
    out = bare.read(tmp_path / "p1.pfm", p.size, tmp_path / "p1_alpha.png", gamma_embedded=2.2)
    assert np.allclose(out.warp, grid, atol=1e-6) and out.area == (0.0, 0.0, 1.0, 1.0)
    assert out.notes == [f"p1_alpha.png of {p.size[0] // 2} x {p.size[1] // 2} resampled to the output's "
                         f"{p.size[0]} x {p.size[1]}"]
    err = np.abs(out.alpha - alpha)  # half the samples: off only where alpha jumps (the screen's edges)
    assert np.percentile(err, 90) < 0.005 and err.mean() < 0.02
    (tmp_path / "far.pfm").write_bytes(pfm.write(np.concatenate([grid * 300, grid[..., :1]], axis=2)))  # pixels
    with pytest.raises(InputError, match=r"far.pfm: maps outside the content"):
        bare.read(tmp_path / "far.pfm", p.size)
