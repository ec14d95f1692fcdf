"""Every door from outside, fuzzed (DESIGN.md, "Doors"): the tracker's datagrams, the remote
view's lines, the panel's messages, wall files, pose files and pieces on the wire. Each door
either takes an input, refuses it (a reason, one rate-limited line) or refuses the run at the
start with one line (InputError, exit 2): nothing raises anything else. The generators make what
the old checks missed: integers of hundreds of digits, nesting thousands deep, NaN, Infinity,
numbers where none fit and values of the wrong type. Each door runs at least 2,000 inputs."""

from __future__ import annotations

import json
import socket

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from multigpu.core import doors, wire
from multigpu.errors import InputError

FUZZ = settings(max_examples=2000, deadline=None, suppress_health_check=list(HealthCheck))

#: numbers of every kind a hostile peer may send: huge integers, floats at and past the limits
NUMBERS = st.one_of(st.integers(), st.integers(min_value=10 ** 17, max_value=10 ** 700),
                    st.integers(max_value=-10 ** 300), st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([1e308, -1e308, 5e-324, 0.5, -1]))
LEAVES = st.one_of(st.none(), st.booleans(), NUMBERS, st.text(max_size=12))
JSONISH = st.recursive(LEAVES, lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner,
                                                                                         max_size=4), max_leaves=20)


def _text(value) -> str:
    """``value`` as JSON text, Python's way: NaN and Infinity written as such."""
    try:
        return json.dumps(value)
    except ValueError:  # an int past Python's digit limit for str: write it as text
        return "1" + "0" * 5000


DEEP = (st.integers(1, 4000).map(lambda d: "[" * d + "]" * d)
        | st.integers(1, 4000).map(lambda d: '{"a":' * d + "1" + "}" * d))
BIG = st.integers(20, 900).map(lambda n: "1" * n)
#: a message as text: valid-looking JSON of every kind, deep nesting, huge integers in place
MESSAGES = st.one_of(JSONISH.map(_text), DEEP, BIG, st.binary(max_size=300),
                     st.builds(lambda big, name: json.dumps({"event": name, "args": [0, 0, 0, 0]}).replace("0", big, 1),
                               BIG, st.sampled_from(["on_key", "_on_button", "_on_cursor", "_on_scroll"])),
                     st.builds(lambda big, action: json.dumps({"do": action, "steps": 1, "dx": 0, "dy": 0, "value": 1})
                               .replace("1", big, 1), BIG, st.sampled_from(["speed", "drag", "render_scale"])))


# -- the one validator


@FUZZ
@given(MESSAGES)
def test_parse_json_never_raises_and_bounds_what_it_takes(data):
    got = doors.parse_json(data, 1 << 20)
    if not isinstance(got, doors.Refusal):
        assert doors._depth(got, doors.MOST_DEPTH)
        json.dumps(got, allow_nan=False)  # no NaN, no Infinity, every int printable


@pytest.mark.parametrize("text,why", [
    ("1" * 400, "digits"), ("[" * 1500 + "]" * 1500, "nested"), ("NaN", "NaN"), ("[Infinity]", "Infinity"),
    ("1e999", "out of range"), (b"\xff", "not UTF-8"), ("{", "not JSON"), ("x" * 5000, "bytes"),
])
def test_parse_json_refuses_with_a_reason(text, why):
    got = doors.parse_json(text, 4096)
    assert isinstance(got, doors.Refusal) and why in got


def test_is_number_takes_a_huge_integer_without_raising():
    assert not doors.is_number(10 ** 400) and not doors.is_number(float("nan")) and not doors.is_number(True)
    assert doors.is_number(3) and doors.is_number(-2.5, -3, 3) and not doors.is_number(4, -3, 3)


def test_refusals_are_rate_limited_and_counted(capsys):
    clock = [0.0]
    r = doors.Refusals("x: ", per_minute=3, clock=lambda: clock[0])
    for _ in range(10):
        r.refuse("bad")
    clock[0] = 61.0
    r.refuse("bad")
    err = capsys.readouterr().err.splitlines()
    assert r.count == 11 and len(err) == 4 and err[-1] == "x: bad (7 more not said)"


# -- the head tracker's datagrams


@FUZZ
@given(MESSAGES)
def test_a_tracker_datagram_is_a_pose_or_a_reason(data):
    from multigpu.core.eyes import Pose
    from multigpu.rank.head_link import _parsed

    got = _parsed(data.encode("utf-8", "replace") if isinstance(data, str) else data)
    assert isinstance(got, (Pose, str))


