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
import socket
import struct
import sys
import threading
import time

import numpy as np

from multigpu.core.doors import Refusal, Refusals, is_number, is_whole, parse_json

#: seconds rank 0 waits to reach the viewer, and for a frame to leave
TIMEOUT = 10.0
HEAD = struct.Struct("<cII")
#: where rank 0 finds the run's token (the launcher sets it; MULTIGPU_* reaches every rank)
TOKEN_ENV = "MULTIGPU_MONITOR_TOKEN"
_KEY = lambda v: is_whole(v, -1, 1023)  # noqa: E731 - glfw's key codes (KEY_UNKNOWN is -1)
_CODE = lambda v: is_whole(v, -1, (1 << 31) - 1)  # noqa: E731 - a platform's scancode
_ACTION = lambda v: is_whole(v, 0, 2)  # noqa: E731 - RELEASE, PRESS, REPEAT
_MODS = lambda v: is_whole(v, 0, 255)  # noqa: E731 - glfw's modifier bits
_BUTTON = lambda v: is_whole(v, 0, 7)  # noqa: E731 - MOUSE_BUTTON_1..8
_PLACE = lambda v: is_number(v, -1e6, 1e6)  # noqa: E731 - a cursor position (pixels)
_WHEEL = lambda v: is_number(v, -100.0, 100.0)  # noqa: E731 - one scroll event's steps
#: the events a view may send, each with the check of every number it takes (glfw's callbacks,
#: the window left out): a key code, button or modifier of another type or range is refused here,
#: so ``Controls`` only ever gets what glfw itself would give it
ARGS = {"on_key": (_KEY, _CODE, _ACTION, _MODS), "_on_button": (_BUTTON, _ACTION, _MODS),
        "_on_cursor": (_PLACE, _PLACE), "_on_scroll": (_WHEEL, _WHEEL)}
EVENTS = {name: len(checks) for name, checks in ARGS.items()}
#: why a view may stop the run (a local monitor's window says the same)
CLOSED = ("escape key", "window closed")
#: the longest line a view may send (bytes): a longer one is dropped unread
MOST_LINE = 4096
#: the most a frame reads from the view: bytes, and lines replayed (the rest waits for the next frame)
MOST_READ = 1 << 16
MOST_LINES = 256
#: seconds between tries to reach a view that stopped reading
RETRY = 5.0
#: seconds a connection to the view has to bring its token (all of it, however slowly it trickles)
ADMIT = 5.0
#: connections being admitted at once: beyond, a new one is closed at once
MOST_ADMITTING = 8


def message(line: bytes) -> tuple[str, object]:
    """One line from a view, checked: ``("event", (name, args))``, ``("closed", why)``, or
    ``("refused", what is wrong)``. Nothing in it is called or looked up unchecked."""
    msg = parse_json(line, MOST_LINE)
    if isinstance(msg, Refusal):
        return "refused", msg
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
    if not isinstance(args, list) or len(args) != EVENTS[name] or not all(ok(a) for ok, a in zip(ARGS[name], args)):
        return "refused", f"{name} takes {EVENTS[name]} numbers, each of its type and range as glfw gives it"
    return "event", (name, args)


