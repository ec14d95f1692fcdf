"""The operator's view on a PC of its own (the wall file's ``monitor.host``): a viewer there
(``multigpu monitor-view``, started by the launcher through the remote shell) shows the frames
rank 0 sends it and sends back its keys and mouse, as if its window were one of rank 0's.

One TCP connection, rank 0 to the viewer. Rank 0 first sends the run's token (a line): the
launcher made it, gave it to the view on its standard input and to rank 0 in ``TOKEN_ENV``, and
the view drops a connection that does not bring it (one line on its console). Then each frame is
``F``, width and height (two uint32, little-endian) and the RGB pixels, bottom row first (what
``Monitor.present`` gets); back come lines of JSON: an input event (``{"event": name, "args":
[...]}``, one of the four glfw callbacks with its numbers, replayed into rank 0's ``Controls``) or
``{"closed": why}`` (``escape key``, ``window closed``, as a local monitor's window says: the run
stops the same way; a view whose connection drops counts as its window closed). Every line is
checked (``message``) before anything is called: a malformed or unknown one is refused with one
line on rank 0's console and the wall goes on. The viewer keeps listening after a connection
ends, so a wall restarted by ``--recover`` finds it again. Sockets and glfw only: no MPI.
"""

from __future__ import annotations

import hmac
import json
import math
import socket
import struct
import sys

import numpy as np

#: seconds rank 0 waits to reach the viewer, and for a frame to leave
TIMEOUT = 10.0
HEAD = struct.Struct("<cII")
#: where rank 0 finds the run's token (the launcher sets it; MULTIGPU_* reaches every rank)
TOKEN_ENV = "MULTIGPU_MONITOR_TOKEN"
#: the events a view may send, with how many numbers each takes (glfw's callbacks, the window left out)
EVENTS = {"on_key": 4, "_on_button": 3, "_on_cursor": 2, "_on_scroll": 2}
#: why a view may stop the run (a local monitor's window says the same)
CLOSED = ("escape key", "window closed")
#: the longest line a view may send (bytes): a longer one is dropped unread
MOST_LINE = 4096


def message(line: bytes) -> tuple[str, object]:
    """One line from a view, checked: ``("event", (name, args))``, ``("closed", why)``, or
    ``("refused", what is wrong)``. Nothing in it is called or looked up unchecked."""
    try:
        msg = json.loads(line)
    except (ValueError, UnicodeDecodeError):
        return "refused", "not JSON"
    if not isinstance(msg, dict):
        return "refused", "not a JSON object"
    if set(msg) == {"closed"}:
        why = msg["closed"]
        return ("closed", why) if why in CLOSED else ("refused", f"unknown close reason {str(why)[:40]!r}")
    if set(msg) != {"event", "args"}:
        return "refused", f"unknown fields {sorted(str(k)[:20] for k in msg)[:4]}"
    name, args = msg["event"], msg["args"]
    if not isinstance(name, str) or name not in EVENTS:
        return "refused", f"unknown event {str(name)[:40]!r}"
    if (not isinstance(args, list) or len(args) != EVENTS[name]
            or not all(isinstance(a, (int, float)) and not isinstance(a, bool) and math.isfinite(a) for a in args)):
        return "refused", f"{name} takes {EVENTS[name]} finite numbers"
    return "event", (name, args)


class RemoteMonitor:
    """Rank 0's side: ``present``, ``poll``, ``close`` as ``display.Monitor``; it is its own
    ``window`` for ``take_input`` (the events come over the connection)."""

    def __init__(self, address: str, token: str):
        from multigpu.errors import InputError

        host, _, port = address.rpartition(":")
        try:
            self.sock = socket.create_connection((host, int(port)), timeout=TIMEOUT)
            self.sock.sendall(token.encode() + b"\n")
        except (OSError, ValueError) as exc:
            raise InputError.of("monitor", f"cannot reach the operator's view at {address} ({exc})") from None
        self.sock.settimeout(TIMEOUT)
        self.window, self.controls, self.buf, self.closed = self, None, b"", None
        self.refused = 0  # lines refused so far

    def take_input(self, controls) -> None:
        """Where the view's events go: each checked event name to its one ``Controls`` method
        (a table, not a look-up by name)."""
        self.controls = controls
        self.handlers = {"on_key": controls.on_key, "_on_button": controls._on_button,
                         "_on_cursor": controls._on_cursor, "_on_scroll": controls._on_scroll}

    def present(self, img: np.ndarray) -> None:
        """Send ``img`` (bottom row first); a viewer gone ends the monitor (``poll`` says so)."""
        h, w = img.shape[:2]
        try:
            self.sock.sendall(HEAD.pack(b"F", w, h) + np.ascontiguousarray(img, dtype=np.uint8).tobytes())
        except OSError:
            self.closed = self.closed or "window closed"  # the view is gone (its connection dropped)

    def poll(self) -> str | None:
        """Replay the events that arrived (no wait); why the view wants the run to stop, or None."""
        self.sock.setblocking(False)
        try:
            while chunk := self.sock.recv(1 << 16):
                self.buf += chunk
            self.closed = self.closed or "window closed"
        except BlockingIOError:
            pass
        except OSError:
            self.closed = self.closed or "window closed"  # the view is gone (its connection dropped)
        finally:
            self.sock.settimeout(TIMEOUT)
        *lines, self.buf = self.buf.split(b"\n")
        if len(self.buf) > MOST_LINE:  # a line with no end: dropped, not kept growing
            lines.append(self.buf[:MOST_LINE] + b"...")
            self.buf = b""
        for line in lines:  # events since the last frame, a handful
            if len(line) > MOST_LINE:
                kind, value = "refused", f"a line of {len(line)} bytes"
            else:
                kind, value = message(line)
            if kind == "closed":
                self.closed = self.closed or value
            elif kind == "event" and self.controls is not None:
                name, args = value
                self.handlers[name](None, *args)
            elif kind == "refused":
                self.refused += 1
                print(f"multigpu: the operator's view sent a message refused ({value}); the wall goes on",
                      file=sys.stderr, flush=True)
        return self.closed

    def close(self) -> None:
        self.sock.close()