def test_a_datagram_of_a_huge_integer_leaves_the_wall_running_and_a_flood_is_read_in_bounds():
    """Defect 1: a 300-digit integer once raised OverflowError out of the tracker's drain."""
    from multigpu.core.eyes import Viewer
    from multigpu.rank.head_link import MOST_PER_FRAME, HeadLink

    class _One:
        def Get_size(self):  # noqa: N802
            return 1

    sock = HeadLink.listen("127.0.0.1", 0)
    link = HeadLink(_One(), sock, Viewer((2.0, 1.0)), 5.0)
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    to = sock.getsockname()
    out.sendto(b'{"position": [0, 0, 2]}', to)
    out.sendto(b'{"position": [0, 0, 1' + b"0" * 300 + b']}', to)
    out.sendto(b"[" * 1500 + b"]" * 1500, to)
    import time

    time.sleep(0.1)
    pose, _ = link.pose()
    assert pose.position == (0.0, 0.0, 2.0) and link.refused == 2 and link.received == 1
    for i in range(3 * MOST_PER_FRAME):
        out.sendto(b'{"position": [0, 0, 3]}', to)
    time.sleep(0.1)
    link.pose()
    assert link.received == 1 + MOST_PER_FRAME  # one frame reads no more than its share
    link.close()
    out.close()


# -- the remote operator view's lines, replayed into the real Controls


def _controls():
    import glfw

    from multigpu.display.controls import Controls

    return Controls(glfw)


@FUZZ
@given(MESSAGES)
def test_a_remote_view_line_reaches_the_real_controls_or_is_refused(line):
    from multigpu.core.camera import Camera
    from multigpu.core.navigate import Input, Navigator
    from multigpu.display.remote import message

    data = line.encode("utf-8", "replace") if isinstance(line, str) else line
    kind, got = message(data)
    assert kind in ("event", "closed", "refused")
    if kind == "event":
        controls = _controls()
        name, args = got
        getattr(controls, name)(None, *args)
        taken = controls.take()
        assert isinstance(taken.input, Input)
        nav = Navigator((0, 0, 0), (1, 1, 1), Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), 60, 0.1, 10))
        cam = nav.step(taken.input, 0.016)
        assert np.isfinite(cam.position).all()


@pytest.mark.parametrize("line", [
    b'{"event": "on_key", "args": [87, 0, 1, 1.5]}',  # a float mods (mods & MOD_SHIFT)
    b'{"event": "_on_button", "args": [-1, 1, 0]}',  # a negative button (1 << button)
    b'{"event": "_on_scroll", "args": [0, 1e308]}',  # STEP ** huge
    b'{"event": "_on_cursor", "args": [1' + b"0" * 400 + b', 0]}',  # OverflowError
    b'{"event": "on_key", "args": [' + b"[" * 2000 + b"]" * 2000 + b"]}",  # RecursionError
])
def test_the_remote_views_crash_lines_are_refused(line):
    """Defect 2: each of these once raised inside rank 0's frame loop."""
    from multigpu.display.remote import message

    assert message(line)[0] == "refused"


def test_controls_and_the_navigator_take_the_extremes_glfw_could_give():
    from multigpu.core.camera import Camera
    from multigpu.core.navigate import Input, Navigator

    c = _controls()
    c._on_button(None, 40, 1, 0)  # out of glfw's range: ignored
    c._on_scroll(None, 0, 1e308)
    assert c.buttons == 0 and c.take().input.speed_steps == 10
    nav = Navigator((0, 0, 0), (1, 1, 1), Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), 60, 0.1, 10))
    for steps in (10 ** 6, -10 ** 6, 10 ** 400):  # a page that flooded speed steps between slow frames
        cam = nav.step(Input(speed_steps=steps), 0.016)
        assert np.isfinite(cam.position).all() and 0 < nav.speed <= 10 * nav.diag


# -- the operator's page


@FUZZ
@given(MESSAGES)
def test_a_panel_message_is_a_command_that_applies_or_a_refusal(text):
    from multigpu.panel.protocol import Command, Refused, command
    from multigpu.rank.panel_link import PanelLink

    got = command(text, ("strips", "cost"))
    assert isinstance(got, (Command, Refused))
    if isinstance(got, Command) and got.do not in ("record", "stop"):
        link = PanelLink.__new__(PanelLink)
        link.__init__(_State(), None, "", None, False)
        link._apply(got)
        link.flight(), link.head_moves()