class RemoteMonitor:
    """Rank 0's side: ``present``, ``poll``, ``close`` as ``display.Monitor``; it is its own
    ``window`` for ``take_input`` (the events come over the connection).

    A view that is slow to read (a send times out) is not a view that closed: the connection
    is dropped with one line, the wall goes on without it, and a new one is tried every
    ``RETRY`` seconds without waiting (a non-blocking connect, looked at once a frame)."""

    def __init__(self, address: str, token: str):
        from multigpu.errors import InputError

        host, _, port = address.rpartition(":")
        self.where, self.token = (host.strip("[]"), port), token
        try:
            self.sock = socket.create_connection((self.where[0], int(port)), timeout=TIMEOUT)
            self.sock.sendall(token.encode() + b"\n")
        except (OSError, ValueError) as exc:
            raise InputError.of("monitor", f"cannot reach the operator's view at {address} ({exc})") from None
        self.sock.settimeout(TIMEOUT)
        self.window, self.controls, self.buf, self.closed = self, None, b"", None
        self.pending: socket.socket | None = None  # a reconnect on its way
        self.next_try = 0.0
        self.refusals = Refusals("multigpu: the operator's view sent a message refused (", per_minute=20)

    @property
    def refused(self) -> int:
        """Lines refused so far."""
        return self.refusals.count

    def take_input(self, controls) -> None:
        """Where the view's events go: each checked event name to its one ``Controls`` method
        (a table, not a look-up by name)."""
        self.controls = controls
        self.handlers = {"on_key": controls.on_key, "_on_button": controls._on_button,
                         "_on_cursor": controls._on_cursor, "_on_scroll": controls._on_scroll}

    def present(self, img: np.ndarray) -> None:
        """Send ``img`` (bottom row first). A view gone ends the monitor (``poll`` says so); a send
        that times out drops the connection until a new one is made."""
        if self.sock is None:
            self._reconnect()
            if self.sock is None:
                return
        h, w = img.shape[:2]
        try:
            self.sock.sendall(HEAD.pack(b"F", w, h) + np.ascontiguousarray(img, dtype=np.uint8).tobytes())
        except TimeoutError:
            self._drop(f"it read nothing for {TIMEOUT:g} s")
        except OSError:
            self.closed = self.closed or "window closed"  # the view is gone (its connection dropped)

    def _drop(self, why: str) -> None:
        print(f"multigpu: the operator's view is not reading ({why}): the wall goes on without it and "
              f"reconnects every {RETRY:g} s", file=sys.stderr, flush=True)
        self.sock.close()
        self.sock, self.buf, self.next_try = None, b"", time.monotonic() + RETRY

    def _reconnect(self) -> None:
        """One step of a reconnect that never waits: start it, or see whether it finished."""
        import select

        if self.pending is None:
            if time.monotonic() < self.next_try:
                return
            self.next_try = time.monotonic() + RETRY
            try:
                infos = socket.getaddrinfo(self.where[0], int(self.where[1]), type=socket.SOCK_STREAM)
                family, kind, proto, _, addr = infos[0]
                self.pending = socket.socket(family, kind, proto)
                self.pending.setblocking(False)
                self.pending.connect_ex(addr)
            except OSError:
                self._abandon()
            return
        _, ready, _ = select.select([], [self.pending], [], 0)
        if not ready:
            if time.monotonic() > self.next_try:
                self._abandon()
            return
        sock, self.pending = self.pending, None
        if sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR):
            sock.close()
            return
        try:
            sock.settimeout(TIMEOUT)
            sock.sendall(self.token.encode() + b"\n")
        except OSError:
            sock.close()
            return
        self.sock = sock
        print("multigpu: the operator's view is back", file=sys.stderr, flush=True)

    def _abandon(self) -> None:
        if self.pending is not None:
            self.pending.close()
        self.pending = None

    def poll(self) -> str | None:
        """Replay the events that arrived (no wait, ``MOST_READ`` bytes and ``MOST_LINES`` lines a
        frame at most: the rest waits for the next); why the view wants the run to stop, or None."""
        if self.sock is None:
            return self.closed
        self.sock.setblocking(False)
        try:
            while len(self.buf) < MOST_READ and (chunk := self.sock.recv(MOST_READ)):
                self.buf += chunk
            if len(self.buf) < MOST_READ:  # the loop ended on an empty read: the view closed
                self.closed = self.closed or "window closed"
        except BlockingIOError:
            pass
        except OSError:
            self.closed = self.closed or "window closed"  # the view is gone (its connection dropped)
        finally:
            if self.sock is not None:
                self.sock.settimeout(TIMEOUT)
        *lines, rest = self.buf.split(b"\n", MOST_LINES)
        self.buf = rest  # beyond MOST_LINES lines, the rest waits for the next frame
        if b"\n" not in rest and len(rest) > MOST_LINE:  # a line with no end: dropped, not kept growing
            lines.append(rest[:MOST_LINE] + b"...")
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
                self.refusals.refuse(f"{value}); the wall goes on")
        return self.closed

    def close(self) -> None:
        self._abandon()
        if self.sock is not None:
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


def admit(conn: socket.socket, token: str, deadline: float = ADMIT) -> bool:
    """Whether the connection's first line (at most 256 bytes, all within ``deadline`` seconds
    however slowly it comes) is ``token``; nothing but that line may come before the first frame."""
    got = _token_of(conn, time.monotonic() + deadline)
    return got is not None and hmac.compare_digest(got, token.encode())


def _token_of(conn: socket.socket, until: float) -> bytes | None:
    data = b""
    try:
        while b"\n" not in data and len(data) < 256:
            left = until - time.monotonic()
            if left <= 0:
                return None
            conn.settimeout(left)
            chunk = conn.recv(256 - len(data))
            if not chunk:
                return None
            data += chunk
    except OSError:
        return None
    line, _, rest = data.partition(b"\n")
    return line if not rest else None  # nothing may follow before the first frame's head


def _admitting(srv: socket.socket, token: str, admitted) -> None:
    """The viewer's door, in a thread of its own: every connection is admitted in a thread with
    its own deadline (``ADMIT``), so a peer that trickles its bytes holds up nobody else; at most
    ``MOST_ADMITTING`` at once, beyond that a connection is closed at once."""
    busy = threading.BoundedSemaphore(MOST_ADMITTING)

    def one(conn, peer) -> None:
        try:
            if admit(conn, token):
                conn.settimeout(None)
                admitted.put(conn)
                return
            print(f"multigpu monitor-view: refused a connection from {peer[0]} (no or wrong token in "
                  f"{ADMIT:g} s)", file=sys.stderr, flush=True)
            conn.close()
        finally:
            busy.release()

    while True:
        conn, peer = srv.accept()
        if not busy.acquire(blocking=False):
            conn.close()
            continue
        threading.Thread(target=one, args=(conn, peer), daemon=True).start()


def serve(display: str | None, position: tuple[int, int], token: str, port: int = 0,
          listen: str = "127.0.0.1") -> None:
    """The viewer: listen on ``listen``:``port`` (0: any; the port is printed as ``port N``),
    and show the frames of each connection that brings ``token`` in a window at ``position``
    on ``display`` until it ends; any other connection is dropped."""
    import queue

    from multigpu.display.window import Window

    srv = socket.create_server((listen, port))
    print(f"port {srv.getsockname()[1]}", flush=True)
    admitted: queue.Queue = queue.Queue()
    threading.Thread(target=_admitting, args=(srv, token, admitted), daemon=True).start()
    while True:  # a connection per run of the wall (a restarted one connects again)
        conn = admitted.get()
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
