"""``multigpu bench gpu``: the plant on one display divided among 1, 4 and 16 ranks, and the
hybrid decomposition beside the screen partition at 4x4, for a host with a GPU.

One display of 1024x1024 (``--quick``: 256x256, and only 1 and 4 ranks): 1x1, 2x2 and 4x4 walls
of the default strategy, then 4x4 with ``--decomposition hybrid``, 300 frames each (``--quick``:
30), in alternated rounds. Figures are wall time: the frame period (the run's frames per
second), the time outside the timed phases (the rows' gather, waits), the rendering phase, and
the emulated frame (the slowest rank's CPU time); speedup and efficiency are the one-rank frame
period over the K-rank one (and over K). Each run's GL renderer is printed: which GPU its ranks
drew on. On this machine (llvmpipe, ranks > cores) the wall figures are not parallel figures.
Prints figures and writes ``gpu.json`` in ``--out``; asserts nothing.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from multigpu.studies.tables import Columns

CONFIGS = (("1x1", (1, 1), []), ("2x2", (2, 2), []), ("4x4", (4, 4), []),
           ("4x4 hybrid", (4, 4), ["--decomposition", "hybrid"]))


def bench_gpu(quick: bool, out: Path = Path("out/gpu"), rounds: int = 2) -> dict:
    from multigpu.studies.runs import walk

    side, frames = (256, 30) if quick else (1024, 300)
    configs = CONFIGS[:2] if quick else CONFIGS
    rounds = 1 if quick else rounds
    out = Path(out)
    got: dict[str, list[dict]] = {name: [] for name, _, _ in configs}
    print(f"bench gpu: the plant (--triangles 100000) on one {side}x{side} display, {frames} frames, "
          f"{rounds} alternated round(s); wall ms (frame period, outside the phases, rendering), "
          "emulated = slowest rank's CPU per frame")
    for r in range(rounds):
        for name, grid, extra in configs:
            tile = (side // grid[1], side // grid[0])
            run = walk(out / f"r{r}_{name.replace(' ', '_')}", grid, tile,
                       ["--triangles", "100000", "--frames", str(frames), "--mosaic-every", "0", *extra], 900)
            s = run.summary
            got[name].append({"frame_ms": s["frame_ms"], "outside_ms": s["outside_phases_ms"],
                              "render_ms": s["wall"]["rendering_ms"], "emulated_ms": s["emulated_frame_ms"],
                              "triangles": s["triangles_per_frame"],
                              "renderer": sorted({str(p.get("gl_renderer")) for p in s["config"]["ranks"]})})
    med = {n: {k: float(np.median([x[k] for x in v])) for k in v[0] if k != "renderer"} for n, v in got.items()}
    one = med["1x1"]["frame_ms"]
    table = Columns(("wall", "wall", ">11"), ("frame_ms", "frame ms", "9.2f"), ("outside_ms", "outside", "8.2f"),
                    ("render_ms", "render", "7.2f"), ("emulated_ms", "emulated", "9.2f"),
                    ("triangles", "triangles", "10.0f"), ("speedup", "speedup", "8.2f"),
                    ("efficiency", "efficiency", "10.3f"), ("renderer", " GL renderer", "<"))
    print(table.header())
    for name, grid, _ in configs:
        m, k = med[name], grid[0] * grid[1]
        m["speedup"] = one / m["frame_ms"]
        m["efficiency"] = m["speedup"] / k
        print(table.row({**m, "wall": name, "renderer": " " + ", ".join(got[name][0]["renderer"])}))
    if "4x4 hybrid" in med:
        print(f"4x4 hybrid over screen: frame period {med['4x4 hybrid']['frame_ms'] / med['4x4']['frame_ms']:.2f}x, "
              f"triangles drawn {med['4x4 hybrid']['triangles'] / med['4x4']['triangles']:.2f}x")
    doc = {"display": side, "frames": frames, "rounds": rounds, "runs": got, "medians": med}
    out.mkdir(parents=True, exist_ok=True)
    (out / "gpu.json").write_text(json.dumps(doc, indent=1))
    return doc
