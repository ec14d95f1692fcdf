"""The operator's view on a PC of its own (display/remote.py), in one process: only a
connection that brings the run's token is shown, and every line the view sends is checked
before anything is called; a malformed or hostile one is refused with one line and the wall
goes on."""

import io
import json
import socket
import threading

import glfw
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.display.controls import Controls
from multigpu.display.remote import CLOSED, EVENTS, RemoteMonitor, admit, message


@given(st.binary(max_size=200))
@settings(max_examples=300, deadline=None)
def test_no_line_raises(line):
    kind, _ = message(line)
    assert kind in ("event", "closed", "refused")


_NUMBERS = (st.floats() | st.integers() | st.integers(min_value=10 ** 300, max_value=10 ** 1000)
            | st.integers(min_value=-(10 ** 1000), max_value=-(10 ** 300)) | st.sampled_from([-1, 1.5, 1e308, 40]))
_EVENTS = st.builds(lambda name, args: {"event": name, "args": args}, st.sampled_from(sorted(EVENTS)),
                    st.lists(_NUMBERS, max_size=5))


@given(st.recursive(st.none() | st.booleans() | _NUMBERS | st.text(max_size=12),
                    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner,
                                                                                  max_size=4), max_leaves=40)
       | _EVENTS)
@settings(max_examples=2000, deadline=None)
def test_any_json_is_an_event_glfw_could_give_or_refused(value):
    """Every line the view could send, big integers, wrong types and events of real names
    included: an event is replayed into the real ``Controls`` (a stub took anything), or refused."""
    try:
        text = json.dumps(value)
    except ValueError:  # an integer past Python's own limit for printing it
        text = '{"event": "on_key", "args": [' + "9" * 5000 + ", 0, 0, 0]}"
    kind, got = message(text.encode())
    if kind == "event":
        name, args = got
        assert name in EVENTS and len(args) == EVENTS[name]
        controls = Controls(glfw)
        getattr(controls, name)(None, *args)  # must not raise
        controls.take()
    elif kind == "closed":
        assert got in CLOSED


@pytest.mark.parametrize("line,want", [
    (b'{"event": "on_key", "args": [87, 0, 1, 0]}', "event"),
    (b'{"closed": "escape key"}', "closed"),
    (b'not json', "refused"),
    (b'[1, 2]', "refused"),
    (b'{"closed": "because"}', "refused"),  # once a KeyError in rank 0's frame loop
    (b'{"event": "__init__", "args": []}', "refused"),  # once called by name
    (b'{"event": "on_key", "args": [87]}', "refused"),
    (b'{"event": "_on_cursor", "args": [1e999, 0]}', "refused"),
    (b'{"event": "_on_cursor", "args": [true, 0]}', "refused"),
    (b'{"event": "_on_cursor", "args": [1, 2], "x": 1}', "refused"),
])
def test_lines(line, want):
    assert message(line)[0] == want


def _pair(token="secret"):
    """A RemoteMonitor connected to a listening socket of this process: (monitor, view side)."""
    srv = socket.create_server(("127.0.0.1", 0))
    got = {}
    t = threading.Thread(target=lambda: got.setdefault("conn", srv.accept()[0]), daemon=True)
    t.start()
    mon = RemoteMonitor(f"127.0.0.1:{srv.getsockname()[1]}", token)
    t.join(10)
    srv.close()
    return mon, got["conn"]


def test_hostile_lines_are_refused_and_the_wall_goes_on(capsys):
    mon, view = _pair()
    assert admit(view, "secret")
    controls = Controls(glfw)  # the real one: what the wall would do with each line
    mon.take_input(controls)
    view.sendall(b'garbage\n{"event": "close", "args": []}\n{"closed": "nope"}\n'
                 b'{"event": "_on_scroll", "args": [0, 1]}\n' + b"x" * 10000 + b"\n")
    import time

    for _ in range(50):  # the lines arrive: each poll reads what is there, waiting for nothing
        assert mon.poll() is None
        if mon.refused >= 4:
            break
        time.sleep(0.02)
    assert mon.refused == 4 and controls.take().input.speed_steps == 1  # the one good line, replayed
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 4 and all(ln.startswith("multigpu: the operator's view sent a message refused") for ln in err)
    view.sendall(b'{"closed": "escape key"}\n')
    for _ in range(50):
        if mon.poll():
            break
        time.sleep(0.02)
    assert mon.poll() == "escape key"
    mon.close()
    view.close()


def test_the_view_admits_only_the_runs_token():
    mon, view = _pair("right")
    assert not admit(view, "wrong")
    mon.close()
    view.close()
    a, b = socket.socketpair()
    a.sendall(b"right\n")
    assert admit(b, "right")
    a.close()
    b.close()


def test_the_view_starts_with_its_own_defaults_and_listens_on_loopback(monkeypatch):
    """Defect 4: ``--position`` defaulted to 0x0, which its check refused; it listened on every interface."""
    import multigpu.display.remote as remote
    from multigpu.cli import build_parser
    from multigpu.tools import monitor_view

    a = build_parser().parse_args(["monitor-view"])
    assert a.position == "0x0" and a.listen == "127.0.0.1"
    got = {}
    monkeypatch.setattr(remote, "serve", lambda *args: got.setdefault("args", args))
    monkeypatch.setattr("sys.stdin", io.StringIO("secret\n"))
    assert monitor_view(a) == 0 and got["args"] == (None, (0, 0), "secret", 0, "127.0.0.1")


def test_a_peer_that_trickles_its_token_is_dropped_at_its_own_deadline():
    """Defect 4: a peer sending a byte every few seconds held the view's accept loop for minutes."""
    import time

    a, b = socket.socketpair()
    stop = threading.Event()

    def trickle():
        while not stop.is_set():
            try:
                a.sendall(b"x")
            except OSError:
                return
            stop.wait(0.1)

    threading.Thread(target=trickle, daemon=True).start()
    t0 = time.monotonic()
    assert not admit(b, "secret", deadline=0.5)
    assert time.monotonic() - t0 < 2.0
    stop.set()
    a.close()
    b.close()


def test_a_view_that_stops_reading_is_dropped_and_found_again_never_a_stop(monkeypatch, capsys):
    """Defect 4: a send that timed out stopped the run as "window closed" (exit 0, no recovery)."""

    import numpy as np

    import multigpu.display.remote as remote

    monkeypatch.setattr(remote, "TIMEOUT", 0.3)
    monkeypatch.setattr(remote, "RETRY", 0.0)
    mon, view = _pair()  # the view side never reads
    img = np.zeros((600, 800, 3), np.uint8)
    for _ in range(200):
        mon.present(img)
        if mon.sock is None:
            break
    assert mon.sock is None and mon.closed is None and mon.poll() is None  # dropped, not stopped
    assert "not reading" in capsys.readouterr().err
    view.close()
    mon.close()


def test_a_flood_of_lines_is_replayed_a_frames_share_at_a_time():
    """Defect 6: the view's lines were read without a limit a frame."""
    import time

    from multigpu.display.remote import MOST_LINES

    mon, view = _pair()
    assert admit(view, "secret")
    controls = Controls(glfw)
    mon.take_input(controls)
    view.sendall(b'{"event": "_on_scroll", "args": [0, 1]}\n' * (3 * MOST_LINES))
    time.sleep(0.2)
    mon.poll()
    assert controls.take().input.speed_steps == MOST_LINES
    mon.poll()
    assert controls.take().input.speed_steps == MOST_LINES  # the rest, the next frames
    mon.close()
    view.close()
