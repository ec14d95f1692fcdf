"""The readers of flag values: text as the numbers, pairs and places a setting holds, or one line
saying what it must look like (``InputError``; the caller names the flag). Pure."""

from __future__ import annotations

import re

from multigpu.errors import InputError

#: ``--monitor`` without a place: right of the wall, on a screen that holds the wall's canvas
MONITOR_BESIDE = (-1, -1)


def read_numbers(text: str, n: int, looks: str) -> tuple[float, ...]:
    """``n`` numbers separated by commas, or one line saying what the value must look like (``looks``)."""
    try:
        v = tuple(float(t) for t in str(text).split(","))
    except ValueError:
        v = ()
    if len(v) != n:
        raise InputError(f"must look like {looks}, got '{text}'")
    return v


def read_vec3(text: str) -> tuple[float, float, float]:
    """'X,Y,Z' as three floats."""
    return read_numbers(text, 3, "X,Y,Z (three numbers)")


def read_pair(text: str, sep: str = "x") -> tuple[int, int]:
    """'AxB' as two positive integers."""
    m = re.fullmatch(rf"\s*(\d+)\s*{sep}\s*(\d+)\s*", str(text))
    if not m:
        raise InputError(f"must look like A{sep}B with positive integers, got '{text}'")
    a, b = int(m.group(1)), int(m.group(2))
    if a < 1 or b < 1:
        raise InputError(f"must be positive on both sides, got '{text}'")
    return a, b


def parse_vec3(text: str, flag: str) -> tuple[float, float, float]:
    """'X,Y,Z' as three floats, or a clear error naming ``flag``."""
    return _named(read_vec3, flag, text)


def parse_pair(text: str, flag: str, sep: str = "x") -> tuple[int, int]:
    """'AxB' as two positive integers, or a clear error naming ``flag``."""
    return _named(read_pair, flag, text, sep)


def _named(read, flag: str, *args):
    try:
        return read(*args)
    except InputError as exc:
        raise InputError(f"{flag} {exc.message}") from None


def read_mullion(text: str) -> tuple[int, int]:
    """'MXxMY': pixels >= 0."""
    m = re.fullmatch(r"\s*(\d+)\s*x\s*(\d+)\s*", str(text))
    if not m:
        raise InputError(f"must look like MXxMY with pixels >= 0 (e.g. 40x40), got '{text}'")
    return int(m.group(1)), int(m.group(2))


def read_monitor(text: str) -> tuple[int, int]:
    """``--monitor`` [X,Y] as a window place (``beside``: the flag without a value)."""
    if text == "beside":
        return MONITOR_BESIDE
    x, y = str(text).split(",", 1) if "," in str(text) else (text, "")
    if not (x.strip().isdigit() and y.strip().isdigit()):
        raise InputError(f"must look like X,Y (pixels from the display's top-left corner), got '{text}'")
    return int(x), int(y)


def read_panel(text: str) -> tuple[str, int]:
    """``--panel [ADDRESS:]PORT`` as (address, port): 127.0.0.1 unless an address is given; port 0:
    any free one (the console prints the URL)."""
    address, _, port = str(text).rpartition(":")
    address = address.strip("[]") or "127.0.0.1"
    if not port.strip().isdigit() or int(port) > 65535:
        raise InputError(f"must look like [ADDRESS:]PORT with a port 0..65535, got '{text}'")
    return address, int(port)


def read_labels(text: str) -> tuple[int, ...]:
    """``--dark-tiles 2,3`` as tile labels."""
    try:
        return tuple(sorted({int(v) for v in str(text).split(",") if v.strip()}))
    except ValueError:
        raise InputError(f"must be tile numbers separated by commas, got '{text}'") from None
