"""The operator's view on a PC of its own (display/remote.py), in one process: only a
connection that brings the run's token is shown, and every line the view sends is checked
before anything is called; a malformed or hostile one is refused with one line and the wall
goes on."""

import json
import socket
import threading

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.display.remote import CLOSED, EVENTS, RemoteMonitor, admit, message


@given(st.binary(max_size=200))
@settings(max_examples=300, deadline=None)
def test_no_line_raises(line):
    kind, _ = message(line)
    assert kind in ("event", "closed", "refused")


@given(st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=12),
                    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner,
                                                                                  max_size=4), max_leaves=12))
@settings(max_examples=300, deadline=None)
def test_any_json_is_an_event_with_its_numbers_or_refused(value):
    kind, got = message(json.dumps(value).encode())
    if kind == "event":
        name, args = got
        assert name in EVENTS and len(args) == EVENTS[name]
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


class _Controls:
    def __init__(self):
        self.calls = []

    def __getattr__(self, name):
        return lambda *args: self.calls.append((name, args))


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
    controls = _Controls()
    mon.take_input(controls)
    view.sendall(b'garbage\n{"event": "close", "args": []}\n{"closed": "nope"}\n'
                 b'{"event": "_on_scroll", "args": [0, 1]}\n' + b"x" * 10000 + b"\n")
    import time

    for _ in range(50):  # the lines arrive: each poll reads what is there, waiting for nothing
        assert mon.poll() is None
        if mon.refused >= 4:
            break
        time.sleep(0.02)
    assert mon.refused == 4 and controls.calls == [("_on_scroll", (None, 0, 1))]
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
