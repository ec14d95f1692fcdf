"""MPCDI files (2D media): a rig's outputs written by ``warp make`` read back to the same
projection; a file laid out by the specification as another tool writes it; bad files refused
in one line naming the file and what is wrong."""

import io
import re
import struct
import zipfile

import numpy as np
import pytest
from PIL import Image

from multigpu.core.warpblend import decode, output, upsample
from multigpu.errors import InputError
from multigpu.warp import mpcdi, pfm
from multigpu.warp.make import outputs
from multigpu.warp.rig import flat_rig


@pytest.mark.parametrize("kind", ["flat", "cylinder"])
def test_a_rig_written_and_read_back_projects_as_the_rig(tmp_path, kind):
    rig = flat_rig(3, 0.18, kind=kind)
    made = outputs(rig, (1600, 600))
    path = mpcdi.write(tmp_path / "wall.mpcdi", (1600, 600), made)
    size, got = mpcdi.read(path)
    assert size == (1600, 600) and [o.name for o in got] == ["p1", "p2", "p3"]
    for a, b in zip(made, got):
        assert b.size == a.size and b.area == pytest.approx(a.area) and not b.notes
        assert np.allclose(b.warp, a.warp, atol=1e-6, equal_nan=True)
        assert np.abs(b.alpha - a.alpha).max() < 2e-4 and np.abs(b.beta - a.beta).max() < 2e-5
    # the wall's outputs from the file: a white field projects within 2 % everywhere
    white = np.full((300, 800, 3), 255, np.uint8)
    pictures = [output(white, content_coords(o, upsample(o.warp, o.size)), o.alpha, o.beta) for o in got]
    s, t = np.meshgrid(np.linspace(0.01, 0.99, 300), np.linspace(0.02, 0.98, 120))
    light = rig.light(pictures, s, t)[..., 0]
    assert np.abs(light / (rig.most() * rig.black + 1 - rig.black) - 1).max() <= 0.02


def content_coords(o, warp: np.ndarray) -> np.ndarray:
    """A region's warp coordinates (..., 2) as coordinates across the whole buffer."""
    x, y, w, h = o.area
    return np.stack([x + warp[..., 0] * w, y + warp[..., 1] * h], axis=-1)


def big_endian_pfm(grid: np.ndarray) -> bytes:
    h, w, _ = grid.shape
    return f"PF\n{w} {h}\n1.0\n".encode() + np.ascontiguousarray(grid[::-1]).astype(">f4").tobytes()


def png(values: np.ndarray) -> bytes:
    out = io.BytesIO()
    Image.fromarray(values).save(out, format="PNG")
    return out.getvalue()


SPEC_XML = """<?xml version="1.0" encoding="UTF-8"?>
<MPCDI profile="2d" geometry="1" color="1" version="2.0">
  <display>
    <buffer id="Main" xResolution="1280" yResolution="480">
      <region id="left" x="0.0" y="0.0" xSize="0.55" ySize="1.0" xResolution="64" yResolution="48"/>
      <region id="right" x="0.45" y="0.0" xSize="0.55" ySize="1.0" xResolution="64" yResolution="48"/>
    </buffer>
  </display>
  <files>
    <fileset region="left">
      <geometryWarpFile>
        <path>left/warp.pfm</path>
        <interpolation>linear</interpolation>
        <originOf2DData>topLeft</originOf2DData>
      </geometryWarpFile>
      <alphaMap>
        <path>left/alpha.png</path>
        <componentDepth>1</componentDepth>
        <bitDepth>8</bitDepth>
        <gammaEmbedded>2.2</gammaEmbedded>
      </alphaMap>
    </fileset>
    <fileset region="right">
      <geometryWarpFile>
        <path>right/warp.pfm</path>
        <interpolation>linear</interpolation>
      </geometryWarpFile>
    </fileset>
  </files>
</MPCDI>
"""


def spec_file(tmp_path, xml: str = SPEC_XML, members: dict | None = None):
    """An MPCDI file laid out as the specification says, with another tool's choices: a
    big-endian warp of 5 x 4 samples, an 8-bit alpha map at half the output's size."""
    grid = np.zeros((4, 5, 3), np.float32)
    grid[..., 0], grid[..., 1] = np.linspace(0, 1, 5)[None, :], np.linspace(0, 1, 4)[:, None]
    grid[0, 0, :2] = np.nan  # the corner shows nothing
    alpha = np.tile(np.linspace(255, 0, 32).round().astype(np.uint8), (24, 1))
    files = {"mpcdi.xml": xml, "left/warp.pfm": big_endian_pfm(grid), "left/alpha.png": png(alpha),
             "right/warp.pfm": pfm.write(grid), **(members or {})}
    path = tmp_path / "other.mpcdi"
    with zipfile.ZipFile(path, "w") as z:
        for name, data in files.items():
            if data is not None:
                z.writestr(name, data)
    return path


