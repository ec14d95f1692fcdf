"""``multigpu wall test`` on Xvfb (2 ranks, every job and server under a hard timeout): the
windows show the canvas pattern bit for bit, every tile the same frame (the swap lock), the
arrow keys move the mullions and print the value for the wall file, Escape ends it with 0; no X
server is one line and exit 2."""

import json
import os
import signal
import subprocess
import time

import numpy as np
import pytest
from mpirun import end_launcher, start_launcher
from xserver import Xvfb, escape, need_tools, screenshot, wait_for, windows

from multigpu.core.canvas import Canvas
from multigpu.display.pattern import BACKGROUND, BAR, tile_pattern
from multigpu.rank.walltest import PACE

pytestmark = pytest.mark.mpi
GRID, TILE, MULLION = (1, 2), (64, 48), (6, 0)


def _start(wall, env):
    return _start_n(2, wall, env)


def _start_n(n, wall, env):
    return start_launcher(["-n", str(n), "wall", "test", str(wall)], env)


def _expected(frame, mullion, host):
    """The screen: each window where it opened (the tile's place with the file's mullions), showing
    its part of the pattern of the canvas with ``mullion``."""
    shown, placed = Canvas(GRID, TILE, mullion), Canvas(GRID, TILE, MULLION)
    W, H = shown.size
    img = np.zeros((placed.size[1], placed.size[0], 3), np.uint8)
    for k, ((x0, _, _, y1), (px, _, _, py1)) in enumerate(zip(shown.tiles(), placed.tiles())):  # two tiles
        top, ptop = H - int(y1), placed.size[1] - int(py1)
        img[ptop:ptop + TILE[1], px:px + TILE[0]] = tile_pattern(
            (W, H), (int(x0), top), TILE, frame, [f"rank {k}", f"host {host}", os.environ["DISPLAY"],
                                                  f"{TILE[0]}x{TILE[1]}"])
    return img


def _frame_shown(shot, mullion, host, since):
    """The frame whose pattern the screenshot is, or None (caught between two swaps); the job
    started at ``since`` (time.monotonic) and shows at most PACE frames a second."""
    W = Canvas(GRID, TILE, mullion).size[0]
    red = np.flatnonzero((shot == BAR).all(axis=2).any(axis=0))
    if red.size == 0:
        return None
    for f in range(0, int((time.monotonic() - since + 1) * PACE) + 10):  # frames that put the bar where it shows
        x = (8 * f) % W
        if any(abs(x - r) < 40 for r in red[:1]) and (shot == _expected(f, mullion, host)).all():
            return f
    return None


def test_the_pattern_is_the_canvas_in_step_and_keys_move_the_mullions(tmp_path):
    import socket

    need_tools()
    c = Canvas(GRID, TILE, MULLION)
    with Xvfb(c.size) as x:
        wall = tmp_path / "wall.json"
        wall.write_text(json.dumps({"grid": "1x2", "tile": f"{TILE[0]}x{TILE[1]}", "mullion": "6x0"}))
        os.environ["DISPLAY"] = x.name  # the label a rank without a display entry shows
        since = time.monotonic()
        proc = _start(wall, {"DISPLAY": x.name})
        try:
            wait_for(lambda: len(windows(x.name)) == 2, timeout=60)
            shown = wait_for(lambda: _frame_shown(screenshot(x.name), MULLION, socket.gethostname(), since) is not None,
                             timeout=30, every=0.05)
            assert shown
            first = windows(x.name, "multigpu tile 0")[0]  # rank 0's window takes the keys
            xenv = {**os.environ, "DISPLAY": x.name}
            subprocess.run(["xdotool", "mousemove", "--window", first, "5", "5"], env=xenv, timeout=10, check=True)
            for _ in range(2):  # the pointer over rank 0's window gives it the keyboard (no window manager)
                subprocess.run(["xdotool", "key", "--window", first, "Right"], env=xenv, timeout=10, check=True)
            wait_for(lambda: _frame_shown(screenshot(x.name), (8, 0), socket.gethostname(), since) is not None,
                     timeout=30, every=0.05)  # every tile redrawn with the new mullion
            escape(x.name, first)
            out, err = end_launcher(proc)
        finally:
            os.environ.pop("DISPLAY", None)
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err[-2000:]
    assert f'mullion 7x0: put "mullion": "7x0" in {wall}' in out and "wall test ended with mullion 8x0" in out, out


