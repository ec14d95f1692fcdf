"""A projector output's colour: `.cube` lookup tables read (1D and 3D, their domain) and applied
(trilinear), bad files refused in one line; a 3x3 matrix in linear light before the blend and the
LUT on the signal last; a wall file naming each output's colour, checked at the door; the outputs'
pictures coloured, and left unblended with ``--blend off``."""

import json
import re

import numpy as np
import pytest

from multigpu.core.canvas import Canvas
from multigpu.core.warpblend import blend
from multigpu.errors import InputError
from multigpu.warp import mpcdi
from multigpu.warp.colour import apply_lut, read_cube, read_matrix
from multigpu.warp.make import buffer_size, outputs
from multigpu.warp.rig import flat_rig

SWAP = [[0, 0, 1], [0, 1, 0], [1, 0, 0]]  # red and blue trade places


def cube_3d(path, n: int = 5, f=lambda r, g, b: (r, g, b), domain=None):
    """A 3D .cube file of ``n`` samples a side, each entry ``f(r, g, b)`` (red changing fastest)."""
    lines = ["TITLE \"test\"", "# a comment", f"LUT_3D_SIZE {n}"]
    if domain:
        lines += [f"DOMAIN_MIN {domain[0]} {domain[0]} {domain[0]}", f"DOMAIN_MAX {domain[1]} {domain[1]} {domain[1]}"]
    s = np.linspace(0, 1, n)
    for b in s:
        for g in s:
            for r in s:
                lines.append("%.6f %.6f %.6f" % f(r, g, b))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_an_identity_lut_changes_nothing_and_a_swapping_one_swaps(tmp_path):
    v = np.random.default_rng(0).random((7, 5, 3))
    ident = read_cube(cube_3d(tmp_path / "id.cube"))
    assert ident.dims == 3 and ident.table.shape == (5, 5, 5, 3)
    assert np.allclose(apply_lut(v, ident), v, atol=1e-6)  # linear entries: trilinear is exact
    swap = read_cube(cube_3d(tmp_path / "swap.cube", f=lambda r, g, b: (b, g, r)))
    assert np.allclose(apply_lut(v, swap), v[..., ::-1], atol=1e-6)
    (tmp_path / "one.cube").write_text("LUT_1D_SIZE 3\n0 0 0\n0.25 0.5 1\n1 1 1\n")
    one = read_cube(tmp_path / "one.cube")
    assert one.dims == 1
    assert np.allclose(apply_lut(np.array([[0.5, 0.5, 0.5], [0.25, 0.75, 1.0]]), one),
                       [[0.25, 0.5, 1.0], [0.125, 0.75, 1.0]])


def test_a_lut_over_its_own_domain(tmp_path):
    lut = read_cube(cube_3d(tmp_path / "d.cube", n=3, f=lambda r, g, b: (r, g, b), domain=(0.0, 2.0)))
    assert np.allclose(apply_lut(np.array([1.0, 2.0, 3.0]), lut), [0.5, 1.0, 1.0])  # clamped past its max


@pytest.mark.parametrize(("text", "says"), [
    ("0 0 0\n1 1 1\n", "no LUT_1D_SIZE or LUT_3D_SIZE: not a .cube LUT"),
    ("LUT_3D_SIZE 2\n0 0 0\n1 1 1\n", "2 entries for a 3D LUT of size 2 (8 wanted)"),
    ("LUT_1D_SIZE 2\n0 0 zero\n1 1 1\n", "line 2 is not a .cube line: '0 0 zero'"),
    ("LUT_1D_SIZE 1\n0 0 0\n", "a 1D size of 1 (2..65536)"),
    ("LUT_3D_SIZE 999\n", "a 3D size of 999 (2..256)"),
    ("LUT_1D_SIZE 2\nDOMAIN_MIN 1 1 1\nDOMAIN_MAX 0 0 0\n0 0 0\n1 1 1\n", "a domain whose max is not above its min"),
    ("LUT_1D_SIZE 2\n0 0 nan\n1 1 1\n", "non-finite entries"),
])
def test_a_bad_cube_is_one_line_naming_the_file(tmp_path, text, says):
    (tmp_path / "bad.cube").write_text(text)
    with pytest.raises(InputError) as got:
        read_cube(tmp_path / "bad.cube")
    assert str(got.value).startswith(f"--wall {tmp_path / 'bad.cube'}: ") and says in str(got.value)
    assert "\n" not in str(got.value)