def test_a_file_another_tool_wrote_is_read(tmp_path):
    size, (left, right) = mpcdi.read(spec_file(tmp_path))
    assert size == (1280, 480) and (left.name, right.name) == ("left", "right")
    assert left.size == (64, 48) and left.area == (0.0, 0.0, 0.55, 1.0) and right.area[0] == 0.45
    assert left.warp.shape == (4, 5, 2) and np.isnan(left.warp[0, 0]).all()
    assert left.warp[3, 4] == pytest.approx([1.0, 1.0]) and left.warp[1, 2] == pytest.approx([0.5, 1 / 3])
    # the alpha map: resampled from 32 x 24 to the output's 64 x 48 (said so), gamma taken off
    assert left.alpha.shape == (48, 64) and left.notes == [
        "alphaMap left/alpha.png of 32 x 24 resampled to the output's 64 x 48"]
    assert left.alpha[0, 0] == pytest.approx(1.0) and left.alpha[0, -1] == pytest.approx(0.0)
    assert left.alpha[10, 31] == pytest.approx(decode(np.linspace(255, 0, 32).round()[15:17]).mean(), abs=0.02)
    assert right.alpha is None and right.beta is None


@pytest.mark.parametrize("change,message", [
    ({"xml": SPEC_XML.replace('profile="2d"', 'profile="3d"')}, r"profile '3d' is not supported"),
    ({"xml": SPEC_XML.replace('<fileset region="right">', '<fileset region="middle">')},
     r"a fileset names region 'middle', which the buffer does not have \(its regions: left, right\)"),
    ({"xml": SPEC_XML.replace('<region id="right"', '<region id="right" ').replace(
        '<fileset region="right">', '<fileset region="left">')}, r"region 'right' has no fileset"),
    ({"members": {"left/warp.pfm": b"Pf\n5 4\n-1.0\n" + bytes(80)}}, r"warp left/warp.pfm has 1 channel"),
    ({"members": {"left/warp.pfm": pfm.write(np.zeros((1, 1, 3)))}}, r"is 1 x 1 samples for an output of 64 x 48"),
    ({"members": {"left/warp.pfm": pfm.write(np.full((4, 5, 3), np.nan))}}, r"every value of the PFM is NaN"),
    ({"members": {"left/warp.pfm": pfm.write(np.full((4, 5, 3), 40.0))}}, r"maps outside the content"),
    ({"members": {"left/warp.pfm": pfm.write(np.zeros((4, 5, 3)))[:60]}}, r"a truncated PFM"),
    ({"members": {"left/warp.pfm": b"P6\n5 4\n255\n" + bytes(60)}}, r"not a PFM file \(it starts with b'P6'"),
    ({"members": {"left/alpha.png": None}}, r"region 'left': its alphaMap 'left/alpha.png' is not in the file"),
])
def test_bad_files_are_refused_in_one_line(tmp_path, change, message):
    path = spec_file(tmp_path, change.get("xml", SPEC_XML), change.get("members"))
    with pytest.raises(InputError, match=message) as got:
        mpcdi.read(path)
    assert str(got.value).startswith(str(path)) and "\n" not in str(got.value)


