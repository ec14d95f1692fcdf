"""``multigpu bench latency``: what frames in flight buy and cost. The default plant walk and the
city drive on 4 ranks at ``--latency`` 0, 1 and 2, in rotating order over the rounds: the wall
time per frame (the frame period averaged over the ranks), the emulated frame (the slowest
rank's CPU time: the work, which frames in flight do not change) and the input-to-photon
latency, medians over the rounds; the cut in wall time against ``--latency 0``. The runs are a
user's (each rank chooses its raster threads, ``gpu.render.raster_threads``): the wall time is
what is measured, and with a raster thread per rank on a machine the ranks fill, the frames in
flight buy far less. Writes ``latency.csv`` (docs/results/latency/ for the docs' figures).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from multigpu.studies.tables import Columns, write_csv

SCENES = {"plant": ["--scene", "plant"], "city": ["--scene", "city"]}
LATENCIES = (0, 1, 2)


def bench_latency(quick: bool, out: str = "out/latency", rounds: int = 2, timeout: float = 900) -> list[dict]:
    """Run, print and write the table; its rows."""
    frames = 40 if quick else 240
    rounds = 1 if quick else rounds
    with tempfile.TemporaryDirectory(prefix="multigpu-latency-") as tmp:  # the runs' own outputs: not kept
        got = _runs(Path(tmp), frames, rounds, timeout)
    return _table(got, frames, rounds, Path(out))


def _runs(dest: Path, frames: int, rounds: int, timeout: float) -> dict:
    """(scene, latency) -> [(wall, emulated, input-to-photon ms, frames)] over the rounds."""
    from multigpu.config import WalkConfig
    from multigpu.studies.runs import walk

    got: dict = {}
    for r in range(rounds):
        for name, flags in SCENES.items():
            order = LATENCIES[r % len(LATENCIES):] + LATENCIES[:r % len(LATENCIES)]  # rotating: drift falls alike
            for latency in order:
                s = walk(dest / f"{name}-{latency}-{r}", WalkConfig.grid, WalkConfig.tile,
                         [*flags, "--frames", str(frames), "--latency", str(latency)], timeout, as_run=True).summary
                got.setdefault((name, latency), []).append(
                    (s["frame_ms"], s["emulated_frame_ms"], s["input_to_photon_ms"], s["input_to_photon_frames"]))
    return got


def _table(got: dict, frames: int, rounds: int, dest: Path) -> list[dict]:
    """Medians per (scene, latency), the cut against latency 0; printed and written."""
    import numpy as np

    rows = []
    for (name, latency), runs in got.items():
        wall, emulated, photon, frames_late = (float(np.median(v)) for v in zip(*runs))
        rows.append({"scene": name, "latency": latency, "wall_ms": wall, "emulated_ms": emulated,
                     "input_to_photon_ms": photon, "input_to_photon_frames": frames_late, "rounds": rounds})
    for row in rows:
        base = next(b for b in rows if b["scene"] == row["scene"] and b["latency"] == 0)
        row["wall_cut"] = 1.0 - row["wall_ms"] / base["wall_ms"]
    dest.mkdir(parents=True, exist_ok=True)
    write_csv(dest / "latency.csv", rows, ".3f")
    print(f"frames in flight, 4 ranks, {frames} frames, {rounds} rotated rounds, medians:")
    table = Columns(("scene", "scene", ">6"), ("latency", "latency", "7d"), ("wall_ms", "wall ms", "8.2f"),
                    ("wall_cut", "cut", "6.0%"), ("emulated_ms", "emulated ms", "11.2f"),
                    ("photon", "input to photon", ">16"))
    print(table.header())
    for row in rows:
        photon = f"{row['input_to_photon_ms']:8.1f} ms {row['input_to_photon_frames']:4.2f} fr"
        print(table.row({**row, "photon": photon}))
    sys.stdout.flush()
    return rows