def test_no_x_server_is_one_line_and_exit_2(tmp_path):
    need_tools()
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x2", "tile": "64x48", "displays": [{"rank": 0, "display": ":987"},
                                                                              {"rank": 1, "display": ":987"}]}))
    proc = _start(wall, {})
    _, err = end_launcher(proc)
    assert proc.returncode == 2, err[-2000:]
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and ":987" in lines[0], err


def test_fullscreen_windows_fill_their_screens(tmp_path):
    need_tools()
    with Xvfb(TILE) as a, Xvfb(TILE) as b:
        wall = tmp_path / "wall.json"
        wall.write_text(json.dumps({"grid": "1x2", "tile": f"{TILE[0]}x{TILE[1]}", "displays": [
            {"rank": 0, "display": a.screen(0), "fullscreen": True},
            {"rank": 1, "display": b.screen(0), "fullscreen": True}]}))
        proc = _start(wall, {})
        try:
            wait_for(lambda: windows(a.name) and windows(b.name), timeout=60)
            for x in (a, b):
                geo = subprocess.run(["xdotool", "getwindowgeometry", windows(x.name)[0]], capture_output=True,
                                     text=True, timeout=10, env={**os.environ, "DISPLAY": x.name}).stdout
                assert "Position: 0,0" in geo and f"Geometry: {TILE[0]}x{TILE[1]}" in geo, geo
                drawn = lambda: bool((screenshot(x.name) == BACKGROUND).all(axis=2).mean() > 0.05)  # the pattern
                wait_for(drawn, timeout=20)
            escape(a.name, windows(a.name, "multigpu tile 0")[0])
            _, err = end_launcher(proc)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err[-2000:]


def test_a_projector_wall_shows_the_pattern_through_each_outputs_warp_and_blend(tmp_path):
    """Three projectors (``warp make``'s rig): each window is its output (96x72, side by side),
    showing its tile's part of the pattern (a grey ramp across the canvas, its output's name)
    warped and blended as a run's pictures are (the numpy reference, within the GPU's filtering)."""
    import socket

    from multigpu.core.warpblend import output, upsample
    from multigpu.warp import mpcdi
    from multigpu.warp.layout import layout
    from multigpu.warp.make import buffer_size, outputs
    from multigpu.warp.rig import flat_rig

    need_tools()
    rig = flat_rig(3, 0.18, size=(96, 72))
    buffer = buffer_size(rig)
    mpcdi.write(tmp_path / "wall.mpcdi", buffer, outputs(rig, buffer))
    size, outs = mpcdi.read(tmp_path / "wall.mpcdi")
    lay = layout("wall.mpcdi", size, outs)
    c = Canvas(lay.grid, lay.tile, lay.mullion)
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"mpcdi": "wall.mpcdi"}))
    host = socket.gethostname()

    def expected(f, k, display):
        x0, _, _, y1 = (int(v) for v in c.tiles()[k])
        tile = tile_pattern(c.size, (x0, c.size[1] - y1), lay.tile, f,
                            [f"rank {k}", f"output p{k + 1}", f"host {host}", display, "96x72"], ramp=True)
        o = outs[k]
        return output(tile, upsample(o.warp, o.size), o.alpha, o.beta)

    def frame_of(shot, display):
        for f in range(0, int((time.monotonic() - since + 1) * PACE) + 10):  # the frames shown so far
            got = shot[:, :96].astype(int)
            if np.abs(got - expected(f, 0, display)).max() <= 2:
                return f
        return None

    with Xvfb((3 * 96, 72)) as x:
        since = time.monotonic()
        proc = _start_n(3, wall, {"DISPLAY": x.name})
        try:
            wait_for(lambda: len(windows(x.name)) == 3, timeout=60)
            found = {}

            def shown():
                found["shot"] = shot = screenshot(x.name)
                found["f"] = frame_of(shot, x.name)
                return found["f"] is not None
            wait_for(shown, timeout=30, every=0.1)
            escape(x.name, windows(x.name, "multigpu tile 0")[0])
            _, err = end_launcher(proc)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err[-2000:]
    shot, f = found["shot"], found["f"]
    for k in (1, 2):  # the same frame on every output (the swap lock), each through its own warp
        d = np.abs(shot[:, 96 * k:96 * (k + 1)].astype(int) - expected(f, k, x.name))
        assert d.max() <= 2 and d.mean() < 0.5, (k, d.max(), d.mean())
