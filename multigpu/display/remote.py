"""The operator's view on a PC of its own (the wall file's ``monitor.host``): a viewer there
(``multigpu monitor-view``, started by the launcher through the remote shell) shows the frames
rank 0 sends it and sends back its keys and mouse, as if its window were one of rank 0's.

One TCP connection, rank 0 to the viewer: each frame is ``F``, width and height (two uint32,
little-endian) and the RGB pixels, bottom row first (what ``Monitor.present`` gets); back come
lines of JSON: an input event (``{"event": name, "args": [...]}``, replayed into rank 0's
``Controls`` as glfw would have called them) or ``{"closed": why}`` (``escape key``, ``window
closed``, as a local monitor's window says: the run stops the same way; a view whose connection
drops counts as its window closed). The viewer keeps listening after a connection ends,
so a wall restarted by ``--recover`` finds it again. Sockets and glfw only: no MPI.
"""

from __future__ import annotations

import json
import socket
import struct
import sys

import numpy as np

#: seconds rank 0 waits to reach the viewer, and for a frame to leave
TIMEOUT = 10.0
HEAD = struct.Struct("<cII")


class RemoteMonitor:
    """Rank 0's side: ``present``, ``poll``, ``close`` as ``display.Monitor``; it is its own
    ``window`` for ``take_input`` (the events come over the connection)."""

    def __init__(self, address: str):
        from multigpu.errors import InputError

        host, _, port = address.rpartition(":")
        try:
            self.sock = socket.create_connection((host, int(port)), timeout=TIMEOUT)
        except (OSError, ValueError) as exc:
            raise InputError.of("monitor", f"cannot reach the operator's view at {address} ({exc})") from None
        self.sock.settimeout(TIMEOUT)
        self.window, self.controls, self.buf, self.closed = self, None, b"", None

    def take_input(self, controls) -> None:
        self.controls = controls

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
        for line in lines:  # events since the last frame, a handful
            msg = json.loads(line)
            if "closed" in msg:
                self.closed = self.closed or msg["closed"]
            elif self.controls is not None:
                getattr(self.controls, msg["event"])(None, *msg["args"])
        return self.closed

    def close(self) -> None:
        self.sock.close()


class _Recorder:
    """The viewer's stand-in for ``Controls``: every call glfw makes is sent to rank 0."""

    EVENTS = ("on_key", "_on_button", "_on_cursor", "_on_scroll")

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


def serve(display: str | None, position: tuple[int, int], port: int = 0) -> None:
    """The viewer: listen on ``port`` (0: any; the port is printed as ``port N``), and show each
    connection's frames in a window at ``position`` on ``display`` until it ends."""
    from multigpu.display.window import Window

    srv = socket.create_server(("", port))
    print(f"port {srv.getsockname()[1]}", flush=True)
    while True:  # a connection per run of the wall (a restarted one connects again)
        conn, _ = srv.accept()
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
