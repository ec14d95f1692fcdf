"""The operator's page, served over HTTP and one WebSocket per page, from a thread of its own.

Built on ``websockets`` (chosen over aiohttp by measurement: 115 ms and 14 MiB to import against
408 ms and 26 MiB, in rank 0 of every run that asks for a panel). Plain GETs serve the page's
files (``page/``: the page, its script and style, uPlot); ``/ws`` carries the run to the page
(JSON text: hello, plot rows, status, events, the summary; binary: the wall's thumbnail as JPEG)
and the page's actions back (``protocol.command``: checked, then queued for the frame loop).

Safe by default: the server listens where it is told (the door's default is 127.0.0.1); every
request must bring the run's token (``?token=`` in the printed URL, or the cookie the page gets
with it), or it is refused with 403; a WebSocket from a page of another origin is refused; a
message that fails its check gets an error reply and one log line. The loop never waits on a
page: the server reads ``PanelState`` at its own pace, and a page that stops reading only fills
its own connection's buffer.
"""

from __future__ import annotations

import asyncio
import io
import json
import sys
import threading
import time
from http import HTTPStatus
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import numpy as np

from multigpu.panel.protocol import Command, Refused, admitted, command, known_host, same_origin
from multigpu.panel.state import PanelState, names

PAGE = Path(__file__).parent / "page"
#: the files the page may fetch, by name, with their types (nothing else is ever read)
FILES = {"panel.js": "text/javascript", "panel.css": "text/css", "uPlot.iife.min.js": "text/javascript",
         "uPlot.min.css": "text/css"}
#: the cookie's name, with the server's port after it: cookies are per host, not per port, so two
#: panels on one machine would otherwise overwrite each other's token
COOKIE = "multigpu-panel"
#: seconds between updates to a page (the thumbnail and plots refresh at this rate at most)
PERIOD = 0.2
#: log lines about refused messages, at most this many a minute (the rest are counted)
MOST_LOG = 20
#: messages a page may send a second (a burst of twice as many): beyond, refused, so that a page
#: that floods cannot fill the queue the frame loop drains
MOST_RATE = 60.0
#: plot rows in one message to a page at most (a long history goes in several, one a period)
MOST_ROWS = 2000


def _log(text: str) -> None:
    print(f"multigpu: panel: {text}", file=sys.stderr, flush=True)


