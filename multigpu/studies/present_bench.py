"""``multigpu bench present``: headless against ``--present window`` (and with the operator's
``--monitor``) on Xvfb, alternated.

For each wall (2x2 of 512x512, 3x3 of 320x240) it starts one Xvfb screen holding the canvas and
the monitor beside it, and runs the same walkthrough headless, with windows, and with windows
and the monitor, in rotating order over the rounds; it prints the emulated frame (slowest
rank's CPU time, median), the wall-clock frame, each rank's present time (upload + blit + swap,
wall; with the monitor also its gather and window), the input phase (rank 0's events and the
one broadcast, wall) and the swap skew (latest minus earliest swap return per frame, one clock:
every rank on this host) as medians and p99. It needs Xvfb (Debian: xvfb); it prints figures
and asserts nothing.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np

from multigpu.display.xvfb import start_xvfb, stop_xvfb
from multigpu.errors import InputError
from multigpu.studies.tables import Columns

WALLS = [((2, 2), (512, 512)), ((3, 3), (320, 240))]
#: headless; a window per rank; windows and rank 0's operator monitor (its gather and window)
MODES = ("headless", "window", "monitor")


def bench_present(quick: bool) -> list[dict]:
    from multigpu.studies.runs import walk

    if shutil.which("Xvfb") is None:
        raise InputError("bench present: needs Xvfb (Debian: apt install xvfb)")
    frames, rounds = (40, 1) if quick else (300, 2)
    walls = [((2, 2), (128, 128))] if quick else WALLS
    rows = []
    print(f"bench present: headless vs --present window on Xvfb, {frames} frames, {rounds} alternated rounds; "
          "emulated = slowest rank's CPU time (median ms), wall = wall-clock frame (median ms)")
    table = Columns(("wall", "wall", "<14"), ("mode", "mode", "<9"), ("emulated_ms", "emulated", "9.2f"),
                    ("wall_ms", "wall", "8.2f"), ("present_ms", "present", "8.3f"),
                    ("present_p99_ms", "present p99", "12.3f"), ("input_ms", "input", "7.3f"),
                    ("skew_ms", "skew", "7.3f"), ("skew_p99_ms", "skew p99", "9.3f"))
    print(table.header())
    for grid, tile in walls:
        size = (grid[1] * tile[0], grid[0] * tile[1])
        try:
            proc, display = start_xvfb((size[0] + 660, max(size[1], 480)))  # the monitor fits beside
        except RuntimeError as exc:
            raise InputError(f"bench present: {exc}") from None
        try:
            got: dict[str, list[dict]] = {m: [] for m in MODES}
            with tempfile.TemporaryDirectory() as tmp:
                for r in range(rounds):
                    for mode in MODES[r % len(MODES):] + MODES[:r % len(MODES)]:
                        args = ["--frames", str(frames), "--mosaic-every", "0", "--present",
                                "headless" if mode == "headless" else "window", *(["--monitor"] if mode == "monitor"
                                                                                 else [])]
                        run = walk(Path(tmp) / f"{mode}{r}", grid, tile, args, 1800, env={"DISPLAY": display})
                        got[mode].append(_figures(run.summary))
            for mode, runs in got.items():
                row = {k: float(np.median([x[k] for x in runs])) for k in runs[0]}
                row.update(wall=f"{grid[0]}x{grid[1]} {tile[0]}x{tile[1]}", mode=mode)
                rows.append(row)
                print(table.row(row))
        finally:
            stop_xvfb(proc)
    return rows


def _figures(s: dict) -> dict:
    """A run's presentation figures from its summary."""
    p = s["present"]
    return {"emulated_ms": s["emulated_frame_ms_median"], "wall_ms": s["frame_ms_median"],
            "present_ms": p["present_ms_median"], "present_p99_ms": p["present_ms_p99"],
            "skew_ms": p["swap_skew_ms_median"], "skew_p99_ms": p["swap_skew_ms_p99"], "input_ms": s["input_ms_median"]}
