"""A wall file that describes the installation: hosts, displays and positions per rank, what
``wall check`` catches, and the launcher placing the ranks from the file (no MPI started)."""

import json
import re
from pathlib import Path

import pytest

from multigpu.errors import InputError
from multigpu.wall import hosts_of, load_wall
from multigpu.wall_check import picture, problems

TWO_PCS = {"grid": "2x2", "tile": "1920x1080", "mullion": "40x40", "displays": [
    {"rank": 0, "host": "pc1", "display": ":0", "position": [0, 0]},
    {"rank": 1, "host": "pc1", "display": ":0", "position": [0, 1080]},
    {"rank": 2, "host": "pc2", "display": ":0", "position": [0, 0]},
    {"rank": 3, "host": "pc2", "display": ":0", "position": [0, 1080]}]}


def _wall(tmp_path, doc) -> str:
    path = tmp_path / "wall.json"
    path.write_text(json.dumps(doc))
    return str(path)


def test_the_file_places_the_ranks_on_its_hosts(tmp_path):
    wall = load_wall(_wall(tmp_path, TWO_PCS))
    assert hosts_of(wall, 4) == [("pc1", 2), ("pc2", 2)]
    assert hosts_of(load_wall(_wall(tmp_path, {"grid": "1x2"})), 2) == []
    lines = picture(wall, (2, 2))
    assert lines[1] == "|    rank 0    |    rank 2    |" and lines[2] == "|     pc1      |     pc2      |"


def test_any_tile_on_any_host_a_pc_per_row(tmp_path):
    """Tiles 0 and 2 (the top row) on pc1, 1 and 3 on pc2: MPI fills pc1 with two processes, then
    pc2, and the processes drive tiles 0, 2, 1, 3 in turn; a file of consecutive tiles keeps the
    identity (today's files unchanged)."""
    from multigpu.wall import tile_order
    from multigpu.wall_check import describe

    doc = json.loads(json.dumps(TWO_PCS))
    doc["displays"][1].update(host="pc2")
    doc["displays"][2].update(host="pc1")
    wall = load_wall(_wall(tmp_path, doc))
    assert hosts_of(wall, 4) == [("pc1", 2), ("pc2", 2)]
    assert tile_order(wall, 4) == [0, 2, 1, 3]
    assert "drive the tiles 0, 2, 1, 3 in turn" in describe(wall, (2, 2), (1920, 1080), (0, 0))
    assert tile_order(load_wall(_wall(tmp_path, TWO_PCS)), 4) == [0, 1, 2, 3]
    assert tile_order(load_wall(_wall(tmp_path, {"grid": "2x2"})), 4) == [0, 1, 2, 3]


@pytest.mark.parametrize("change,needle", [
    (lambda d: d["displays"][3].pop("host"), "rank 3 names no host, but others do"),
    (lambda d: d["displays"][0].update(host="a b"), "displays[0]: host must be a host name"),
])
def test_hosts_that_cannot_be_placed_are_one_line(tmp_path, change, needle):
    doc = json.loads(json.dumps(TWO_PCS))
    change(doc)
    with pytest.raises(InputError, match=re.escape(needle)):
        hosts_of(load_wall(_wall(tmp_path, doc)), 4)


def test_check_finds_overlaps_screens_names_and_missing_displays(tmp_path):
    ok = load_wall(_wall(tmp_path, TWO_PCS))
    screens = lambda host, display: (1920, 2160)
    resolve = lambda host: "127.0.0.1"
    assert problems(ok, (2, 2), (1920, 1080), (40, 40), screens, resolve) == []
    doc = json.loads(json.dumps(TWO_PCS))
    doc["displays"][1]["position"] = [100, 500]  # on top of rank 0
    doc["displays"][3].pop("display")  # a remote rank without a display
    found = problems(load_wall(_wall(tmp_path, doc)), (2, 2), (1920, 1080), (40, 40), screens, resolve)
    assert any(f.startswith("ranks 0 and 1: their windows overlap on :0 of pc1") for f in found), found
    assert any(f.startswith("rank 3 on host pc2 has no display") for f in found), found
    small = lambda host, display: (1920, 1080)
    found = problems(ok, (2, 2), (1920, 1080), (40, 40), small, resolve)
    assert found == [f"rank {k}: its window 1920x1080 at 0,1080 is off the 1920x1080 screen :0 of pc{k // 2 + 1}"
                     for k in (1, 3)]

    def unknown(host):
        raise OSError("no such host")

    assert problems(ok, (2, 2), (1920, 1080), (40, 40), None, unknown) == [
        "host pc1: its name does not resolve (check it, or give its address)",
        "host pc2: its name does not resolve (check it, or give its address)"]
    one_screen = load_wall(_wall(tmp_path, {"grid": "1x2", "tile": "1920x1080", "displays": [
        {"rank": 0, "display": ":0.0"}, {"rank": 1, "display": ":0.1"}]}))
    found = problems(one_screen, (1, 2), (1920, 1080), (0, 0), lambda h, d: (1920, 1080), resolve)
    assert found == ["rank 1: its window 1920x1080 at 1920,0 is off the 1920x1080 screen :0.1 of this machine (no "
                     "position: it went to the tile's place on the canvas; give \"position\": [0, 0] for a screen "
                     "of its own)"]


