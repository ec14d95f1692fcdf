"""The operator's page in one process: its protocol (every message checked, fuzzed), the server's
token, origin and file rules, a page that stops reading, the finished run's view, and the flag
and wall-file entry. The real run in a real browser is test_panel_mpi.py."""

from __future__ import annotations

import asyncio
import json
import socket
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.config import WalkConfig, read_panel
from multigpu.errors import InputError
from multigpu.panel.protocol import ACTIONS, MOST_MESSAGE, Command, Refused, admitted, command, same_origin
from multigpu.panel.server import PanelServer
from multigpu.panel.state import SERIES, PanelState, names, width

BALANCES = ("strips", "cost", "db")
VALID = [{"do": "pause"}, {"do": "resume"}, {"do": "stop"}, {"do": "balance", "name": "db"},
         {"do": "target_fps", "value": 30}, {"do": "target_fps", "value": None}, {"do": "render_scale", "value": 0.5},
         {"do": "lod_error", "value": 2.5}, {"do": "keys", "held": ["forward", "left"]}, {"do": "keys", "held": []},
         {"do": "drag", "dx": -12.5, "dy": 3}, {"do": "speed", "steps": -2}, {"do": "orbit"}, {"do": "reset"},
         {"do": "record", "on": False}, {"do": "head", "dx": 0.05, "dy": 0, "dz": -0.25}, {"do": "head_home"},
         {"do": "scene_pause"}, {"do": "scene_play"}, {"do": "scene_time", "value": -2.5}]
TAMPERED = ['{"do": "exec", "cmd": "rm -rf /"}', "not json", "[1, 2]", '"pause"', '{"do": "pause", "x": 1}',
            '{"do": "balance", "name": "../etc/passwd"}', '{"do": "render_scale", "value": 1e9}',
            '{"do": "render_scale", "value": "NaN"}', '{"do": "render_scale", "value": true}',
            '{"do": "drag", "dx": Infinity, "dy": 0}', '{"do": "keys", "held": ["forward", "__class__"]}',
            '{"do": "speed", "steps": 1.5}', '{"do": "head", "dx": 2, "dy": 0, "dz": 0}',
            '{"do": "head", "dx": 0.1}', '{"do": "lod_error"}', '{"do": null}', '{"do": {"do": "stop"}}',
            '{"do": "scene_time", "value": 1e300}', '{"do": "scene_time", "value": NaN}', '{"do": "scene_time"}',
            "x" * (MOST_MESSAGE + 1)]


def test_every_action_is_declared_and_accepted_with_its_fields():
    assert {m["do"] for m in VALID} == set(ACTIONS)
    for msg in VALID:
        got = command(json.dumps(msg), BALANCES)
        assert isinstance(got, Command) and got.do == msg["do"], (msg, got)
        assert got.args == {k: v for k, v in msg.items() if k != "do"}


@pytest.mark.parametrize("text", TAMPERED)
def test_tampered_messages_are_refused_with_a_reason(text):
    got = command(text, BALANCES)
    assert isinstance(got, Refused) and got.why


def test_a_binary_message_is_refused():
    assert isinstance(command(b'{"do": "stop"}', BALANCES), Refused)


_numbers = (st.integers() | st.integers(min_value=10 ** 300, max_value=10 ** 1000) | st.floats(allow_nan=True)
            | st.sampled_from([1e308, -1e308, 11, -11, 0.5]))
_json = st.recursive(st.none() | st.booleans() | _numbers | st.text(max_size=20),
                     lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=10), inner,
                                                                                  max_size=4), max_leaves=40)


def _dumps(value) -> str:
    try:
        return json.dumps(value)
    except ValueError:  # an integer past Python's own limit for printing it
        return '{"do": "speed", "steps": ' + "9" * 5000 + "}"


@settings(max_examples=2000, deadline=None)
@given(st.one_of(_json.map(_dumps), st.text(max_size=300),
                 st.integers(1, 3000).map(lambda d: '{"do": "drag", "dx": ' + "[" * d + "]" * d + ', "dy": 0}'),
                 st.fixed_dictionaries({"do": st.sampled_from(sorted(ACTIONS))}, optional={
                     "name": _json, "value": _json, "held": _json, "dx": _json, "dy": _json, "steps": _json,
                     "on": _json, "do2": _json}).map(_dumps)))