def test_a_missing_cube_and_a_bad_matrix_are_one_line(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_cube(tmp_path / "none.cube")
    for bad, says in (([[1, 0], [0, 1]], "3 rows of 3 finite numbers"), ([[5, 0, 0], [0, 1, 0], [0, 0, 1]],
                                                                          "rows must sum to 0..4")):
        with pytest.raises(InputError, match=re.escape(says)):
            read_matrix(bad, "here")


def test_the_matrix_acts_in_linear_light_before_the_blend_and_the_lut_on_the_signal_last(tmp_path):
    values = np.array([[[200.0, 100.0, 20.0]]])
    alpha = np.full((1, 1), 0.5)
    plain = blend(values, alpha)
    assert (blend(values, alpha, matrix=np.eye(3)) == plain).all()
    assert (blend(values, alpha, matrix=SWAP) == plain[..., ::-1]).all()  # per channel: the blend commutes
    assert (blend(values, alpha, signal=lambda v: v) == plain).all()
    assert (blend(values, alpha, signal=lambda v: 1.0 - v) == 255 - plain).all()  # on the encoded signal


def test_a_wall_file_gives_each_output_its_colour_and_refuses_a_bad_one_at_the_door(tmp_path, capsys):
    from multigpu.wall import load_wall

    mpcdi.write(tmp_path / "rig.mpcdi", (400, 100), outputs(flat_rig(2, 0.2, size=(64, 48)), (400, 100)))
    cube_3d(tmp_path / "p2.cube", n=3)
    wall = tmp_path / "wall.json"
    doc = {"mpcdi": "rig.mpcdi",
           "outputs": {"p1": {"color_matrix": SWAP}, "p2": {"lut": "p2.cube"}}}
    wall.write_text(json.dumps(doc))
    got = load_wall(str(wall)).outputs
    assert got == {"p1": {"matrix": [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]},
                   "p2": {"lut": str(tmp_path / "p2.cube")}}
    from multigpu.cli import main

    assert main(["wall", "check", str(wall), "--offline"]) == 0
    said = capsys.readouterr().out
    assert "output p1: a colour matrix" in said and "output p2: the LUT p2.cube" in said
    for outs, says in (({"p9": {}}, "outputs: p9: no such region in the mpcdi file (p1, p2)"),
                       ({"p1": {"color_matrix": [[1, 2, 3], [0, 0, 0], [9, 9, 9]]}}, "rows must sum to 0..4"),
                       ({"p1": {"lut": "none.cube"}}, "outputs: p1: lut: "),
                       ({"p1": {"gamma": 2.2}}, "outputs.p1: unknown key 'gamma' (known: color_matrix, lut)")):
        wall.write_text(json.dumps({**doc, "outputs": outs}))
        with pytest.raises(InputError) as err:
            load_wall(str(wall))
        assert str(err.value).startswith(f"--wall {wall}: ") and says in str(err.value), str(err.value)
    wall.write_text(json.dumps({"grid": "1x2", "tile": "200x100", "outputs": {"p1": {}}}))
    with pytest.raises(InputError, match="outputs: give the mpcdi file whose regions they name"):
        load_wall(str(wall))


def pictures(path, canvas, colors=None, blend=True, grid=None) -> dict:
    """Every output's picture of ``canvas`` (top row first) as the ranks' GPU pass makes it, on a
    wall of ``grid`` ranks (None: a rank a region)."""
    from multigpu.gpu.context import create_context
    from multigpu.rank.outputs import Projector
    from multigpu.warp.layout import layout, outputs_by_tile

    ctx, _ = create_context()
    lay = layout(path, *mpcdi.read(path), grid)
    tiles = Canvas(lay.grid, lay.tile, lay.mullion).tiles()
    everyone = outputs_by_tile(str(path), grid)
    out = {}
    for k, (x0, y0, x1, y1) in enumerate(tiles):
        p = Projector(ctx, str(path), k, lay.grid, lay.tile, colors or {}, blend)
        top = p.run(np.ascontiguousarray(canvas[::-1][y0:y1, x0:x1]))[::-1].copy()
        for o in (o for o in everyone if o.tile == k):
            out[o.name] = top[o.at[1]:o.at[1] + o.size[1], o.at[0]:o.at[0] + o.size[0]]
        p.release()
    ctx.release()
    return out


def test_a_rank_driving_several_projectors_makes_each_ones_picture(tmp_path):
    """Four projectors on two ranks (a block of two regions a tile, overlapping inside it as
    across it) or on one: each output's picture is the numpy reference's of its own region, as
    when each has a rank of its own; the rank's picture holds them side by side."""
    from projected import reference

    from multigpu.warp.layout import layout, outputs_by_tile, picture_size

    rig = flat_rig(4, 0.2, size=(64, 48))
    bw, bh = buffer_size(rig)
    path = tmp_path / "rig.mpcdi"
    mpcdi.write(path, (bw, bh), outputs(rig, (bw, bh)))
    canvas = np.zeros((bh, bw, 3), dtype=np.uint8)
    canvas[..., 1] = (np.arange(bw) * 255 // bw)[None, :]  # a ramp across, lines down
    canvas[::5, :, 0] = 220
    lay = layout(path, *mpcdi.read(path), (1, 2))
    region = layout(path, *mpcdi.read(path)).tile
    assert lay.per == (1, 2) and lay.region == region and lay.labels == (0, 0, 1, 1)
    assert lay.tile == (2 * region[0] + lay.mullion[0], region[1]) and lay.offsets[1] == (region[0] + lay.mullion[0], 0)
    outs = outputs_by_tile(str(path), (1, 2))
    assert [(o.name, o.tile, o.at) for o in outs] == [("p1", 0, (0, 0)), ("p2", 0, (64, 0)), ("p3", 1, (0, 0)),
                                                      ("p4", 1, (64, 0))]
    assert picture_size(outs, 1) == (128, 48)
    want = reference(canvas, path)
    for grid in ((1, 2), (1, 1), None):
        got = pictures(path, canvas, grid=grid)
        for name in ("p1", "p2", "p3", "p4"):
            d = np.abs(got[name].astype(int) - want[name])
            assert d.max() <= 2 and d.mean() < 0.5, (grid, name, d.max(), d.mean())
    with pytest.raises(InputError, match="its regions make a 1x4 grid: a wall of 1x3 ranks must divide it"):
        layout(path, *mpcdi.read(path), (1, 3))


def test_the_outputs_pictures_are_coloured_and_unblended_with_blend_off(tmp_path):
    from projected import reference

    path = tmp_path / "rig.mpcdi"
    mpcdi.write(path, (400, 100), outputs(flat_rig(2, 0.2, size=(64, 48)), (400, 100)))
    canvas = np.zeros((100, 400, 3), dtype=np.uint8)
    canvas[..., 0] = 200  # a red canvas
    canvas[:, ::7, 2] = 90  # with blue lines
    plain = pictures(path, canvas)
    coloured = pictures(path, canvas, {"p1": {"matrix": SWAP}})
    assert (coloured["p1"] == plain["p1"][..., ::-1]).all() and (coloured["p2"] == plain["p2"]).all()
    whole = pictures(path, canvas, blend=False)
    lit = whole["p1"][..., 0] > 0
    assert lit.mean() > 0.5 and (whole["p1"][..., 0][lit] >= 190).all()  # no fade in the overlap
    assert (plain["p1"][..., 0][lit] < 150).any()  # where the blend fades it out
    # the GPU's pass is the numpy reference's arithmetic (its bilinear weights 8-bit: a level or two)
    for got, want in ((plain, reference(canvas, path)), (whole, reference(canvas, path, blend=False)),
                      (coloured, reference(canvas, path, {"p1": {"matrix": SWAP}}))):
        for name in ("p1", "p2"):
            d = np.abs(got[name].astype(int) - want[name])
            assert d.max() <= 2 and d.mean() < 0.5, (name, d.max(), d.mean())


def test_the_gpu_pass_takes_colour_alpha_and_beta_maps_and_a_1d_lut(tmp_path):
    """Maps of three channels (MPCDI's componentDepth 3: each primary its own blend) and a 1D
    table: the GPU's picture is the numpy reference's within two levels."""
    from multigpu.core.warpblend import output
    from multigpu.gpu.context import create_context
    from multigpu.gpu.outputs import OutputPass

    rng = np.random.default_rng(5)
    h, w = 24, 32
    yy, xx = np.mgrid[0:h, 0:w]
    coords = np.stack([(xx + 0.5) / w * 0.9 + 0.05, (yy + 0.5) / h * 0.8 + 0.1], axis=-1)
    coords[0, 0] = np.nan  # a pixel that shows nothing (beta still lifts it)
    alpha = rng.uniform(0.2, 1.0, (h, w, 3))
    beta = rng.uniform(0.0, 0.05, (h, w, 3))
    tile = rng.integers(0, 256, (40, 50, 3), dtype=np.uint8)  # top row first
    (tmp_path / "one.cube").write_text("LUT_1D_SIZE 4\n0 0 0\n0.4 0.3 0.2\n0.7 0.6 0.5\n1 1 1\n")
    lut = read_cube(tmp_path / "one.cube")
    ctx, _ = create_context()
    p = OutputPass(ctx, (w, h), (50, 40), coords, alpha, beta, lut=lut)
    got = p.run(np.ascontiguousarray(tile[::-1]))[::-1].copy()
    p.release()
    ctx.release()
    want = output(tile, coords, alpha, beta, signal=lambda v: apply_lut(v, lut))
    d = np.abs(got.astype(int) - want)
    assert d.max() <= 2 and d.mean() < 0.5, (d.max(), d.mean())
    assert got[0, 0].max() > 0  # beta's lift where nothing is shown