def test_wall_check_refuses_in_one_line_and_prints_hosts_for_the_launcher(tmp_path, capsys, monkeypatch):
    from multigpu.cli import main

    monkeypatch.setattr("socket.gethostbyname", lambda host: "127.0.0.9")
    path = _wall(tmp_path, TWO_PCS)
    assert main(["wall", "check", path, "--hosts-only"]) == 0
    assert capsys.readouterr().out.strip() == "pc1:2,pc2:2"
    doc = json.loads(json.dumps(TWO_PCS))
    doc["displays"][1]["position"] = [0, 0]
    assert main(["wall", "check", _wall(tmp_path, doc)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ranks 0 and 1: their windows overlap" in err[0]


def test_the_launcher_takes_the_hosts_from_the_wall_file(tmp_path, capsys, monkeypatch):
    from multigpu.launcher import mpirun

    path = _wall(tmp_path, TWO_PCS)
    assert mpirun.wall_hosts(["walkthrough", "--wall", path], 4, None) == [("pc1", 2), ("pc2", 2)]
    assert mpirun.wall_hosts(["walkthrough", f"--wall={path}"], 4, [("pc1", 2), ("pc2", 2)]) == [("pc1", 2),
                                                                                                  ("pc2", 2)]
    with pytest.raises(InputError, match="places the ranks on pc1:2,pc2:2, but --hosts/--hostfile says a:4"):
        mpirun.wall_hosts(["walkthrough", "--wall", path], 4, [("a", 4)])
    monkeypatch.setenv("MULTIGPU_RSH", "/bin/false")  # the placement is probed like --hosts
    assert mpirun.main(["-n", "4", "walkthrough", "--wall", path, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("multigpu: error: host pc1: the remote shell '/bin/false pc1 true'")


def test_fullscreen_ranks_fill_their_screens_and_the_tile_must_match(tmp_path):
    doc = {"grid": "1x2", "tile": "1920x1080", "displays": [{"rank": 0, "display": ":0.0", "fullscreen": True},
                                                            {"rank": 1, "display": ":0.1", "fullscreen": True}]}
    wall = load_wall(_wall(tmp_path, doc))
    assert wall.fullscreen == {0, 1}
    assert problems(wall, (1, 2), (1920, 1080), (0, 0), lambda h, d: (1920, 1080), lambda h: "1.2.3.4") == []
    assert problems(wall, (1, 2), (1920, 1080), (0, 0), lambda h, d: (2560, 1440), lambda h: "1.2.3.4")[0] == (
        "rank 0: full screen on the 2560x1440 screen :0.0 of this machine, but the tile is 1920x1080: make the "
        "tile the monitor's size")
    doc["displays"][1]["fullscreen"] = "yes"
    with pytest.raises(InputError, match="fullscreen must be true or false"):
        load_wall(_wall(tmp_path, doc))


EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples" / "walls").glob("*.json"))


@pytest.mark.parametrize("path", [p for p in EXAMPLES if p.name != "wall.schema.json"], ids=lambda p: p.name)
def test_the_example_walls_pass_wall_check(path, capsys):
    """Every shipped example passes ``wall check --offline`` (no host look-up, no X asked) and
    names its own schema, which is the one the code checks against."""
    from multigpu.cli import main
    from multigpu.wall import SCHEMA

    assert main(["wall", "check", "--offline", str(path)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"\dx\d wall of (1920x1080 tiles|\d+x1080 tiles, overlapping)", out)
    assert (path.parent / json.loads(path.read_text())["$schema"]).resolve() == SCHEMA.resolve()


def test_the_schema_is_a_valid_json_schema():
    from jsonschema import Draft202012Validator

    from multigpu.wall import schema

    Draft202012Validator.check_schema(schema())


@pytest.mark.parametrize("doc,needle", [
    ({"grid": "2by2"}, "grid must be 'ROWSxCOLS' or [ROWS, COLS] with integers >= 1, got \"2by2\""),
    ({"displays": [{"rank": 0}, {"rank": 1, "host": "a b"}]}, "displays[1]: host must be a host name or address"),
    ({"displays": [{"rank": 0, "gpu": -1}]}, "displays[0]: gpu must be a GPU index >= 0"),
    ({"displays": [{"rank": -2}]}, "displays[0]: needs \"rank\": a rank label >= 0"),
    ({"bezel": {"bezel_to_bezel_mm": 3}}, "bezel must be {\"bezel_to_bezel_mm\""),
    ({"bezel": {"bezel_to_bezel_mm": 3, "pixel_pitch_mm": 0.5}, "mullion": "4x4"}, "mullion (pixels) or bezel"),
])
def test_a_wrong_wall_file_names_the_entry_and_the_key(tmp_path, doc, needle):
    with pytest.raises(InputError) as e:
        load_wall(_wall(tmp_path, doc))
    assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_bezels_in_millimetres_become_mullion_pixels(tmp_path):
    from multigpu.wall import bezel_mullion

    by_pitch = load_wall(_wall(tmp_path, {"bezel": {"bezel_to_bezel_mm": [3.5, 7.0], "pixel_pitch_mm": 0.5}}))
    assert bezel_mullion(by_pitch, (1920, 1080)) == (7, 14)
    by_panel = load_wall(_wall(tmp_path, {"bezel": {"bezel_to_bezel_mm": 6, "panel_mm": [960, 540]}}))
    assert bezel_mullion(by_panel, (1920, 1080)) == (12, 12)  # 0.5 mm pixels
    assert bezel_mullion(load_wall(_wall(tmp_path, {"grid": "1x2"})), (10, 10)) is None


def test_a_gpu_per_rank_reaches_the_configuration(tmp_path):
    from multigpu.cli import build_parser
    from multigpu.flags import walk_config

    path = _wall(tmp_path, {"grid": "1x2", "displays": [{"rank": 0, "gpu": 1}, {"rank": 1}]})
    cfg = walk_config(build_parser().parse_args(["walkthrough", "--wall", path]))
    assert cfg.gpus == (1, None)
    from multigpu.rank.presenters import screen_of

    assert screen_of(":0", 1) == ":0.1" and screen_of(":0.2", 1) == ":0.2" and screen_of(":3", None) == ":3"


def test_the_wall_file_places_the_operators_view(tmp_path):
    """``--monitor`` without a value opens where the wall file's monitor says; a flag value wins."""
    from multigpu.cli import build_parser
    from multigpu.flags import walk_config

    path = _wall(tmp_path, {"grid": "1x2", "monitor": {"position": [100, 800]}})
    parse = lambda *extra: walk_config(build_parser().parse_args(["walkthrough", "--wall", path, "--present", "window",
                                                                  *extra]))
    assert parse("--monitor").monitor == (100, 800)
    assert parse("--monitor", "5,6").monitor == (5, 6)
    assert parse().monitor is None  # the file places the view; the flag asks for it


def test_the_wall_file_chooses_compression_and_the_flag_wins(tmp_path):
    """The wall file's ``compress`` reaches the configuration where no flag is given; ``--compress``
    overrides it; neither given: auto. A value the wire does not know is one line naming the key."""
    from multigpu.cli import build_parser
    from multigpu.flags import walk_config

    parse = lambda path, *extra: walk_config(build_parser().parse_args(["walkthrough", "--wall", path, *extra]))
    path = _wall(tmp_path, {"grid": "1x2", "compress": "zstd:3"})
    assert parse(path).compress == "zstd:3" and parse(path, "--compress", "none").compress == "none"
    assert parse(_wall(tmp_path, {"grid": "1x2"})).compress == "auto"
    with pytest.raises(InputError, match=r"compress must be auto, none, lz4, zstd or zstd:LEVEL.*got \"gzip\""):
        load_wall(_wall(tmp_path, {"grid": "1x2", "compress": "gzip"}))


def test_a_passive_walls_right_eye_windows_are_placed_and_checked(tmp_path):
    """A passive tile's second window: where the file puts it, else beside the wall; an overlap
    with a left-eye window, or a screen too narrow for it, is a problem naming that window."""
    doc = json.loads((EXAMPLES[0].parent / "passive-projectors.json").read_text())
    del doc["$schema"]
    wall = load_wall(_wall(tmp_path, doc))
    assert wall.right_eye == {0: (1920, 0), 1: (1920, 0)}
    from multigpu.wall_check import describe
    assert describe(wall, (1, 2), (1920, 1080), (0, 0)).count("right eye's window at 1920,0") == 2
    resolve = lambda h: "1.2.3.4"  # noqa: E731
    assert problems(wall, (1, 2), (1920, 1080), (0, 0), lambda h, d: (3840, 1080), resolve) == []
    assert problems(wall, (1, 2), (1920, 1080), (0, 0), lambda h, d: (1920, 1080), resolve) == [
        f"rank {k}'s right-eye window 1920x1080 at 1920,0 is off the 1920x1080 screen :0 of pc{k + 1}: give its "
        "\"right_eye_position\", or a screen as wide as both eyes' walls" for k in (0, 1)]
    doc["displays"][0]["right_eye_position"] = [960, 0]
    assert "rank 0 and rank 0's right-eye window overlap on :0 of pc1" in problems(
        load_wall(_wall(tmp_path, doc)), (1, 2), (1920, 1080), (0, 0), None, resolve)[0]
    one = {"grid": "1x2", "tile": "64x48", "stereo": {"mode": "passive"}, "displays": [{"rank": 0}, {"rank": 1}]}
    from multigpu.wall_check import windows
    assert [w[2:4] for w in windows(load_wall(_wall(tmp_path, one)), (1, 2), (64, 48), (0, 0))] == [
        (0, 0), (64, 0), (128, 0), (192, 0)]  # the right eyes' wall beside the left eyes'