def jpeg(img: np.ndarray, quality: int = 80) -> bytes:
    """The thumbnail as the page shows it."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img)).save(buf, format="JPEG", quality=quality)
    return buf.getvalue()


class PanelServer:
    """Serves ``state`` on ``address``:``port`` (0: any free port) to pages that bring ``token``."""

    def __init__(self, state: PanelState, address: str, port: int, token: str, readonly: bool = False):
        self.state, self.address, self.port, self.token = state, address, port, token
        self.readonly = readonly  # a finished run's page (``multigpu view``): nothing to control
        self.loop: asyncio.AbstractEventLoop | None = None
        self.thread: threading.Thread | None = None
        self.ready = threading.Event()
        self.error: str | None = None
        self.logged: list[float] = []
        self.unlogged = 0
        self.thumbs: dict = {}  # the newest thumbnail as sent: its seq, pieces (JSON) and JPEG
        self.delivered = threading.Event()  # every page connected got the summary

    # -- life

    def start(self) -> str:
        """Listen (in a daemon thread); the page's URL, token included. Raises OSError where the
        address cannot be listened on."""
        self.thread = threading.Thread(target=self._run, name="multigpu-panel", daemon=True)
        self.thread.start()
        self.ready.wait(30)
        if self.error or not self.ready.is_set():
            raise OSError(self.error or "the panel's server did not start")
        host = self.address if self.address not in ("", "0.0.0.0", "::") else _hostname()
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}/?token={self.token}"

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except Exception as exc:  # noqa: BLE001 - said by start(), or the server just ends
            self.error = self.error or f"{exc.__class__.__name__}: {exc}"
            self.ready.set()

    async def _main(self) -> None:
        from websockets.asyncio.server import serve

        self.loop = asyncio.get_running_loop()
        self.stopping = asyncio.Event()
        try:
            server = await serve(self._page, self.address or None, self.port, process_request=self._http,
                                 server_header=None, compression=None, max_size=1 << 16, ping_interval=5,
                                 ping_timeout=20, logger=_QUIET)
        except OSError as exc:
            self.error = str(exc)
            self.ready.set()
            return
        self.port = server.sockets[0].getsockname()[1]
        self.cookie = f"{COOKIE}-{self.port}"
        self.names = _names(self.address)
        self.ready.set()
        async with server:
            await self.stopping.wait()

    def cpu_s(self) -> float:
        """CPU seconds the server's thread has used so far (its own clock: what the page costs rank 0
        beside the frame loop's hand-overs)."""
        if self.thread is None or self.thread.ident is None or not self.thread.is_alive():
            return 0.0
        try:
            return time.clock_gettime(time.pthread_getcpuclockid(self.thread.ident))
        except (OSError, AttributeError):  # a platform without per-thread clocks
            return 0.0

    def close(self, linger: float = 0.0) -> None:
        """Stop serving; ``linger``: seconds at most to let connected pages get the summary first."""
        if self.loop is None or self.thread is None:
            return
        if linger and self.state.clients:
            self.delivered.wait(linger)
        try:
            self.loop.call_soon_threadsafe(self.stopping.set)
        except RuntimeError:  # the loop already ended
            pass
        self.thread.join(5)

    # -- HTTP

    def _token(self, request) -> str | None:
        query = parse_qs(urlsplit(request.path).query)
        if "token" in query:
            return query["token"][0]
        for part in request.headers.get("Cookie", "").split(";"):
            name, _, value = part.strip().partition("=")
            if name == self.cookie:
                return value
        return None

    def _http(self, connection, request):
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        path = urlsplit(request.path).path
        plain = lambda status, text: Response(status.value, status.phrase, Headers(  # noqa: E731
            [("Content-Type", "text/plain; charset=utf-8"), ("Cache-Control", "no-store")]), text.encode())
        if not known_host(request.headers.get("Host"), self.names):
            self._refused(f"a request for host {request.headers.get('Host', '')[:80]!r}")
            return plain(HTTPStatus.MISDIRECTED_REQUEST, "multigpu panel: not this server's name\n")
        if not admitted(self._token(request), self.token):
            return plain(HTTPStatus.FORBIDDEN, "multigpu panel: this page needs the run's token: open the URL "
                                               "the console printed\n")
        if path == "/ws":
            if not same_origin(request.headers.get("Origin"), request.headers.get("Host")):
                self._refused(f"a WebSocket from origin {request.headers.get('Origin', '')[:80]!r}")
                return plain(HTTPStatus.FORBIDDEN, "multigpu panel: a page of another origin\n")
            return None  # the WebSocket handshake goes on
        if path == "/":
            name, kind = "index.html", "text/html; charset=utf-8"
        elif path.startswith("/static/") and path[len("/static/"):] in FILES:
            name = path[len("/static/"):]
            kind = FILES[name]
        else:
            return plain(HTTPStatus.NOT_FOUND, "not found\n")
        headers = [("Content-Type", kind), ("Cache-Control", "no-store"), ("X-Content-Type-Options", "nosniff"),
                   ("Content-Security-Policy", "default-src 'self'; img-src 'self' blob:; connect-src 'self'; "
                                               "style-src 'self'; frame-ancestors 'none'")]
        if path == "/":
            headers.append(("Set-Cookie", f"{self.cookie}={self.token}; HttpOnly; SameSite=Strict; Path=/"))
        return Response(200, "OK", Headers(headers), (PAGE / name).read_bytes())

    # -- the page's WebSocket

    async def _page(self, ws) -> None:
        state = self.state
        state.clients += 1
        self.delivered.clear()
        pusher = asyncio.create_task(self._push(ws))
        allowance, last = 2 * MOST_RATE, time.monotonic()  # a token bucket per page
        holding = False  # the page's last keys message held some down
        try:
            async for message in ws:
                now = time.monotonic()
                allowance = min(2 * MOST_RATE, allowance + (now - last) * MOST_RATE)
                last = now
                if allowance < 1.0:
                    got = Refused(f"more than {MOST_RATE:g} messages a second")
                else:
                    allowance -= 1.0
                    try:
                        got = command(message, state.balances)
                    except Exception as exc:  # noqa: BLE001 - a bug in a check: said, the page stays
                        got = Refused(f"a message the checks could not read ({exc.__class__.__name__})")
                if isinstance(got, Command) and self.readonly:
                    await ws.send(json.dumps({"error": f"{got.do}: a finished run, nothing to control"}))
                elif isinstance(got, Command):
                    state.commands.put(got)
                    holding = bool(got.args["held"]) if got.do == "keys" else holding
                    await ws.send(json.dumps({"ok": got.do}))
                else:
                    self._refused(f"a message from {_peer(ws)} ({got.why})")
                    await ws.send(json.dumps({"error": got.why}))
        except Exception:  # noqa: BLE001 - a page that goes away, however it goes
            pass
        finally:
            pusher.cancel()
            state.clients -= 1
            if holding:  # a page gone (a laptop closed) holds no keys down
                state.commands.put(Command("keys", {"held": []}))

    async def _push(self, ws) -> None:
        state = self.state
        hello = {"hello": {"header": state.header, "balances": list(state.balances), "ranks": state.K,
                           "series": names(state.K)}}
        await ws.send(json.dumps(hello))
        seq, thumb, status, events, summary = 0, 0, None, 0, False
        try:
            while True:
                seq, rows = state.rows_since(seq, MOST_ROWS)
                if len(rows):
                    await ws.send(json.dumps({"rows": np.where(np.isnan(rows), None, rows).tolist()}))
                with state.lock:
                    now_status, got = dict(state.status), state.thumb
                events, new_events = state.events_since(events)
                if now_status != status:
                    status = now_status
                    await ws.send(json.dumps({"status": status}))
                if new_events:
                    await ws.send(json.dumps({"events": [[round(t, 3), e] for t, e in new_events]}))
                if got is not None and got[0] != thumb:
                    thumb = got[0]
                    pieces, picture = self._thumb(got)
                    await ws.send(pieces)  # where each rank's pieces lie (the page draws them on request)
                    await ws.send(picture)
                if state.summary is not None and not summary:
                    summary = True
                    await ws.send(json.dumps({"summary": state.summary}, default=str))
                    self.delivered.set()
                await asyncio.sleep(PERIOD)
        except Exception:  # noqa: BLE001 - the page went away
            pass

    def _thumb(self, got) -> tuple[str, bytes]:
        """The newest thumbnail as the page gets it: its pieces (JSON: each rank's rects in the
        thumbnail's pixels, top row first) and the picture (JPEG), made once for every page."""
        seq, img, rects, shrink = got
        if self.thumbs.get("seq") != seq:
            h, w = img.shape[:2]
            pieces = [] if rects is None else [
                [k, x0 / shrink, h - y1 / shrink, x1 / shrink, h - y0 / shrink]
                for k, r in enumerate(rects) for x0, y0, x1, y1 in np.asarray(r, dtype=float).reshape(-1, 4).tolist()]
            self.thumbs = {"seq": seq, "pieces": json.dumps({"thumb": {"width": w, "height": h, "pieces": pieces}}),
                           "jpeg": jpeg(img)}
        return self.thumbs["pieces"], self.thumbs["jpeg"]

    def _refused(self, what: str) -> None:
        """One log line per refusal, at most ``MOST_LOG`` a minute (the others counted)."""
        now = time.monotonic()
        self.logged = [t for t in self.logged if now - t < 60.0]
        if len(self.logged) >= MOST_LOG:
            self.unlogged += 1
            return
        self.logged.append(now)
        more = f" ({self.unlogged} more not logged)" if self.unlogged else ""
        self.unlogged = 0
        _log(f"refused {what}; the wall goes on{more}")


def _peer(ws) -> str:
    try:
        return str(ws.remote_address[0])
    except (AttributeError, IndexError, TypeError):
        return "a page"


def _names(address: str) -> frozenset:
    """The names a request's ``Host`` may give for this server: ``localhost``, the machine's
    names and the address it listens on."""
    import socket

    names = {"localhost", socket.gethostname(), address}
    try:
        names.add(socket.getfqdn())
    except OSError:
        pass
    return frozenset(n.lower().rstrip(".") for n in names if n)


def _hostname() -> str:
    import socket

    return socket.gethostname()


def _quiet():
    """The server's own log, silenced: a refused request is said once by ``_refused``."""
    import logging

    log = logging.getLogger("multigpu.panel.server")
    log.addHandler(logging.NullHandler())
    log.propagate = False
    return log


_QUIET = _quiet()