def test_a_truncated_zip_is_refused_in_one_line(tmp_path):
    whole = spec_file(tmp_path).read_bytes()
    cut = tmp_path / "cut.mpcdi"
    cut.write_bytes(whole[: len(whole) // 2])
    with pytest.raises(InputError, match=r"cut.mpcdi: not a complete MPCDI \(ZIP\) file"):
        mpcdi.read(cut)


def test_pfm_round_trips_either_byte_order():
    img = np.random.default_rng(3).normal(size=(3, 4, 3)).astype(np.float32)
    assert np.array_equal(pfm.read(pfm.write(img), "a.pfm"), img)
    assert np.array_equal(pfm.read(big_endian_pfm(img), "b.pfm"), img)
    one = pfm.read(pfm.write(img[..., 0]), "c.pfm")
    assert one.shape == (3, 4, 1) and np.array_equal(one[..., 0], img[..., 0])
    assert struct.unpack("<f", pfm.write(img)[-4:])[0] == img[0, -1, 2]  # the top row last


def test_warp_make_writes_a_file_warp_check_reads(tmp_path, capsys):
    from multigpu.cli import main

    out = tmp_path / "dome.mpcdi"
    assert main(["warp", "make", str(out), "--screen", "cylinder", "--projectors", "2", "--size", "160x120"]) == 0
    size, got = mpcdi.read(out)
    assert [o.name for o in got] == ["p1", "p2"] and got[0].size == (160, 120) and size[1] < 120
    capsys.readouterr()
    assert main(["warp", "check", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"buffer     {size[0]}x{size[1]}, 2 regions") and sum("alpha" in s for s in lines) == 2
    for bad, flag in ((["--overlap", "0.6"], "--overlap"), (["--size", "12"], "--size"),
                      (["--projectors", "1"], "--projectors")):
        assert main(["warp", "make", str(tmp_path / "x.mpcdi"), *bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and flag in err[0]
    assert not (tmp_path / "x.mpcdi").exists()
    assert main(["warp", "check", str(tmp_path / "x.mpcdi")]) == 2
    # a wall's canvas: the screen takes its shape, the buffer its size; one too tall is refused
    assert main(["warp", "make", str(out), "--size", "160x120", "--canvas", "480x100"]) == 0
    assert mpcdi.read(out)[0] == (480, 100)
    capsys.readouterr()
    assert main(["warp", "make", str(tmp_path / "x.mpcdi"), "--size", "160x120", "--canvas", "480x400"]) == 2
    assert "--canvas a screen of aspect 1.2 is taller than 3 projectors" in capsys.readouterr().err


def test_a_wall_file_names_its_mpcdi_file_and_a_bad_one_ends_it_at_the_door(tmp_path, capsys):
    import json

    from multigpu.cli import main
    from multigpu.wall import load_wall

    mpcdi.write(tmp_path / "rig.mpcdi", (400, 100), outputs(flat_rig(2, 0.2, size=(64, 48)), (400, 100)))
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"mpcdi": "rig.mpcdi"}))
    got = load_wall(str(wall))
    assert got.mpcdi == str(tmp_path / "rig.mpcdi")
    # the tiles are the regions: two overlapping tiles across the buffer
    (rows, cols), (tw, th), (mx, my) = got.grid, got.tile, got.mullion
    assert (rows, cols, th, my) == (1, 2, 100, 0) and mx < 0 and 2 * tw + mx == 400
    assert main(["wall", "check", str(wall), "--offline"]) == 0
    said = capsys.readouterr().out
    assert "2 projector outputs on a 400x100 buffer" in said and "rank 0 p1 64x48, rank 1 p2 64x48" in said
    (tmp_path / "bad.mpcdi").write_bytes(b"PK\x03\x04 not a zip")
    for name, why in (("bad.mpcdi", "not a complete MPCDI (ZIP) file"), ("none.mpcdi", "no such file")):
        wall.write_text(json.dumps({"mpcdi": name}))
        with pytest.raises(InputError, match=re.escape(f"--wall {wall}: mpcdi: ") + f".*{re.escape(f'{name}: {why}')}"):
            load_wall(str(wall))


def test_a_projector_walls_tiles_are_its_regions_and_others_are_refused(tmp_path):
    import json

    from multigpu.flags import walk_config, walkthrough_parser
    from multigpu.wall import load_wall
    from multigpu.warp.layout import layout

    lay = layout("x", *mpcdi.read(spec_file(tmp_path)))  # another tool's: 0..704 and 576..1280 of 1280
    got = (lay.grid, lay.tile, lay.mullion, lay.labels, lay.overlap)
    assert got == ((1, 2), (704, 480), (-128, 0), (0, 1), (128, 0))
    for region, says in (('x="0.45" y="0.0" xSize="0.5"', "region 'right' is 640 pixels in x, 'left' 704"),
                         ('x="0.5" y="0.0" xSize="0.55"', "region 'right' spans 640.00..1344.00 of the buffer's 1280"),
                         ('x="0.4501" y="0.0" xSize="0.55"', "region 'right' spans 576.13..1280.13")):
        xml = SPEC_XML.replace('x="0.45" y="0.0" xSize="0.55"', region)
        with pytest.raises(InputError, match=re.escape(says)):
            layout("f.mpcdi", *mpcdi.read(spec_file(tmp_path, xml)))
    apart = SPEC_XML.replace('xSize="0.55" ySize="1.0" xResolution="64" yResolution="48"/>\n      <region id="right" '
                             'x="0.45"', 'xSize="0.4" ySize="1.0" xResolution="64" yResolution="48"/>\n      <region '
                             'id="right" x="0.6"')
    apart = apart.replace('x="0.6" y="0.0" xSize="0.55"', 'x="0.6" y="0.0" xSize="0.4"')
    with pytest.raises(InputError, match="leave 256 pixels between them in x"):
        layout("f.mpcdi", *mpcdi.read(spec_file(tmp_path, apart)))
    # a wall file: its grid and tile come from the regions; others, or a mullion, are refused at the door
    spec_file(tmp_path)
    wall = tmp_path / "wall.json"
    for doc, says in (({"tile": "640x480"}, "tile 640x480: the mpcdi file's regions make a 704x480 tile"),
                      ({"grid": "2x1"}, "its regions make a 1x2 grid: a wall of 2x1 ranks must divide it"),
                      ({"mullion": "0x0"}, "give no mullion or bezel")):
        wall.write_text(json.dumps({"mpcdi": "other.mpcdi", **doc}))
        with pytest.raises(InputError, match=re.escape(says)):
            load_wall(str(wall))
    wall.write_text(json.dumps({"mpcdi": "other.mpcdi", "grid": "1x2"}))
    assert load_wall(str(wall)).tile == (704, 480)
    assert walk_config(walkthrough_parser().parse_args(["--wall", str(wall), "--grid", "1x2"])).tile == (704, 480)
    with pytest.raises(InputError, match=re.escape("--tile a projector wall's tiles are its wall file's grid of its "
                                                   "mpcdi file's regions")):
        walk_config(walkthrough_parser().parse_args(["--wall", str(wall), "--tile", "320x240"]))
    with pytest.raises(InputError, match=re.escape("--stereo side-by-side: a projector wall")):
        walk_config(walkthrough_parser().parse_args(["--wall", str(wall), "--stereo", "side-by-side"]))


def test_a_stereo_projector_walls_right_eyes_file_makes_the_same_wall_or_is_refused(tmp_path):
    """``mpcdi_right`` (the right eyes' projectors): read beside ``mpcdi`` where its regions make the
    same wall; another wall, no ``mpcdi`` beside it or no such file end the job at the door, in one
    line; a run needs ``--stereo passive --eyes own``."""
    import json

    from multigpu.flags import walk_config, walkthrough_parser
    from multigpu.wall import load_wall
    from multigpu.warp.make import buffer_size

    for name, n, overlap in (("two", 2, 0.2), ("other", 2, 0.2), ("three", 3, 0.2), ("wide", 2, 0.3)):
        rig = flat_rig(n, overlap, size=(64, 48))
        mpcdi.write(tmp_path / f"{name}.mpcdi", buffer_size(rig), outputs(rig, buffer_size(rig)))
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"mpcdi": "two.mpcdi", "mpcdi_right": "other.mpcdi"}))
    assert load_wall(str(wall)).mpcdi_right == str(tmp_path / "other.mpcdi")
    cfg = walk_config(walkthrough_parser().parse_args(["--wall", str(wall), "--stereo", "passive", "--eyes", "own",
                                                       "--screen-size", "1.2,0.4"]))
    assert cfg.mpcdi_right == str(tmp_path / "other.mpcdi") and cfg.processes == 4
    with pytest.raises(InputError, match=re.escape("mono: the wall file's mpcdi_right (the right eyes' projectors) "
                                                   "needs --stereo passive --eyes own")):
        walk_config(walkthrough_parser().parse_args(["--wall", str(wall)]))
    for doc, says in (({"mpcdi": "two.mpcdi", "mpcdi_right": "three.mpcdi"}, "three.mpcdi: its regions make a 1x3"),
                      ({"mpcdi": "two.mpcdi", "mpcdi_right": "wide.mpcdi"}, "wide.mpcdi's regions make a 1x2 wall of "),
                      ({"mpcdi_right": "two.mpcdi"}, "mpcdi_right: give mpcdi too"),
                      ({"mpcdi": "two.mpcdi", "mpcdi_right": "gone.mpcdi"}, "gone.mpcdi: no such file")):
        wall.write_text(json.dumps(doc))
        with pytest.raises(InputError, match=re.escape(says)):
            load_wall(str(wall))