def test_no_message_raises_and_every_command_is_in_range(text):
    got = command(text, BALANCES)
    assert isinstance(got, (Command, Refused))
    if isinstance(got, Command):
        a = got.args
        if got.do == "render_scale":
            assert 0.25 <= a["value"] <= 1.0
        if got.do == "balance":
            assert a["name"] in BALANCES
        if got.do == "keys":
            assert all(isinstance(m, str) for m in a["held"])


def test_tokens_and_origins():
    assert admitted("abc", "abc") and not admitted("abd", "abc") and not admitted(None, "abc")
    assert same_origin("http://127.0.0.1:8000", "127.0.0.1:8000")
    assert same_origin(None, "127.0.0.1:8000")  # not a browser: the token decides
    assert not same_origin("http://evil.example", "127.0.0.1:8000")
    assert not same_origin("http://127.0.0.1:8001", "127.0.0.1:8000")
    assert not same_origin("file://", "127.0.0.1:8000")


def test_the_flag_and_the_wall_file(tmp_path):
    assert read_panel("8080") == ("127.0.0.1", 8080)  # safe by default
    assert read_panel("0.0.0.0:0") == ("0.0.0.0", 0)
    assert read_panel("[::1]:9000") == ("::1", 9000)
    for bad in ("", "x", "1.2.3.4:", "70000", "host:-1"):
        with pytest.raises(InputError):
            read_panel(bad)
    from multigpu.cli import build_parser
    from multigpu.flags import walk_config

    wall = tmp_path / "w.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": "64x64", "panel": "127.0.0.1:8765"}))
    cfg = walk_config(build_parser().parse_args(["walkthrough", "--wall", str(wall)]))
    assert cfg.panel == ("127.0.0.1", 8765)
    cfg = walk_config(build_parser().parse_args(["walkthrough", "--wall", str(wall), "--panel", "9000"]))
    assert cfg.panel == ("127.0.0.1", 9000)  # the flag wins
    wall.write_text(json.dumps({"grid": "1x2", "panel": "99999"}))  # past the schema, refused by read_panel
    with pytest.raises(InputError) as got:  # once AttributeError (wall.path) on every rank
        walk_config(build_parser().parse_args(["walkthrough", "--wall", str(wall)]))
    assert str(got.value).startswith(f"{wall}: panel must look like [ADDRESS:]PORT"), str(got.value)
    with pytest.raises(InputError, match="--path"):
        WalkConfig(path="interactive")  # no window and no page to fly from
    assert WalkConfig(path="interactive", panel=("127.0.0.1", 0)).panel == ("127.0.0.1", 0)


@pytest.fixture
def served():
    state = PanelState({"title": "t", "wall_pixels": [64, 32]}, BALANCES, 2)
    server = PanelServer(state, "127.0.0.1", 0, "tok")
    url = server.start()
    yield state, server, url
    server.close()


def _get(url: str, headers: dict | None = None) -> tuple[int, bytes, dict]:
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read(), dict(r.headers)
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read(), dict(exc.headers)


def test_the_server_wants_the_token_for_everything(served):
    state, server, url = served
    base = url.split("?")[0]
    assert url.endswith("?token=tok") and url.startswith("http://127.0.0.1:")
    assert _get(base)[0] == 403
    assert _get(base + "?token=nope")[0] == 403
    assert _get(base + "static/panel.js")[0] == 403
    code, body, headers = _get(url)
    assert code == 200 and b"panel.js" in body and "HttpOnly" in headers["Set-Cookie"]
    port = url.split(":")[2].split("/")[0]
    assert headers["Set-Cookie"].startswith(f"multigpu-panel-{port}=")  # one cookie per panel, not per host
    assert _get(url, {"Host": f"evil.example:{port}"})[0] == 421  # DNS rebinding: another name, token or not
    assert _get(url, {"Host": f"localhost:{port}"})[0] == 200
    cookie = {"Cookie": headers["Set-Cookie"].split(";")[0]}
    assert _get(base + "static/panel.js", cookie)[0] == 200  # the page's own files, with its cookie
    assert _get(base + "static/uPlot.iife.min.js", cookie)[0] == 200
    for other in ("static/../server.py", "static/server.py", "static/%2e%2e/server.py", "etc/passwd", "ws2"):
        assert _get(base + other, cookie)[0] in (403, 404), other


