"""``multigpu bench exchange``: the frame exchange by messages against the node-shared segment.

The plant walkthrough and the city drive on a 2x2 wall of 256x256 tiles, under ``cross`` (pieces
travel between ranks) and ``none`` (each rank keeps its own tile: nothing travels), each run with
``--exchange messages`` and ``--exchange shared`` in alternating order over the rounds. It prints
the emulated frame (the slowest rank's CPU time per frame, mean), the exchange CPU per rank, the
wall-clock frame and the exchange's wall time (means over frames and ranks, from frame 20 on),
and the bytes a rank sends per frame; medians over rounds. It prints figures and asserts nothing.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from multigpu.studies.tables import Columns

SCENES = ("city", "plant")
BALANCES = ("cross", "none")
EXCHANGES = ("messages", "shared")
SKIP = 20  # frames left out at the start (caches, cross's first frames)


def bench_exchange(quick: bool) -> list[dict]:
    from multigpu.studies.runs import walk

    frames, rounds, triangles = (24, 1, 20_000) if quick else (240, 2, 100_000)
    skip, timeout = (4, 300) if quick else (SKIP, 1800)
    rows = []
    print(f"bench exchange: 2x2 wall of 256x256, {frames} frames, --triangles {triangles}, {rounds} alternated "
          f"rounds (medians); emulated = slowest rank's CPU per frame, exchange CPU per rank, wall-clock frame "
          f"and exchange, ms, frames {skip}+")
    table = Columns(("scene", "scene", "<6"), ("balance", "balance", "<7"), ("exchange", "exchange", "<9"),
                    ("emulated_ms", "emulated", "9.2f"), ("exchange_cpu_ms", "exch CPU", "9.3f"),
                    ("wall_ms", "wall", "8.2f"), ("exchange_ms", "exch wall", "10.3f"),
                    ("bytes_sent", "bytes/rank", "11.0f"))
    print(table.header())
    with tempfile.TemporaryDirectory() as tmp:
        for scene in SCENES:
            for balance in BALANCES:
                got: dict[str, list[dict]] = {x: [] for x in EXCHANGES}
                for r in range(rounds):
                    for exchange in (EXCHANGES if r % 2 == 0 else EXCHANGES[::-1]):
                        out = Path(tmp) / f"{scene}_{balance}_{exchange}_{r}"
                        run = walk(out, (2, 2), (256, 256), ["--scene", scene, "--triangles", str(triangles),
                                                             "--frames", str(frames), "--balance", balance,
                                                             "--exchange", exchange, "--mosaic-every", "0"], timeout)
                        got[exchange].append(_figures(run, skip))
                for exchange, runs in got.items():
                    row = {k: float(np.median([x[k] for x in runs])) for k in runs[0]}
                    row.update(scene=scene, balance=balance, exchange=exchange)
                    rows.append(row)
                    print(table.row(row))
    return rows


def _figures(run, skip: int) -> dict:
    """One run's means over its frames from ``skip`` on."""
    cpu = sum(run.col(c) for c in ("load_balancing_cpu_ms", "rendering_cpu_ms", "frame_exchange_cpu_ms",
                                   "display_cpu_ms"))[skip:]
    return {"emulated_ms": float(cpu.max(axis=1).mean()),
            "exchange_cpu_ms": float(run.col("frame_exchange_cpu_ms")[skip:].mean()),
            "wall_ms": float(run.col("frame_ms")[skip:].mean()),
            "exchange_ms": float(run.col("frame_exchange_ms")[skip:].mean()),
            "bytes_sent": float(run.col("bytes_sent")[skip:].mean())}