class _State:
    def set_status(self, **kw):
        pass

    def event(self, text):
        pass


@pytest.mark.parametrize("text", ['{"do": "speed", "steps": 1' + "0" * 400 + "}",
                                  '{"do": "drag", "dx": ' + "[" * 3000 + "]" * 3000 + ', "dy": 0}',
                                  '{"do": "render_scale", "value": NaN}'])
def test_the_panels_crash_messages_are_refused(text):
    """Defect 3: ``command`` once raised on a huge integer and on deep nesting."""
    from multigpu.panel.protocol import Refused, command

    assert isinstance(command(text, ()), Refused)


def test_the_panel_knows_its_own_names_only():
    from multigpu.panel.protocol import known_host

    names = frozenset({"localhost", "wallpc"})
    assert known_host("127.0.0.1:8080", names) and known_host("[::1]:80", names) and known_host("wallpc:1", names)
    assert not known_host("evil.example:8080", names) and not known_host(None, names) and not known_host("", names)


def test_events_reach_a_page_after_the_list_is_trimmed():
    """Defect 15: after 200 events a page counting places in the trimmed list got none."""
    from multigpu.panel.state import MOST_EVENTS, PanelState

    state = PanelState({}, (), 2)
    seen = 0
    for i in range(3 * MOST_EVENTS):
        state.event(f"e{i}")
        seen, new = state.events_since(seen)
        assert [e for _, e in new] == [f"e{i}"]


# -- wall files and pose files


def _wall_docs():
    """Example walls with one field changed to a hostile value."""
    base = {"grid": "1x2", "tile": "64x48", "screen_m": [2.4, 0.9], "panel": "127.0.0.1:0",
            "stereo": {"mode": "anaglyph", "eye_separation_m": 0.05, "head_m": [0.1, 0.0, 2.0]},
            "displays": [{"rank": 0, "position": [0, 0]}, {"rank": 1, "position": [64, 0]}]}
    paths = [("grid",), ("tile",), ("screen_m",), ("screen_m", 0), ("panel",), ("stereo",), ("stereo", "mode"),
             ("stereo", "eye_separation_m"), ("stereo", "head_m"), ("stereo", "head_m", 2), ("stereo", "tracker"),
             ("displays",), ("displays", 0), ("displays", 0, "rank"), ("displays", 1, "position"), ("mullion",),
             ("bezel",), ("monitor",), ("compress",), ("displays", 0, "corners_m")]

    def put(value, path):
        doc = json.loads(json.dumps(base))
        node = doc
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
        return doc

    return st.builds(put, JSONISH | st.sampled_from(["99999", "0", "1e999", "nope", [1e308, 1e308, 1e308]]),
                     st.sampled_from(paths))


@FUZZ
@given(_wall_docs())
def test_a_wall_file_runs_or_is_refused_in_one_line(tmp_path_factory, doc):
    from multigpu.cli import build_parser, walk_config

    wall = tmp_path_factory.mktemp("wall") / "wall.json"
    wall.write_text(_text(doc))
    try:
        walk_config(build_parser().parse_args(["walkthrough", "--wall", str(wall)]))
    except InputError as exc:
        assert "\n" not in str(exc)


@pytest.mark.parametrize("field,value,words", [
    ("panel", "99999", "panel must look like"),  # once AttributeError: wall.path
    ("stereo", {"mode": "anaglyph", "tracker": "0"}, "stereo.tracker"),
    ("screen_m", [float("inf"), 1.0], "Infinity"),
    ("grid", "99999x99999", "tiles (at most 4096)"),  # once 23 GB of memory before any word
])
def test_a_wall_files_bad_field_names_the_file(tmp_path, field, value, words):
    """Defects 9 and 11."""
    from multigpu.cli import build_parser, walk_config

    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": "64x48", field: value}))
    with pytest.raises(InputError) as got:
        walk_config(build_parser().parse_args(["walkthrough", "--wall", str(wall)]))
    assert str(wall) in str(got.value) and words in str(got.value), str(got.value)


