"""Real X servers for window tests: Debian's Xvfb, screenshots with xwd + ImageMagick, input with
xdotool, a window manager's close request (WM_DELETE_WINDOW) through libX11. Every server is
started under a hard deadline and killed by process id when the test ends."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import shutil
import subprocess
import time

import numpy as np
import pytest

from multigpu.display.xvfb import start_xvfb, stop_xvfb

TOOLS = ("Xvfb", "xwd", "convert", "xdotool")


def need_tools() -> None:
    missing = [t for t in TOOLS if shutil.which(t) is None]
    if missing:
        pytest.skip(f"no {', '.join(missing)} (Debian: apt install xvfb x11-apps imagemagick xdotool)")


class Xvfb:
    """An Xvfb server with ``screens`` (W, H) screens; ``name`` is its display, e.g. ':5'."""

    def __init__(self, *screens: tuple[int, int], display: str | None = None):
        need_tools()  # skips, naming the tools, where they are missing; a server that fails to start fails
        self.proc, self.name = start_xvfb(*screens, display=display)

    def screen(self, i: int = 0) -> str:
        return f"{self.name}.{i}"

    def stop(self) -> None:
        stop_xvfb(self.proc)

    def __enter__(self) -> "Xvfb":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def screenshot(display: str) -> np.ndarray:
    """The whole root window of ``display`` as (H, W, 3) uint8, top row first."""
    from io import BytesIO

    from PIL import Image

    xwd = subprocess.run(["xwd", "-root", "-silent", "-display", display], capture_output=True, timeout=30, check=True)
    png = subprocess.run(["convert", "xwd:-", "png:-"], input=xwd.stdout, capture_output=True, timeout=30, check=True)
    return np.asarray(Image.open(BytesIO(png.stdout)).convert("RGB"))


def windows(display: str, name: str = "multigpu tile") -> list[str]:
    got = subprocess.run(["xdotool", "search", "--name", name], capture_output=True, text=True, timeout=10,
                         env={**os.environ, "DISPLAY": display})
    return got.stdout.split()


def escape(display: str, window: str) -> None:
    """Press Escape in ``window`` to end the run: the press alone, since the run acts on it and
    may have destroyed the window before a release could be sent (X error BadWindow)."""
    env = {**os.environ, "DISPLAY": display}
    subprocess.run(["xdotool", "mousemove", "--window", window, "5", "5"], env=env, timeout=10, check=True)
    subprocess.run(["xdotool", "keydown", "--window", window, "Escape"], env=env, timeout=10, check=True)


class _ClientMessage(ctypes.Structure):
    _fields_ = [("type", ctypes.c_int), ("serial", ctypes.c_ulong), ("send_event", ctypes.c_int),
                ("display", ctypes.c_void_p), ("window", ctypes.c_ulong), ("message_type", ctypes.c_ulong),
                ("format", ctypes.c_int), ("data", ctypes.c_long * 5), ("pad", ctypes.c_long * 24)]


def wm_close(display: str, window: str) -> None:
    """What a window manager does when the user closes a window: WM_DELETE_WINDOW."""
    x11 = ctypes.CDLL(ctypes.util.find_library("X11"))
    x11.XOpenDisplay.restype = ctypes.c_void_p
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x11.XInternAtom.restype = ctypes.c_ulong
    x11.XInternAtom.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int]
    x11.XSendEvent.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.c_int, ctypes.c_long, ctypes.c_void_p]
    x11.XFlush.argtypes = x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    dpy = x11.XOpenDisplay(display.encode())
    assert dpy, f"cannot open {display}"
    try:
        ev = _ClientMessage(type=33, send_event=1, window=int(window), format=32,
                            message_type=x11.XInternAtom(dpy, b"WM_PROTOCOLS", 0))
        ev.data[0] = x11.XInternAtom(dpy, b"WM_DELETE_WINDOW", 0)
        x11.XSendEvent(dpy, int(window), 0, 0, ctypes.byref(ev))
        x11.XFlush(dpy)
    finally:
        x11.XCloseDisplay(dpy)


def wait_for(what, timeout: float = 60.0, every: float = 0.2):
    """Poll ``what()`` until it is truthy; its value, or an AssertionError at the deadline."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got = what()
        if got:
            return got
        time.sleep(every)
    raise AssertionError(f"timed out after {timeout} s waiting for {getattr(what, '__name__', what)}")