def _ws(url: str, origin: str | None = None):
    from websockets.asyncio.client import connect

    base = url.split("?")[0].replace("http", "ws") + "ws?" + url.split("?")[1]
    return connect(base, origin=origin, open_timeout=10)


def test_a_page_gets_the_run_and_its_commands_reach_the_loop(served):
    state, server, url = served
    state.add_row(np.arange(width(2), dtype=float))
    state.set_thumb(np.full((8, 16, 3), 200, np.uint8), [np.array([[0, 0, 32, 32]]), np.array([[32, 0, 64, 32]])], 4)
    state.set_status(paused=False)

    async def talk():
        async with _ws(url) as ws:
            got = {"bin": 0}
            while not ({"hello", "rows", "status"} <= set(got) and got["bin"]):
                m = await asyncio.wait_for(ws.recv(), 10)
                if isinstance(m, bytes):
                    got["bin"] += 1
                    assert m[:2] == b"\xff\xd8"  # a JPEG
                else:
                    got.update(json.loads(m))
            await ws.send(json.dumps({"do": "balance", "name": "cost"}))
            await ws.send('{"do": "exec"}')
            replies = []
            while len(replies) < 2:
                m = await asyncio.wait_for(ws.recv(), 10)
                m = json.loads(m) if isinstance(m, str) else {}
                if "ok" in m or "error" in m:
                    replies.append(m)
            return got, replies

    got, replies = asyncio.run(talk())
    assert got["hello"]["balances"] == list(BALANCES) and got["hello"]["ranks"] == 2
    assert got["rows"][0] == list(range(width(2))) and got["hello"]["series"] == names(2)
    assert replies[0] == {"ok": "balance"} and "unknown action" in replies[1]["error"]
    cmds = state.take_commands()
    assert cmds == [Command("balance", {"name": "cost"})] and state.take_commands() == []


def test_a_page_of_another_origin_is_refused(served):
    state, server, url = served
    from websockets.exceptions import InvalidStatus

    async def attempt():
        async with _ws(url, origin="http://evil.example"):
            pass

    with pytest.raises(InvalidStatus) as exc:
        asyncio.run(attempt())
    assert exc.value.response.status_code == 403


def _stalled_page(url: str) -> socket.socket:
    """A page that opens its WebSocket and then never reads a byte (a raw socket with a small
    receive buffer: a client library would keep reading into its own)."""
    import base64
    import os

    port = int(url.split(":")[2].split("/")[0])
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET /ws?{url.split('?')[1]} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                  f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
    assert sock.recv(12) == b"HTTP/1.1 101"
    return sock


def test_a_page_that_stops_reading_costs_the_loop_and_the_other_pages_nothing(served):
    """A page connects and never reads while the loop hands over thousands of rows and large
    thumbnails: every hand-over returns, and another page still gets the run (the stalled one
    only fills its own connection's buffer)."""
    state, server, url = served
    stalled = _stalled_page(url)
    img = np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    for i in range(3000):
        state.add_row(np.full(width(2), float(i)))
        if i % 10 == 0:
            state.set_thumb(img.copy(), None, 1)
    assert state.seq == 3000 and state.clients == 1

    async def another():
        async with _ws(url) as ws:
            rows = 0
            while rows < 1:
                m = await asyncio.wait_for(ws.recv(), 10)
                if isinstance(m, str) and "rows" in json.loads(m):
                    rows = len(json.loads(m)["rows"])
            return rows

    assert asyncio.run(another()) >= 1 and state.clients >= 1
    stalled.close()