@pytest.mark.parametrize("z", [0.0, -1.0])
def test_corners_that_put_the_default_viewer_in_or_behind_the_screen_are_refused(tmp_path, z):
    """Defect 10: a flat wall in the plane z = 0 (the viewer inside it) divided by zero at the first
    frame; one facing away showed flipped frusta."""
    from multigpu.cli import build_parser, walk_config

    flip = 1.0 if z == 0.0 else -1.0  # -1: the screens face away from the room's origin
    corners = [[[-1, -0.5, z], [0, -0.5, z], [-1, 0.5, z]], [[0, -0.5, z], [1, -0.5, z], [0, 0.5, z]]]
    if flip < 0:
        corners = [[c[1], c[0], [c[1][0], 0.5, z]] for c in corners][::-1]
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": "64x48", "displays": [
        {"rank": r, "corners_m": corners[r]} for r in range(2)]}))
    with pytest.raises(InputError, match="room's origin"):
        walk_config(build_parser().parse_args(["walkthrough", "--wall", str(wall)]))
    walk_config(build_parser().parse_args(["walkthrough", "--wall", str(wall), "--head", f"0,0,{2 * flip}"]))


@FUZZ
@given(st.one_of(st.lists(JSONISH, max_size=4).map(_text), DEEP, BIG, JSONISH.map(_text)))
def test_a_pose_file_is_read_or_refused_in_one_line(tmp_path_factory, text):
    from multigpu.viewing import read_poses

    path = tmp_path_factory.mktemp("poses") / "head.json"
    path.write_text(text)
    try:
        read_poses(str(path))
    except InputError as exc:
        assert str(exc).startswith(f"--head-poses {path}: ") and "\n" not in str(exc)


# -- pieces on the wire


@FUZZ
@given(st.sampled_from(["none", "lz4", "zstd"]), st.integers(0, 2 ** 32 - 1),
       st.sampled_from(["cut", "flip", "pad", "head"]))
def test_a_spoilt_piece_is_refused_never_composed(codec, seed, how):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 9000))
    packed = (rng.integers(0, 4, n, dtype=np.uint8) * 60).astype(np.uint8)  # compressible, or not
    msg = wire.encode(packed.copy(), wire.parse(codec) if codec != "none" else wire.RAW)
    box = np.full(wire.bound(n), 0xA5, np.uint8)  # a receive buffer: what was there before stays
    sent = msg.copy()
    if how == "cut":
        sent = sent[:int(rng.integers(0, sent.nbytes))]
    elif how == "flip":
        at = int(rng.integers(0, sent.nbytes))
        sent[at] ^= np.uint8(1 << int(rng.integers(0, 8)))
    elif how == "pad":
        sent = np.concatenate([sent, np.zeros(int(rng.integers(1, 9)), np.uint8)])[:box.nbytes]
    else:
        sent[int(rng.integers(0, wire.HEADER_BYTES))] ^= np.uint8(0xFF)
    box[:sent.nbytes] = sent
    try:
        got, _ = wire.decode(box, n, sent.nbytes)
    except wire.WireError:
        return
    assert (got == packed).all()  # taken only where it is what was sent (a flip in a spare byte)


def test_a_raw_piece_cut_short_or_flipped_is_found():
    """Defect 7: a raw piece had no checksum, and a short one was composed from leftover memory."""
    packed = np.arange(1000, dtype=np.uint8)
    msg = wire.encode(packed.copy(), wire.AUTO)
    assert wire.header(msg)[0] == 0  # under 4 kB: raw
    box = np.zeros(wire.bound(1000), np.uint8)
    box[:msg.nbytes - 10] = msg[:-10]
    with pytest.raises(wire.WireError, match="short"):
        wire.decode(box, 1000, msg.nbytes - 10)
    with pytest.raises(wire.WireError, match="checksum"):  # the count unknown: the leftover bytes fail the CRC
        wire.decode(box, 1000)
    bad = msg.copy()
    bad[-1] ^= 1
    with pytest.raises(wire.WireError, match="checksum"):
        wire.decode(bad, 1000, bad.nbytes)


def test_an_lz4_frame_that_claims_another_size_is_refused_before_decoding():
    """Defect 8."""
    import lz4.frame

    packed = np.zeros(10_000, np.uint8)
    msg = wire.encode(packed.copy(), wire.parse("lz4"))
    big = lz4.frame.compress(bytes(10 ** 7), store_size=True, content_checksum=True)
    head = bytearray(msg[:wire.HEADER_BYTES].tobytes())
    head[24:32] = len(big).to_bytes(8, "little")
    forged = np.frombuffer(bytes(head) + big, np.uint8)
    with pytest.raises(wire.WireError, match="says 10000000 bytes"):
        wire.decode(forged, 10_000, forged.nbytes)
