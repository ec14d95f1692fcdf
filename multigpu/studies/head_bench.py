"""``multigpu bench head``: motion to photon for a tracked head.

A side-by-side stereo walk (the plant, a 2x2 wall of 256x256 tiles, 4 ranks, headless) whose head
comes over UDP (``--head-tracker``) from a tracker in this process sending a moving pose at 120 Hz,
at ``--latency`` 0, 1 and 2 in rotating order over the rounds. Motion to photon is rank 0's figure
(summary.json): from the moment a frame's pose arrived at rank 0 to that frame shown on rank 0's
display. Figures only, no asserts.
"""

from __future__ import annotations

import json
import math
import socket
import threading
from pathlib import Path

from multigpu.studies.tables import Columns, write_csv

LATENCIES = (0, 1, 2)
RATE = 120.0  # poses a second, as an optical tracker sends them
#: where the results go (head.csv); docs/results/head/ holds the published ones
OUT = Path("out/head")


def _free_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def _tracker(port: int, stop: threading.Event) -> None:
    """A head swaying 0.3 m left and right every two seconds, 2 m from the wall."""
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    k = 0
    while not stop.is_set():
        x = 0.3 * math.sin(2 * math.pi * k / (2 * RATE))
        out.sendto(json.dumps({"position": [x, 0.0, 2.0]}).encode(), ("127.0.0.1", port))
        k += 1
        stop.wait(1.0 / RATE)
    out.close()


def _one(out: Path, latency: int, frames: int, scene: list[str]) -> dict:
    from multigpu.studies.runs import walk

    port = _free_port()
    stop = threading.Event()
    sender = threading.Thread(target=_tracker, args=(port, stop), daemon=True)
    sender.start()
    try:
        run = walk(out, (2, 2), (256, 256), ["--frames", str(frames), "--mosaic-every", "0", "--stereo",
                                             "side-by-side", "--screen-size", "1.6,1.6", "--latency", str(latency),
                                             "--head-tracker", f"127.0.0.1:{port}", *scene], 1800)
    finally:
        stop.set()
        sender.join(5)
    s = run.summary
    if not s.get("head_poses_received"):
        raise RuntimeError("bench head: no pose reached the wall")
    return {"photon_ms": s["head_to_photon_ms_median"], "photon_p99_ms": s["head_to_photon_ms_p99"],
            "frame_ms": s["frame_ms"], "poses": s["head_poses_received"]}


def bench_head(quick: bool) -> list[dict]:
    frames, rounds = (60, 1) if quick else (300, 3)
    scene = ["--triangles", "20000"] if quick else []
    print(f"bench head: the plant side by side on a 2x2 wall of 256x256, {frames} frames, {rounds} alternated "
          f"rounds, poses at {RATE:g} Hz over UDP; motion to photon = a pose reaching rank 0's host to its frame "
          "shown there (ms, median and 99th percentile), frame = wall-clock frame (ms); medians over rounds")
    from multigpu.studies.runs import alternated, medians

    got = alternated(LATENCIES, rounds, lambda n, folder: _one(folder, n, frames, scene))
    table = Columns(("latency", "latency", ">7"), ("photon_ms", "photon", "7.1f"), ("photon_p99_ms", "p99", "6.1f"),
                    ("frame_ms", "frame", "6.1f"), ("poses", "poses", "6.0f"))
    print(table.header())
    rows = []
    for n in LATENCIES:
        row = medians(got[n])
        row["latency"] = n
        rows.append(row)
        print(table.row(row))
    OUT.mkdir(parents=True, exist_ok=True)
    write_csv(OUT / "head.csv", [{"frames": frames, "rounds": rounds, **r} for r in rows])
    print(f"results in {OUT}/head.csv")
    return rows
