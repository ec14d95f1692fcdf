"""--path interactive on Xvfb, driven by xdotool: keys and a drag fly the camera, B switches the
strategy at one frame on every rank, Escape ends the run cleanly, the recording replays bit for
bit; the operator's monitor shows the wall with the partition; a failing rank leaves every whole
frame and the recorded path. Every job and X server runs under a hard timeout, killed by id."""

import csv
import json
import os
import subprocess
import time

import numpy as np
import pytest
from mpirun import SMALL, read_png, run_mpi, start_mpi
from xserver import Xvfb, escape, need_tools, screenshot, wait_for, windows

from multigpu.config import WalkConfig
from multigpu.strategies import REGISTRY

pytestmark = pytest.mark.mpi
TILE = (96, 72)
CANVAS = (2 * 96, 2 * 72)


def live_args(out, extra=()):
    return ["walkthrough", *SMALL, "--path", "interactive", "--present", "window", "--grid", "2x2", "--tile",
            f"{TILE[0]}x{TILE[1]}", "--out", str(out), "--record", str(out.parent / f"{out.name}.json"),
            "--mosaic-every", "3", "--no-overlay", *extra]


def frames_done(out) -> int:
    f = out / "timings.csv"
    return (len(f.read_text().splitlines()) - 1) // 4 if f.exists() else 0


def xdo(display: str, *args: str) -> None:
    subprocess.run(["xdotool", *args], env={**os.environ, "DISPLAY": display}, timeout=10, check=True)