def test_a_page_that_goes_away_lets_go_of_its_keys(served):
    """Defect 16: keys held on a page stayed held when it disconnected (a closed laptop flew on)."""
    state, server, url = served

    async def hold_and_go():
        async with _ws(url) as ws:
            await ws.send(json.dumps({"do": "keys", "held": ["forward"]}))
            while "ok" not in json.loads(await asyncio.wait_for(ws.recv(), 10)):
                pass

    asyncio.run(hold_and_go())
    for _ in range(100):
        cmds = state.take_commands()
        if cmds and cmds[-1] == Command("keys", {"held": []}):
            break
        time.sleep(0.05)
    assert cmds[-1] == Command("keys", {"held": []})


def test_a_finished_run_is_served_read_only(tmp_path, monkeypatch):
    from PIL import Image

    from multigpu.panel.finished import load, plot_rows
    from multigpu.records.report import COLUMNS, TimingWriter

    out = tmp_path / "run"
    (out / "mosaic").mkdir(parents=True)
    rows = np.zeros((6, len(COLUMNS)))
    rows[:, COLUMNS.index("frame")] = [0, 0, 1, 1, 2, 2]
    rows[:, COLUMNS.index("rank")] = [1, 0, 0, 1, 1, 0]
    rows[:, COLUMNS.index("frame_ms")] = [10, 20, 30, 40, 50, 60]
    rows[:, COLUMNS.index("rendering_cpu_ms")] = [1, 3, 2, 2, 4, 4]
    writer = TimingWriter(out / "timings.csv")
    for f in range(3):
        writer.write(rows[2 * f:2 * f + 2])
    writer.close()
    (out / "summary.json").write_text(json.dumps({"complete": True, "frames_written": 3, "ranks": 2,
                                                  "config": {"decomposition": "screen", "grid": [1, 2]}}))
    Image.new("RGB", (64, 32), (9, 9, 9)).save(out / "mosaic" / "frame_00000.png")
    state, mosaics = load(out)
    assert [p.name for p in mosaics] == ["frame_00000.png"]
    n, got = state.rows_since(0)
    assert n == 3 and got[:, 0].tolist() == [0, 1, 2]
    assert got[:, len(SERIES):len(SERIES) + 2].tolist() == [[20, 10], [30, 40], [60, 50]]  # frame time, by rank
    assert got[:, len(SERIES) + 2:].tolist() == [[3, 1], [2, 2], [4, 4]]  # render CPU time, by rank
    assert got[0, 4] == pytest.approx(1.5)  # imbalance: slowest render over the mean
    assert state.summary["frames_written"] == 3 and state.status["view"]
    assert plot_rows(np.zeros((0, len(COLUMNS))), 2).shape == (0, width(2))
    with pytest.raises(InputError, match="not a run"):
        load(tmp_path / "nothing")
    _view_refuses_and_bounds(out, monkeypatch)


def _view_refuses_and_bounds(out, monkeypatch):
    """Defect 13: a summary that is a list, or says a non-numeric or huge ``ranks``, gave a traceback;
    a mosaic past Pillow's bomb limit killed the thumbnail thread; a long run went as one message."""
    import threading

    from PIL import Image

    import multigpu.panel.finished as finished

    good = (out / "summary.json").read_text()
    for bad, words in (("[]", "not a JSON object"), ('{"ranks": "x"}', "ranks must be"),
                       ('{"ranks": 1' + "0" * 30 + "}", "ranks must be"), ('{"ranks": 0}', "ranks must be")):
        (out / "summary.json").write_text(bad)
        with pytest.raises(InputError, match=words):
            finished.load(out)
    (out / "summary.json").write_text(good)
    monkeypatch.setattr(finished, "MOST_PLOTTED", 2)
    state, mosaics = finished.load(out)
    assert state.rows_since(0)[1][:, 0].tolist() == [0, 2]  # every k-th frame, the last one kept
    assert state.rows_since(0, 1)[0] == 1  # a page gets a long history in pieces
    Image.new("RGB", (64, 32), (9, 9, 9)).save(out / "mosaic" / "frame_00001.png")
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 10)  # every mosaic is a "bomb" now
    stop = threading.Event()
    slides = threading.Thread(target=finished._slides, args=(state, sorted(mosaics), stop), daemon=True)
    slides.start()
    slides.join(0.5)
    assert slides.is_alive()  # skipped with one line, still showing the others
    stop.set()
    slides.join(5)


