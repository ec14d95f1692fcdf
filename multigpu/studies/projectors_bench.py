"""``multigpu bench projectors``: what driving a projector wall costs beside the same content on
monitors.

Three 1920x1080 projectors on a flat screen, 18 % overlap (``warp make``'s rig, its MPCDI file
written here), three ranks, headless, the default walk: ``projectors`` runs the wall file naming
that file (each rank composes its projector's region of the canvas, overlaps included, and makes
its picture in one GPU pass: warp, blend in linear light, colour); ``monitors`` runs the same walk
on a 1x3 wall of 1920x1080 tiles without a pass. The arms alternate over the rounds (this machine
is shared and noisy: ratios within a round, medians over rounds). Per-rank CPU time per frame is
the sum of a rank's phase CPU times (process CPU, llvmpipe's threads included), averaged over
ranks and frames. The pass's cost is the display phase's CPU beyond the monitors' (where the pass
runs: the tile uploaded, the draw, the picture read back), against the monitors' whole frame: the
issue's goal is at most 10 %. Figures only, no asserts.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from multigpu.studies.tables import Columns, write_csv

ARMS = ("monitors", "projectors")
#: where the results go (projectors.csv, the rig's files); docs/results/projectors/ holds the published ones
OUT = Path("out/projectors")
PHASES = ("load_balancing_cpu_ms", "rendering_cpu_ms", "frame_exchange_cpu_ms", "display_cpu_ms")


def rig_wall(folder: Path, size: tuple[int, int]) -> Path:
    """A wall file of three projectors of ``size`` side by side (their MPCDI file beside it)."""
    from multigpu.warp import make, mpcdi
    from multigpu.warp.rig import flat_rig

    canvas = (3 * size[0], size[1])
    folder.mkdir(parents=True, exist_ok=True)
    rig = flat_rig(3, 0.18, size, aspect=canvas[0] / canvas[1])
    mpcdi.write(folder / "rig.mpcdi", canvas, make.outputs(rig, canvas))
    (folder / "wall.json").write_text(json.dumps({"mpcdi": "rig.mpcdi"}))
    return folder / "wall.json"


def _one(out: Path, arm: str, wall: Path, size: tuple[int, int], frames: int, scene: list[str]) -> dict:
    from multigpu.studies.runs import walk

    args = ["--frames", str(frames), "--mosaic-every", "0", *scene]
    run = walk(out, (1, 3), None, ["--wall", str(wall), *args], 3600) if arm == "projectors" else \
        walk(out, (1, 3), size, args, 3600)
    s = run.summary
    cpu = s["cpu"]
    return {"cpu_ms": sum(cpu[k] for k in PHASES), "render_cpu_ms": cpu["rendering_cpu_ms"],
            "exchange_cpu_ms": cpu["frame_exchange_cpu_ms"], "display_cpu_ms": cpu["display_cpu_ms"],
            "wall_ms": s["frame_ms"], "tile_px": s["config"]["tile"][0] * s["config"]["tile"][1]}


def measure(size: tuple[int, int], frames: int, rounds: int, scene: list[str], folder: Path) -> list[dict]:
    """Both arms in rotating order over ``rounds``: each arm's medians; the projectors' the pass's
    CPU (display beyond the monitors', in the same round) and its share of the monitors' frame."""
    from multigpu.studies.runs import alternated, medians

    wall = rig_wall(folder, size)
    got = alternated(ARMS, rounds, lambda arm, f: _one(f, arm, wall, size, frames, scene))
    mon, pro = got["monitors"], got["projectors"]
    rows = [{"arm": "monitors", **medians(mon), "pass_ms": 0.0, "pass_share": 0.0, "ratio": 1.0}]
    passes = [p["display_cpu_ms"] - m["display_cpu_ms"] for p, m in zip(pro, mon)]
    rows.append({"arm": "projectors", **medians(pro), "pass_ms": float(np.median(passes)),
                 "pass_share": float(np.median([x / m["cpu_ms"] for x, m in zip(passes, mon)])),
                 "ratio": float(np.median([p["cpu_ms"] / m["cpu_ms"] for p, m in zip(pro, mon)]))})
    return rows


def bench_projectors(quick: bool) -> list[dict]:
    size, frames, rounds = ((480, 270), 30, 1) if quick else ((1920, 1080), 120, 3)
    scene = ["--triangles", "20000"] if quick else []
    print(f"bench projectors: three {size[0]}x{size[1]} projectors (18 % overlap) against a 1x3 wall of "
          f"{size[0]}x{size[1]} monitors, the default walk, {frames} frames, {rounds} alternated rounds; cpu = "
          "per-rank CPU time per frame (ms, every phase, process CPU), pass = the output pass's CPU (display beyond "
          "the monitors'), share = pass / the monitors' frame; wall = wall-clock frame (ms); medians over rounds")
    table = Columns(("arm", "wall of", "<11"), ("tile_px", "tile px", "9.0f"), ("cpu_ms", "cpu", "8.2f"),
                    ("ratio", "x monitors", "11.2f"), ("render_cpu_ms", "render", "8.2f"),
                    ("exchange_cpu_ms", "exchange", "9.2f"), ("display_cpu_ms", "display", "8.2f"),
                    ("pass_ms", "pass", "7.2f"), ("pass_share", "share", "7.3f"), ("wall_ms", "wall", "8.2f"))
    rows = measure(size, frames, rounds, scene, OUT / "rig")
    print(table.header())
    for row in rows:
        print(table.row(row))
    OUT.mkdir(parents=True, exist_ok=True)
    write_csv(OUT / "projectors.csv", [{"output": f"{size[0]}x{size[1]}", "frames": frames, "rounds": rounds, **r}
                                       for r in rows])
    print(f"results in {OUT}/projectors.csv")
    return rows
