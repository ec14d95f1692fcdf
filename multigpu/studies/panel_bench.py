"""``multigpu bench panel``: what the operator's page costs the wall, alternated.

The same headless walk (the plant on a 2x2 wall of 256x256 tiles) three ways, in rotating order
over the rounds: without ``--panel``; with it and no page connected ("closed"); with a page
connected that reads everything the server sends ("open"; a
WebSocket client in this process, so a browser's own CPU stays out of the ranks' figures). It
prints, as medians over the rounds, per frame: the server thread's CPU time (its own clock), rank
0's display phase CPU time (where the loop hands the page its thumbnail), and their sum over
what rank 0's process uses a frame without a panel ("cost": the page's own CPU, which the
machine's noise in rendering does not blur); then rank 0's whole process CPU time over the frame
loop (every thread) and its share over the run without a panel, the emulated frame (the slowest
rank's phase CPU time) and the wall-clock frame. Figures only, no asserts.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import threading
import time
from pathlib import Path

from multigpu.studies.tables import Columns

ARMS = ("off", "closed", "open")
#: where the results go (panel.csv); docs/results/panel/ holds the published ones
OUT = Path("out/panel")


def _read_page(url: str, stop: threading.Event, got: dict) -> None:
    """A page that reads everything (rows, status, thumbnails and their pieces) until ``stop``."""
    from websockets.asyncio.client import connect

    async def run():
        base, query = url.split("?", 1)
        async with connect(base.replace("http", "ws", 1) + "ws?" + query, open_timeout=30, max_size=None) as ws:
            while not stop.is_set():
                try:
                    m = await asyncio.wait_for(ws.recv(), 0.5)
                except asyncio.TimeoutError:
                    continue
                got["thumbs" if isinstance(m, bytes) else "texts"] += 1

    try:
        asyncio.run(run())
    except Exception as exc:  # noqa: BLE001 - the run ended and closed the page
        got["ended"] = f"{exc.__class__.__name__}"


def _one(out: Path, arm: str, frames: int, scene: list[str], timeout: float) -> dict:
    from multigpu.studies.runs import end, start, study_env

    args = ["walkthrough", "--grid", "2x2", "--tile", "256x256", "--frames", str(frames), "--mosaic-every", "0",
            "--no-progress", "--out", str(out), *scene, *(["--panel", "127.0.0.1:0"] if arm != "off" else [])]
    proc = start(4, args, env=study_env(), stdout=subprocess.PIPE)
    stop, got, reader = threading.Event(), {"thumbs": 0, "texts": 0}, None
    try:
        lines = []
        deadline = time.monotonic() + timeout
        for line in proc.stdout:  # the URL comes first, before the frames
            lines.append(line)
            if arm == "open" and "the panel: http" in line:
                url = line.split("the panel: ", 1)[1].strip()
                reader = threading.Thread(target=_read_page, args=(url, stop, got), daemon=True)
                reader.start()
            if time.monotonic() > deadline:
                raise RuntimeError(f"bench panel: a run took over {timeout} s")
        proc.wait(timeout)
        if proc.returncode != 0:
            raise RuntimeError(f"bench panel: the {arm} run failed (exit {proc.returncode}): "
                               f"{''.join(lines)[-1000:]}{proc.stderr.read()[-2000:]}")
    finally:
        stop.set()
        end(proc)
        if reader is not None:
            reader.join(10)
    s = json.loads((out / "summary.json").read_text())
    if arm == "open" and got["thumbs"] < 2:
        raise RuntimeError(f"bench panel: the page got {got['thumbs']} thumbnails: it was not open")
    cpu = s["cpu"]
    return {"rank0_cpu_ms": s["rank0_process_cpu_ms"], "server_cpu_ms": s.get("panel_server_cpu_ms", 0.0),
            "display_cpu_ms": cpu["display_cpu_ms"],
            "emulated_ms": s["emulated_frame_ms"], "wall_ms": s["frame_ms"], "thumbs": got["thumbs"]}


def bench_panel(quick: bool) -> list[dict]:
    frames, rounds = (60, 1) if quick else (400, 3)
    scene = ["--triangles", "20000"] if quick else []
    print(f"bench panel: the plant on a 2x2 wall of 256x256, {frames} frames, {rounds} alternated rounds; "
          "rank 0 = its whole process CPU per frame (ms), emulated = slowest rank's phase CPU (ms), wall = "
          "wall-clock frame (ms); medians; share = over the run without a panel")
    from multigpu.studies.runs import alternated, medians

    got = alternated(ARMS, rounds, lambda arm, folder: _one(folder, arm, frames, scene, 1800))
    table = Columns(("arm", "panel", "<7"), ("server_cpu_ms", "server", "7.3f"), ("display_cpu_ms", "display", "8.3f"),
                    ("cost", "cost", ">7"), ("rank0_cpu_ms", "rank 0", "8.2f"), ("rank0_share", "share", ">7"),
                    ("emulated_ms", "emulated", "9.2f"), ("wall_ms", "wall", "7.2f"), ("thumbs", "thumbnails", "11.0f"))
    print(table.header())
    rows = []
    base = medians(got["off"])
    for arm in ARMS:
        row = medians(got[arm])
        # the page's own CPU on rank 0: its server thread, and what the loop's display phase does more
        own = row["server_cpu_ms"] + max(row["display_cpu_ms"] - base["display_cpu_ms"], 0.0)
        row.update(arm=arm, cost=f"{100 * own / base['rank0_cpu_ms']:.2f}%",
                   rank0_share=f"{100 * (row['rank0_cpu_ms'] / base['rank0_cpu_ms'] - 1):+.1f}%")
        rows.append(row)
        print(table.row(row))
    from multigpu.studies.tables import write_csv

    OUT.mkdir(parents=True, exist_ok=True)
    write_csv(OUT / "panel.csv", [{"frames": frames, "rounds": rounds, **r} for r in rows])
    print(f"results in {OUT}/panel.csv")
    return rows
