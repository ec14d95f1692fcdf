"""Bezels in one process: canvas geometry, the canvas -> visible mapping (exact pixel sets, the
extremes), work cut at tile borders (hidden pixels never rendered, every visible one once), and
wall files (every error names the file and the entry; flags override the file)."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core.canvas import Canvas
from multigpu.core.regions import pixel_spans
from multigpu.errors import InputError


def test_canvas_geometry_follows_the_design():
    c = Canvas((2, 3), (100, 50), (10, 4))
    assert c.size == (3 * 100 + 2 * 10, 2 * 50 + 4) and c.visible == (300, 100)
    tiles = c.tiles()
    # label = col*rows + row, row 0 at the top: label 0 is top-left, label 1 bottom-left
    assert tiles[0].tolist() == [0, 54, 100, 104] and tiles[1].tolist() == [0, 0, 100, 50]
    assert tiles[5].tolist() == [220, 0, 320, 50]
    hid = c.hidden()
    assert hid.sum() == c.size[0] * c.size[1] - 6 * 100 * 50
    assert hid[:, 100:110].all() and hid[50:54].all() and not hid[0, :100].any()


def test_no_mullions_is_the_identity():
    c = Canvas((2, 2), (64, 48))
    r = np.random.default_rng(0).random((10, 4))
    assert c.to_visible(r) is r


def _canvas_pixels(rect, canvas):
    """Visible pixels (as visible coordinates) a normalized canvas rect covers, by brute force."""
    W, H = canvas.size
    x0, y0, x1, y1 = rect
    if x1 < 0 or x0 > 1 or y1 < 0 or y0 > 1:
        return set()
    cx = range(max(int(np.floor(x0 * W)), 0), min(int(np.floor(x1 * W)), W - 1) + 1)
    cy = range(max(int(np.floor(y0 * H)), 0), min(int(np.floor(y1 * H)), H - 1) + 1)
    hid = canvas.hidden()[::-1]  # bottom row first
    (tw, th), (mx, my) = canvas.tile, canvas.mullion
    return {(x - (x // (tw + mx)) * mx, y - (y // (th + my)) * my) for x in cx for y in cy if not hid[y, x]}


@settings(max_examples=300, deadline=None)
@given(grid=st.tuples(st.integers(1, 3), st.integers(1, 3)), tile=st.tuples(st.integers(1, 9), st.integers(1, 9)),
       mullion=st.tuples(st.integers(0, 5), st.integers(0, 5)),
       a=st.tuples(*[st.floats(-0.3, 1.3, allow_nan=False)] * 4))
def test_mapped_rects_keep_exactly_the_visible_pixels(grid, tile, mullion, a):
    """Every visible pixel an object may cover on the canvas is covered after the mapping; at
    most one pixel of slack per side (the rounding pad), never a pixel dropped."""
    c = Canvas(grid, tile, mullion)
    rect = (min(a[0], a[2]), min(a[1], a[3]), max(a[0], a[2]), max(a[1], a[3]))
    want = _canvas_pixels(rect, c)
    v = c.to_visible(np.array([rect]))
    spans, on = pixel_spans(v, c.visible)
    got = set()
    if on[0]:
        x0, y0, x1, y1 = spans[0].tolist()
        got = {(x, y) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)}
    assert want <= got
    if want:
        xs, ys = [p[0] for p in want], [p[1] for p in want]
        assert x0 >= min(xs) - 1 and x1 <= max(xs) + 1 and y0 >= min(ys) - 1 and y1 <= max(ys) + 1


def test_an_object_behind_a_bezel_is_invisible_and_nan_stays_nan():
    c = Canvas((1, 2), (100, 100), (20, 0))
    W = c.size[0]
    rects = np.array([[102 / W, 0.2, 118 / W, 0.4], [np.nan] * 4, [95 / W, 0.1, 125 / W, 0.2]])
    v = c.to_visible(rects)
    assert np.isnan(v[0]).all() and np.isnan(v[1]).all()
    spans, on = pixel_spans(v, c.visible)
    # across the bezel: 95..99 | 100..105 (a pixel of slack from the rounding pad at most)
    assert on[2] and spans[2, 0] in (94, 95) and spans[2, 2] in (105, 106)


def _work(rects_per_rank, n=6):
    from multigpu.core.work import Work

    rng = np.random.default_rng(1)
    rects = tuple(np.asarray(r, dtype=np.int64).reshape(-1, 4) for r in rects_per_rank)
    masks = tuple(rng.random((len(r), n)) < 0.7 for r in rects)
    return Work(rects, masks, np.zeros(len(rects), dtype=np.int64))


def test_work_is_cut_at_tile_borders_onto_the_canvas():
    c = Canvas((2, 2), (10, 8), (3, 2))
    VW, VH = c.visible
    # four ranks splitting the visible space unevenly, regions crossing both bezels
    work = _work([[0, 0, 13, 5], [13, 0, 20, 5], [0, 5, 7, 16], [7, 5, 20, 16]])
    vrects = np.array([[0, 0, 1, 1], [0, 0, 0.2, 0.2], [0.9, 0.9, 1, 1], [0.4, 0.4, 0.6, 0.6],
                       [np.nan] * 4, [0.0, 0.6, 0.1, 0.7]])
    tris = np.arange(1, 7)
    out = c.to_canvas(work, vrects, tris)
    W, H = c.size
    cover = np.zeros((H, W), dtype=int)
    for r in out.rects:
        for x0, y0, x1, y1 in r:
            cover[y0:y1, x0:x1] += 1
    assert (cover[::-1] == ~c.hidden()).all()  # every visible pixel once, no hidden one
    spans = pixel_spans(vrects, c.visible)[0]
    for k in range(4):
        for rect, mask in zip(out.rects[k], out.masks[k]):
            assert not (mask & ~work.masks[k].any(axis=0)).any()  # never an object the plan did not give
        assert out.loads[k] == int((out.masks[k].astype(int) @ tris).sum())
    assert len(out.rects[3]) == 4 and spans is not None  # rank 3's region spans four tiles


def _wall(tmp_path, doc):
    p = tmp_path / "wall.json"
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return str(p)


@pytest.mark.parametrize("doc,needle", [
    ("{", "not JSON"),
    ([1, 2], "top level must be a JSON object"),
    ({"grid": "2x"}, "grid must be"),
    ({"tile": [0, 10]}, "tile must be"),
    ({"mullion": "-1x2"}, "mullion must be"),
    ({"walls": 1}, "unknown key 'walls'"),
    ({"displays": [{"display": ":0"}]}, "displays[0]: needs \"rank\""),
    ({"displays": [{"rank": 0}, {"rank": 0}]}, "displays[1]: rank 0 appears twice"),
    ({"displays": [{"rank": 0, "display": "zero"}]}, "displays[0]: display must be an X display name"),
    ({"displays": [{"rank": 0, "position": [1]}]}, "displays[0]: position must be [x, y]"),
    ({"displays": [{"rank": 0, "screen": 1}]}, "displays[0]: unknown key 'screen'"),
])
def test_wall_file_errors_name_the_file_and_the_entry(tmp_path, doc, needle):
    from multigpu.wall import load_wall

    path = _wall(tmp_path, doc)
    with pytest.raises(InputError) as err:
        load_wall(path)
    assert str(err.value).startswith(f"--wall {path}: ") and needle in str(err.value)
    assert "\n" not in str(err.value)


def test_wall_file_sets_the_wall_and_flags_override_it(tmp_path):
    from multigpu.cli import build_parser, walk_config

    path = _wall(tmp_path, {"grid": "1x2", "tile": [320, 200], "mullion": "12x0", "displays": [
        {"rank": 0}, {"rank": 1, "display": ":3.1", "position": [5, 6]}]})
    cfg = walk_config(build_parser().parse_args(["walkthrough", "--wall", path]))
    assert cfg.grid == (1, 2) and cfg.tile == (320, 200) and cfg.mullion == (12, 0)
    assert cfg.displays == (None, ":3.1") and cfg.positions == (None, (5, 6)) and cfg.canvas.size == (652, 200)
    cfg = walk_config(build_parser().parse_args(["walkthrough", "--wall", path, "--tile", "64x48",
                                                 "--mullion", "0x0"]))
    assert cfg.tile == (64, 48) and cfg.mullion == (0, 0) and cfg.grid == (1, 2)
    with pytest.raises(InputError, match="displays entry for rank 1, but the wall has ranks 0..0"):
        walk_config(build_parser().parse_args(["walkthrough", "--wall", path, "--grid", "1x1"]))
    with pytest.raises(InputError, match="no displays entry for rank 2, 3 of the 4-rank wall"):
        walk_config(build_parser().parse_args(["walkthrough", "--wall", path, "--grid", "2x2"]))


def test_wall_check_prints_the_layout(tmp_path, capsys):
    from multigpu.cli import main

    path = _wall(tmp_path, {"grid": "2x2", "tile": "1920x1080", "mullion": "40x40"})
    assert main(["wall", "check", path]) == 0
    out = capsys.readouterr().out
    assert "canvas 3880x2200 pixels (3840x2160 visible)" in out
    assert "   3   1   1  -            $DISPLAY     -  1960,1120" in out
    assert "|    rank 0    |    rank 2    |" in out and "ranks count down each column" in out
    assert main(["wall", "check", path, "--grid-only"]) == 0
    assert capsys.readouterr().out.strip() == "2x2"
    assert main(["wall", "check", str(tmp_path / "none.json")]) == 2
    assert "none.json: no such file" in capsys.readouterr().err


@pytest.mark.parametrize("flags,needle", [(["--mullion", "3"], "--mullion must look like MXxMY"),
                                          (["--present", "screen"], "--present must be one of headless, window"),
                                          (["--grid", "1x2", "--tile", "16384x8", "--mullion", "4000x0"],
                                           "exceeds 32768 pixels per side")])
def test_bad_display_flags_are_refused_at_the_door(flags, needle):
    from multigpu.cli import build_parser, walk_config

    with pytest.raises(InputError, match=needle):
        walk_config(build_parser().parse_args(["walkthrough", *flags]))


def test_overlapping_tiles_share_pixels_and_plan_on_the_canvas_itself():
    """A projector wall's tiles (a negative mullion): the canvas is the visible space, nothing is
    hidden, each tile is its region; with a dark tile, the pixels a live one shares stay shown."""
    c = Canvas((1, 3), (100, 50), (-30, 0))
    assert c.size == (240, 50) and c.visible == c.size and c.overlapping and not c.bezels and not c.cuts
    assert c.tiles().tolist() == [[0, 0, 100, 50], [70, 0, 170, 50], [140, 0, 240, 50]]
    assert not c.hidden().any()
    rects = np.array([[0.1, 0.0, 0.5, 1.0]])
    assert c.to_visible(rects) is rects  # no bezels: nothing to squeeze
    dark = Canvas((1, 3), (100, 50), (-30, 0), dark=(2,))
    hidden = dark.hidden()
    assert not hidden[:, :170].any() and hidden[:, 170:].all()
    for bad in (((0, 0), (-30, 10)), ((100, 50), (-100, 0))):
        with pytest.raises(ValueError):
            Canvas((1, 3), (100, 50) if bad[0] == (0, 0) else bad[0], bad[1])
