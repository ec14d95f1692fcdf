"""The one validator every door from outside starts with (DESIGN.md, "Doors"): JSON read with
its size, nesting and numbers bounded, numbers checked without ever raising, and refusals said
in a rate-limited line.

Python's ``json`` turns a few hundred digits into an int that ``math.isfinite`` cannot take
(OverflowError), deep nesting into RecursionError, and reads ``NaN`` and ``Infinity``. Here
each of those is a refusal, a string saying what is wrong, never an exception: a door's caller
refuses the message and the wall goes on. Pure: no sockets, no MPI, no GL.
"""

from __future__ import annotations

import json
import math
import sys
import time

#: the most digits an integer in a message may have (a frame number, a key code: far fewer)
MOST_DIGITS = 15
#: the deepest nesting a message may have (every door's messages are two or three levels deep)
MOST_DEPTH = 8
#: the largest magnitude a number from a door may have before its own range check
MOST_MAGNITUDE = 1e15


class Refusal(str):
    """Why a door's input was refused (a string: it is said as it is)."""


class Unfit(ValueError):
    """A JSON document with a number it may not hold (NaN, Infinity, out of range, too many digits)."""


def _int(text: str) -> int:
    if len(text.lstrip("-")) > MOST_DIGITS:
        raise Unfit(f"an integer of {len(text.lstrip('-'))} digits (at most {MOST_DIGITS})")
    return int(text)


def _float(text: str) -> float:
    v = float(text)
    if not math.isfinite(v):  # 1e999 reads as inf
        raise Unfit("a number out of range")
    return v


def _constant(name: str):
    raise Unfit(f"{name} is not a number JSON allows")


def _depth(value, most: int) -> bool:
    """Whether ``value`` nests no deeper than ``most`` (an explicit stack: no recursion)."""
    stack = [(value, 1)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, (list, dict)):
            if d > most:
                return False
            stack.extend((c, d + 1) for c in (v.values() if isinstance(v, dict) else v))
    return True


def loads(text: str) -> object:
    """``json.loads`` with numbers bounded: ``Unfit`` for NaN, Infinity, a float out of range or
    an integer of more than ``MOST_DIGITS`` digits (JSONDecodeError as ``json``'s)."""
    return json.loads(text, parse_int=_int, parse_float=_float, parse_constant=_constant)


def parse_json(data: str | bytes, most_bytes: int, most_depth: int = MOST_DEPTH) -> object:
    """``data`` read as JSON, or a ``Refusal`` saying why not: longer than ``most_bytes``, not
    UTF-8, not JSON, nested deeper than ``most_depth``, an integer of more than ``MOST_DIGITS``
    digits, a float out of range, NaN or Infinity. Never raises."""
    if len(data) > most_bytes:
        return Refusal(f"{len(data)} bytes (at most {most_bytes})")
    try:
        text = data.decode("utf-8") if isinstance(data, (bytes, bytearray, memoryview)) else data
        if text.count("[") + text.count("{") > 4 * most_depth and not _shallow(text, most_depth):
            return Refusal(f"nested deeper than {most_depth}")
        value = loads(text)
    except Unfit as exc:
        return Refusal(str(exc))
    except UnicodeDecodeError:
        return Refusal("not UTF-8")
    except (ValueError, RecursionError, TypeError):
        return Refusal("not JSON")
    if not _depth(value, most_depth):
        return Refusal(f"nested deeper than {most_depth}")
    return value


def _shallow(text: str, most: int) -> bool:
    """A cheap look before parsing: whether brackets outside strings nest no deeper than ``most``
    (so a message of nothing but brackets never reaches the parser's recursion)."""
    depth, in_string, escaped = 0, False, False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > most:
                return False
        elif ch in "]}":
            depth -= 1
    return True


def is_number(v, lo: float = -MOST_MAGNITUDE, hi: float = MOST_MAGNITUDE) -> bool:
    """Whether ``v`` is an int or float (not a bool), finite, within ``lo``..``hi``; never raises
    (a huge int is compared as an int, never turned into a float)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    if isinstance(v, float) and not math.isfinite(v):
        return False
    try:
        return lo <= v <= hi
    except OverflowError:  # an int beyond float's range against a float bound
        return False


def is_whole(v, lo: int, hi: int) -> bool:
    """Whether ``v`` is an int (not a bool) within ``lo``..``hi``."""
    return isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi


class Refusals:
    """Refusals said in one line each, at most ``per_minute`` lines a minute; the rest counted
    (``count``) and named in the next line said."""

    def __init__(self, prefix: str, per_minute: int = 20, clock=time.monotonic):
        self.prefix, self.per_minute, self.clock = prefix, per_minute, clock
        self.said: list[float] = []
        self.unsaid = 0
        self.count = 0

    def refuse(self, what: str) -> bool:
        """Count a refusal and say it unless too many were said this minute; whether it was said."""
        self.count += 1
        now = self.clock()
        self.said = [t for t in self.said if now - t < 60.0]
        if len(self.said) >= self.per_minute:
            self.unsaid += 1
            return False
        self.said.append(now)
        more = f" ({self.unsaid} more not said)" if self.unsaid else ""
        self.unsaid = 0
        print(f"{self.prefix}{what}{more}", file=sys.stderr, flush=True)
        return True