class _Recorder:
    """The viewer's stand-in for ``Controls``: every call glfw makes is sent to rank 0."""

    def __init__(self, glfw, conn: socket.socket):
        self.glfw, self.conn = glfw, conn

    def attach_mouse(self, window) -> None:
        g = self.glfw
        g.set_mouse_button_callback(window, self._on_button)
        g.set_cursor_pos_callback(window, self._on_cursor)
        g.set_scroll_callback(window, self._on_scroll)

    def _send(self, name: str, args) -> None:
        try:
            args = [int(a) if isinstance(a, (bool, int)) else float(a) for a in args]  # glfw's keys, codes, positions
            self.conn.sendall((json.dumps({"event": name, "args": args}) + "\n").encode())
        except OSError:
            pass

    def on_key(self, window, *args) -> None:
        self._send("on_key", args)

    def _on_button(self, window, *args) -> None:
        self._send("_on_button", args)

    def _on_cursor(self, window, *args) -> None:
        self._send("_on_cursor", args)

    def _on_scroll(self, window, *args) -> None:
        self._send("_on_scroll", args)


def _read(conn: socket.socket, n: int) -> bytes | None:
    data = b""
    while len(data) < n:
        chunk = conn.recv(n - len(data))
        if not chunk:
            return None
        data += chunk
    return data


def admit(conn: socket.socket, token: str) -> bool:
    """Whether the connection's first line (at most 256 bytes, within ``TIMEOUT``) is ``token``;
    nothing but that line may come before the first frame."""
    got = _token_of(conn)
    return got is not None and hmac.compare_digest(got, token.encode())


def _token_of(conn: socket.socket) -> bytes | None:
    conn.settimeout(TIMEOUT)
    data = b""
    try:
        while b"\n" not in data and len(data) < 256:
            chunk = conn.recv(256 - len(data))
            if not chunk:
                return None
            data += chunk
    except OSError:
        return None
    line, _, rest = data.partition(b"\n")
    return line if not rest else None  # nothing may follow before the first frame's head


def serve(display: str | None, position: tuple[int, int], token: str, port: int = 0, listen: str = "") -> None:
    """The viewer: listen on ``listen``:``port`` (0: any; the port is printed as ``port N``),
    and show the frames of each connection that brings ``token`` in a window at ``position``
    on ``display`` until it ends; any other connection is dropped."""
    from multigpu.display.window import Window

    srv = socket.create_server((listen, port))
    print(f"port {srv.getsockname()[1]}", flush=True)
    while True:  # a connection per run of the wall (a restarted one connects again)
        conn, peer = srv.accept()
        if not admit(conn, token):
            print(f"multigpu monitor-view: refused a connection from {peer[0]} (no or wrong token)",
                  file=sys.stderr, flush=True)
            conn.close()
            continue
        conn.settimeout(None)
        window = None
        try:
            while (head := _read(conn, HEAD.size)) is not None:
                _, w, h = HEAD.unpack(head)
                pixels = _read(conn, w * h * 3)
                if pixels is None:
                    break
                if window is None or window.size != (w, h):
                    if window is not None:
                        window.close()
                    window = Window(0, (w, h), position, display, "the operator's view", title="multigpu monitor",
                                    vsync=False)
                    window.size = (w, h)
                    window.take_input(_Recorder(window.glfw, conn))
                window.show(np.frombuffer(pixels, dtype=np.uint8).reshape(h, w, 3))
                window.swap()
                why = window.poll()
                if why:
                    conn.sendall((json.dumps({"closed": why}) + "\n").encode())
        except OSError as exc:
            print(f"multigpu monitor-view: the connection dropped ({exc})", file=sys.stderr, flush=True)
        finally:
            if window is not None:
                window.close()
            conn.close()