def test_a_page_that_floods_is_refused_beyond_its_rate(served):
    """A page that sends thousands of valid commands at once: the loop's queue gets at most the
    burst and what the rate refills while they arrive (timed here: a slow machine takes longer),
    the rest get an error reply."""
    from multigpu.panel.server import MOST_RATE

    state, server, url = served
    began = time.monotonic()

    async def flood():
        async with _ws(url) as ws:
            for _ in range(1000):
                await ws.send('{"do": "orbit"}')
            got = {"ok": 0, "error": 0}
            while got["ok"] + got["error"] < 1000:
                m = await asyncio.wait_for(ws.recv(), 10)
                if isinstance(m, str):
                    m = json.loads(m)
                    for k in got:
                        got[k] += k in m
            return got

    got = asyncio.run(flood())
    most = 2 * MOST_RATE + MOST_RATE * (time.monotonic() - began) + 1
    queued = len(state.take_commands())
    assert queued == got["ok"] and queued <= most and got["error"] >= 1000 - most, (got, most)


def test_the_page_offers_the_decompositions_the_exchange_has_room_for():
    """A shared segment is sized for the decomposition a run starts with: a screen run's page
    offers the strategies and bins (no depth), a db run's db too, a hybrid's every one; over
    messages, every one. Without a panel, B cycles what it always did."""
    from multigpu.planner import balances_of, most_of
    from multigpu.strategies import REGISTRY as STRATEGIES

    panel = ("127.0.0.1", 0)
    strategies = list(STRATEGIES)
    assert balances_of(WalkConfig()) == strategies
    assert balances_of(WalkConfig(decomposition="db")) == ["db"]
    assert balances_of(WalkConfig(panel=panel)) == [*strategies, "bins"]
    assert balances_of(WalkConfig(panel=panel, decomposition="db")) == [*strategies, "db", "bins"]
    assert balances_of(WalkConfig(panel=panel, decomposition="hybrid")) == [*strategies, "db", "bins", "hybrid"]
    assert balances_of(WalkConfig(panel=panel, exchange="messages")) == [*strategies, "db", "bins", "hybrid"]
    for cfg in (WalkConfig(panel=panel), WalkConfig(panel=panel, decomposition="db"),
                WalkConfig(panel=panel, decomposition="hybrid")):
        from multigpu.decompositions import REGISTRY

        own = REGISTRY[cfg.decomposition]
        assert most_of(cfg, balances_of(cfg)) == (own.depth, own.layers)  # no more room than it asked for
    tiny = WalkConfig(panel=panel, exchange="messages", grid=(2, 2), tile=(8, 8), bin_size=64)
    assert "bins" not in balances_of(tiny)  # fewer bins than ranks: left out


def test_the_page_moves_the_viewers_head_and_brings_it_home():
    """The page's head buttons reach the frame's control as the window's head keys do (a page's
    home first, then only its own moves)."""
    from multigpu.rank.panel_link import PanelLink
    from multigpu.rank.steer import Steering

    class _Comm:
        def Get_rank(self):
            return 0

        def Get_size(self):
            return 1

    state = PanelState({"title": "t", "wall_pixels": [64, 32]}, BALANCES, 1)
    link = PanelLink(state, None, "", None, False, viewer=True)
    steering = Steering(_Comm(), 1.0, list(BALANCES), 0, panel=link)

    def say(*msgs):
        for m in msgs:
            state.commands.put(command(json.dumps(m), BALANCES))
        return steering.next().head

    assert np.allclose(say({"do": "head", "dx": 0.05, "dy": 0.0, "dz": -0.05},
                           {"do": "head", "dx": 0.05, "dy": 0.25, "dz": 0.0}), (0.1, 0.25, -0.05))
    assert np.allclose(say(), (0.1, 0.25, -0.05))  # it stays where the page put it
    assert np.allclose(say({"do": "head_home"}), (0.0, 0.0, 0.0))
    assert np.allclose(say({"do": "head", "dx": 0.5, "dy": 0.0, "dz": 0.0}, {"do": "head_home"},
                           {"do": "head", "dx": 0.0, "dy": 0.05, "dz": 0.0}), (0.0, 0.05, 0.0))


