"""What the operator's page may say, checked before anything acts on it; and who may say it.

Pure: no sockets, no MPI. Every message from a page is one JSON object with a ``do`` naming one
of the listed actions (``ACTIONS``) and exactly that action's fields, each of a declared kind and
range. ``command`` turns a message into a ``Command`` or a refusal naming what is wrong; nothing
in a message is looked up or called unchecked. ``admitted`` compares a request's token in
constant time; ``same_origin`` is the WebSocket origin check (a page from elsewhere may not drive
the wall with the operator's cookie).
"""

from __future__ import annotations

import hmac
import ipaddress
from typing import NamedTuple
from urllib.parse import urlsplit

from multigpu.core.doors import Refusal, is_number, is_whole, parse_json
from multigpu.core.navigate import MOVES
from multigpu.core.resample import MIN_SCALE

#: the longest message a page may send (bytes): a longer one is refused unread
MOST_MESSAGE = 2048
#: the most pixels one drag message may move the view by, on either axis
MOST_DRAG = 10000.0
#: the largest level-of-detail bound and frame-rate target the page may ask for
MOST_LOD_PX = 1000.0
MOST_FPS = 1000.0
#: the most metres one message may move the viewer's head by, on each axis
MOST_HEAD_M = 1.0
#: the furthest a page may set a moving scene's time (seconds either side of 0)
MOST_SCENE_S = 1e6


def _number(lo: float, hi: float, none: bool = False):
    def check(v) -> bool:
        return none if v is None else is_number(v, lo, hi)
    return check


_flag = lambda v: isinstance(v, bool)  # noqa: E731
_moves = lambda v: isinstance(v, list) and len(v) <= len(MOVES) and all(m in MOVES for m in v)  # noqa: E731

#: action -> {field: (check, what it must be)}
ACTIONS: dict[str, dict] = {
    "pause": {},
    "resume": {},
    "stop": {},
    "balance": {"name": (lambda v: isinstance(v, str) and len(v) <= 40, "a strategy's name")},
    "target_fps": {"value": (_number(1.0, MOST_FPS, none=True), f"null or a frame rate 1..{MOST_FPS:g}")},
    "render_scale": {"value": (_number(MIN_SCALE, 1.0), f"a render scale {MIN_SCALE:g}..1")},
    "lod_error": {"value": (_number(0.0, MOST_LOD_PX), f"a bound 0..{MOST_LOD_PX:g} pixels")},
    "keys": {"held": (_moves, f"a list of moves from {', '.join(MOVES)}")},
    "drag": {"dx": (_number(-MOST_DRAG, MOST_DRAG), "a number of pixels"),
             "dy": (_number(-MOST_DRAG, MOST_DRAG), "a number of pixels")},
    "speed": {"steps": (lambda v: is_whole(v, -10, 10), "a whole number -10..10")},
    "orbit": {},
    "reset": {},
    "record": {"on": (_flag, "true or false")},
    "head": {axis: (_number(-MOST_HEAD_M, MOST_HEAD_M), f"metres -{MOST_HEAD_M:g}..{MOST_HEAD_M:g}")
             for axis in ("dx", "dy", "dz")},
    "head_home": {},
    "scene_pause": {},
    "scene_play": {},
    "scene_time": {"value": (_number(-MOST_SCENE_S, MOST_SCENE_S), f"seconds -{MOST_SCENE_S:g}..{MOST_SCENE_S:g}")},
}


class Command(NamedTuple):
    """One checked action from the page, with its fields."""

    do: str
    args: dict


class Refused(NamedTuple):
    """A message that was not acted on, and why (for the reply and the one log line)."""

    why: str


def command(text: str | bytes, balances: tuple[str, ...] = ()) -> Command | Refused:
    """A page's message, checked: a ``Command``, or ``Refused`` saying what is wrong.
    ``balances``: the strategies this run can switch between."""
    if len(text) > MOST_MESSAGE:
        return Refused(f"a message of {len(text)} bytes (at most {MOST_MESSAGE})")
    if isinstance(text, bytes):
        return Refused("a binary message (the page sends JSON text)")
    msg = parse_json(text, MOST_MESSAGE)
    if isinstance(msg, Refusal):
        return Refused(msg)
    if not isinstance(msg, dict):
        return Refused("not a JSON object")
    do = msg.get("do")
    if not isinstance(do, str) or do not in ACTIONS:
        return Refused(f"unknown action {str(do)[:40]!r}")
    fields = ACTIONS[do]
    extra = set(msg) - {"do"} - set(fields)
    if extra:
        return Refused(f"{do}: unknown fields {sorted(str(k)[:20] for k in extra)[:4]}")
    for name, (check, must) in fields.items():
        if name not in msg or not check(msg[name]):
            return Refused(f"{do}: {name} must be {must}")
    args = {k: msg[k] for k in fields}
    if do == "balance" and args["name"] not in balances:
        return Refused(f"balance: {args['name']!r} is not one of this run's ({', '.join(balances)})")
    return Command(do, args)


def admitted(given: str | None, token: str) -> bool:
    """Whether a request brought the run's token (compared in constant time)."""
    return given is not None and hmac.compare_digest(given.encode(), token.encode())


def known_host(host: str | None, names: frozenset) -> bool:
    """Whether a request's ``Host`` names this server: an IP address, or one of ``names`` (its
    listening address, ``localhost``, the machine's names). A browser fooled by DNS rebinding
    sends the attacker's name here, so it is refused even with the token in hand."""
    if not host or len(host) > 300:
        return False
    name = host.lower()
    if name.startswith("["):  # [IPv6]:port
        name = name[1:name.find("]")] if "]" in name else ""
    else:
        name = name.rpartition(":")[0] if ":" in name else name
    try:
        ipaddress.ip_address(name)
        return True
    except ValueError:
        return name.rstrip(".") in names


def same_origin(origin: str | None, host: str | None) -> bool:
    """Whether a WebSocket's ``Origin`` is the page's own address (``Host``): a browser always
    sends it; a page served from elsewhere carries its own. Absent (not a browser): allowed, the
    token still decides."""
    if origin is None:
        return True
    if host is None:
        return False
    parts = urlsplit(origin)
    return parts.scheme in ("http", "https") and parts.netloc.lower() == host.lower()