def rows_by_frame(out) -> dict[int, list[dict]]:
    with open(out / "timings.csv") as fh:
        rows = list(csv.DictReader(fh))
    by: dict[int, list[dict]] = {}
    for r in rows:
        by.setdefault(int(r["frame"]), []).append(r)
    return by


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_keys_fly_switch_the_strategy_and_the_recording_replays_bit_for_bit(tmp_path):
    cycle, default = list(REGISTRY), WalkConfig.balance
    after = cycle[(cycle.index(default) + 1) % len(cycle)]  # what B switches the default to
    with Xvfb(CANVAS) as x:
        out = tmp_path / "live"
        proc, kill = start_mpi(4, live_args(out), env={"DISPLAY": x.name})
        try:
            wait_for(lambda: frames_done(out) >= 5 and windows(x.name, "multigpu tile 0"))
            w = windows(x.name, "multigpu tile 0")[0]
            xdo(x.name, "mousemove", "--window", w, "10", "10")  # the pointer over it: it has the keyboard
            start = frames_done(out)
            xdo(x.name, "keydown", "--window", w, "w")
            wait_for(lambda: frames_done(out) >= start + 8)  # held over several frames
            xdo(x.name, "keyup", "--window", w, "w")
            xdo(x.name, "key", "--window", w, "b")
            wait_for(lambda: any(r["balance"] == after for r in rows_by_frame(out).get(frames_done(out) - 1, [])))
            xdo(x.name, "mousemove", "--window", w, "20", "20", "mousedown", "1")
            xdo(x.name, "mousemove_relative", "--", "60", "0")  # drag right: turn right
            xdo(x.name, "mouseup", "1")
            turned = frames_done(out)
            wait_for(lambda: frames_done(out) >= turned + 4)
            escape(x.name, w)
            _, err = proc.communicate(timeout=120)
        finally:
            kill() if proc.poll() is None else None
    assert proc.returncode == 0, err[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["stopped_by"] == "escape key (rank 0's window)" and s["config"]["path"] == "interactive"
    n = s["frames_written"]
    by = rows_by_frame(out)
    assert sorted(by) == list(range(n)) and all(len(r) == 4 for r in by.values())
    names = [{r["balance"] for r in by[f]} for f in range(n)]
    assert all(len(k) == 1 for k in names), "every rank plans each frame with the same strategy"
    names = [k.pop() for k in names]
    switch = names.index(after)
    assert set(names[:switch]) == {default} and set(names[switch:]) == {after}  # from one frame on
    assert s["balance_frames"] == {default: switch, after: n - switch}

    cams = json.loads((tmp_path / "live.json").read_text())["cameras"]
    assert len(cams) == n  # the camera of every frame written
    pos = np.array([c["position"] for c in cams])
    look = unit(np.array([c["target"] for c in cams]) - pos)
    assert len({tuple(p) for p in pos}) > 3  # W moved the camera
    assert np.linalg.norm(look[-1] - look[0]) > 0.05  # the drag turned it
    right = np.cross(look[0], cams[0]["up"])
    assert (look[-1] - look[0]) @ right > 0  # to the right

    replay = tmp_path / "replay"
    res = run_mpi(4, ["walkthrough", *SMALL, "--path", str(tmp_path / "live.json"), "--grid", "2x2", "--tile",
                      f"{TILE[0]}x{TILE[1]}", "--out", str(replay), "--mosaic-every", "3", "--no-overlay"],
                  timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    live = sorted((out / "mosaic").glob("frame_*.png"))
    assert len(live) >= 5
    for png in live:  # the live window run and the headless replay: the same pictures, bit for bit
        a, b = read_png(png), read_png(replay / "mosaic" / png.name)
        assert (a == b).all(), f"{png.name}: {(a != b).any(axis=2).sum()} pixels differ"


def test_the_monitor_shows_the_wall_with_its_partition_and_escape_there_ends_the_run(tmp_path):
    # the interactive path runs until Escape and, untouched, shows the same picture and partition
    # every frame: no race with the end of a fixed path on a fast machine
    with Xvfb((CANVAS[0] + 10 + CANVAS[0], CANVAS[1] + 30)) as x:
        out = tmp_path / "mon"
        args = ["walkthrough", *SMALL, "--path", "interactive", "--present", "window", "--grid", "2x2", "--tile",
                f"{TILE[0]}x{TILE[1]}", "--balance", "strips", "--monitor", f"{CANVAS[0] + 10},30", "--out",
                str(out), "--mosaic-every", "100"]
        proc, kill = start_mpi(4, args, env={"DISPLAY": x.name})
        try:
            wait_for(lambda: frames_done(out) >= 10 and windows(x.name, "multigpu monitor"))
            time.sleep(0.5)
            shot = screenshot(x.name)
            m = windows(x.name, "multigpu monitor")[0]
            escape(x.name, m)
            _, err = proc.communicate(timeout=120)
        finally:
            kill() if proc.poll() is None else None
    assert proc.returncode == 0, err[-3000:]
    partition = read_png(out / "mosaic" / "frame_00000_partition.png")  # the mosaic with the partition over it
    monitor = shot[30:30 + CANVAS[1], CANVAS[0] + 10:2 * CANVAS[0] + 10]
    assert (monitor == partition).all(), f"{(monitor != partition).any(axis=2).sum()} monitor pixels differ"
    assert (shot[:CANVAS[1], :CANVAS[0]] == read_png(out / "mosaic" / "frame_00000.png")).all()  # the wall itself
    s = json.loads((out / "summary.json").read_text())
    assert s["stopped_by"] == "escape key (the monitor)"


@pytest.mark.parametrize("latency", [0, 1])
def test_a_failing_rank_keeps_every_whole_frame_and_the_recorded_path(tmp_path, latency):
    """Rank 2 fails as it starts frame 12: every frame shown before it is kept, rows and
    cameras alike (with a frame in flight, frame 11 was never shown)."""
    with Xvfb(CANVAS) as x:
        out = tmp_path / "fail"
        res = run_mpi(4, [*live_args(out), "--latency", str(latency)],
                      env={"DISPLAY": x.name, "MULTIGPU_FAULT": "2:12"}, timeout=180)
    assert res.returncode == 1, res.stderr[-2000:]
    shown = 12 - latency
    s = json.loads((out / "summary.json").read_text())
    assert not s["complete"] and s["frames_written"] == shown
    assert len(json.loads((tmp_path / "fail.json").read_text())["cameras"]) == shown
    assert frames_done(out) == shown


@pytest.mark.parametrize("case", ["headless", "no-dir", "no-display"])
def test_bad_interactive_input_is_one_line_and_exit_2(tmp_path, case):
    need_tools()
    args, env = live_args(tmp_path / "bad"), {}
    if case == "headless":
        args[args.index("window")] = "headless"
        want = "--path interactive needs --present window"
    elif case == "no-dir":
        args[args.index("--record") + 1] = str(tmp_path / "missing" / "rec.json")
        want = "--record"
        env = {"DISPLAY": ":987"}  # refused before any window opens
    else:
        env = {"DISPLAY": ""}
        want = "DISPLAY"
    res = run_mpi(4, args, env=env, timeout=120)
    assert res.returncode == 2, res.stderr[-2000:]
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and want in lines[0], res.stderr
    assert not (tmp_path / "bad").exists() and not (tmp_path / "bad.json").exists()