def _link(tmp_path):
    """Rank 0's side of a page, without a server."""
    from multigpu.rank.panel_link import PanelLink

    return PanelLink(PanelState({}, BALANCES, 1), None, "", tmp_path, interactive=False)


def test_a_paused_run_still_hears_a_signal():
    """Defect 14: a run paused from the page ignored Ctrl-C and SIGTERM (the pause loop never looked)."""
    import threading

    from multigpu.rank.steer import Steering

    class _One:
        def Get_rank(self):  # noqa: N802
            return 0

        def Get_size(self):  # noqa: N802
            return 1

    link = _link(None)
    link._apply(Command("pause", {}))
    steering = Steering(_One(), 1.0, list(BALANCES), 0, panel=link)
    signalled = threading.Event()
    steering.stopping = signalled.is_set
    got = []
    t = threading.Thread(target=lambda: got.append(steering.next()), daemon=True)
    t.start()
    t.join(0.5)
    assert t.is_alive()  # paused: it waits
    signalled.set()  # SIGTERM reaches rank 0
    t.join(5)
    assert not t.is_alive() and got[0].paused_s > 0


def test_a_recording_after_a_restart_keeps_the_ones_before(tmp_path):
    """Defect 17: after a recovery the first recording from the page overwrote recorded-01.json."""
    (tmp_path / "recorded-01.json").write_text("kept")
    link = _link(tmp_path)
    link._apply(Command("record", {"on": True}))
    assert link.recording.path == tmp_path / "recorded-02.json"
    link._apply(Command("record", {"on": False}))
    assert (tmp_path / "recorded-01.json").read_text() == "kept"


def test_the_page_gets_a_simulations_colour_bar():
    """A scene coloured by a field: the page's header carries the field, its range and the map's
    colours (drawn beside the wall, ``colorBar`` in panel.js); a scene without one carries none."""
    from pathlib import Path

    from multigpu.rank.panel_link import header, legend

    meta = {"simulation": {"color_by": {"field": "p", "where": "cell", "range": [0.0, 2.0], "colormap": "viridis"}}}
    got = legend(meta)
    assert got["field"] == "p" and got["range"] == [0.0, 2.0] and len(got["colors"]) == 11
    assert (got["colors"][0], got["colors"][-1]) == ("#440154", "#fde725")  # viridis from end to end
    assert legend({}) is None
    cfg = WalkConfig(grid=(1, 2), tile=(8, 8))
    assert header(cfg, "t", BALANCES, got)["color_by"] == got and "color_by" not in header(cfg, "t", BALANCES)
    page = Path(__file__).resolve().parents[1] / "multigpu" / "panel" / "page"
    js, html = (page / "panel.js").read_text(), (page / "index.html").read_text()
    assert "colorBar(head.color_by)" in js and all(f'id="{i}"' in html for i in ("colorbar", "cbstrip", "cbname"))


def test_the_page_gets_a_series_step_and_whether_it_is_late():
    """A series playing: the page's status carries the step on the wall (from rank 0's landed row)
    and whether the wall holds it late; the header the series' step count; another run none."""
    from pathlib import Path

    from multigpu.rank.panel_link import PanelLink
    from multigpu.records.report import COLUMNS

    col = {c: i for i, c in enumerate(COLUMNS)}
    rows = np.zeros((2, len(COLUMNS) + 1))
    rows[:, col["step"]], rows[:, col["step_late"]] = 3, 1
    for steps, want in ((5, {"step": 3, "step_late": True}), (0, {})):
        state = PanelState({"title": "t"}, BALANCES, 2, [])
        link = PanelLink(state, None, "", Path("."), False, False, steps)
        link.landed(0, rows, col, None)
        link.status(None, BALANCES, type("F", (), {"target_fps": None, "scale": 1.0, "lod_error": 0.0})())
        assert {k: state.status[k] for k in ("step", "step_late") if k in state.status} == want
    page = Path(__file__).resolve().parents[1] / "multigpu" / "panel" / "page"
    js, html = (page / "panel.js").read_text(), (page / "index.html").read_text()
    assert "seen.header.series_steps" in js and all(f'id="{i}"' in html for i in ("step", "steps", "steplate"))
