"""``multigpu bench moving``: what per-frame balancing buys when the load moves, and what moving costs.

Four parts, headless, 2x2 walls of 256x256 tiles (4 ranks), every figure from the runs'
summaries (per-rank CPU time; the emulated frame is the slowest rank's phase CPU time per frame):

1. **The swarm** (``--scene swarm``, the camera held still over a whole gather-and-scatter
   cycle): the default strategy against ``static`` (the first frame's split, held) and against
   ``none`` (the paper's balancer off), in rotating order over the rounds; the ratios are
   paired within each round, their medians printed.
2. **Balancing and bounds at 100k moving objects**: the swarm of 2 M triangles; the share of the
   emulated frame spent balancing (posing the objects included) and culling.
3. **The plant with 20 % of its objects moving** against the still plant, along its walkthrough,
   alternated (two rounds more than the others: the ratio is near its floor): the emulated
   frame's ratio.
4. **Memory**: the host's peak proportional set size (every rank's ``Pss`` summed) of the moving
   plant and of the 100k swarm against the same scenes at rest (``--anim-speed 0``).
5. **Models that animate** (rigid ``models/pump-running.glb``, skinned ``models/arm.glb``, and
   Khronos' morphing ``AnimatedMorphCube`` where Debian's ``assimp-testmodels`` is installed)
   against themselves at rest, alternated: what their animation adds to the emulated frame.

Results in ``out/moving/`` (``moving.csv``, one row per figure). Figures only, no asserts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.studies.tables import write_csv

OUT = Path("out/moving")
ARMS = ("auto", "static", "none")


def _run(out: Path, args: list[str]) -> dict:
    from multigpu.studies.runs import walk

    s = walk(out, (2, 2), (256, 256), ["--mosaic-every", "0", *args], 3600).summary
    return {"emulated_ms": s["emulated_frame_ms"], "balancing_share": s["balancing_share"],
            "posing_ms": s["cpu"].get("posing_cpu_ms", 0.0), "balancing_ms": s["cpu"]["load_balancing_cpu_ms"],
            "imbalance": s["imbalance_render_cpu"]}


def swarm(frames: int, rounds: int, triangles: int) -> list[dict]:
    """Part 1: each strategy's medians, and the default's speed-up over each (paired by round)."""
    from multigpu.studies.runs import alternated, medians

    scene = ["--scene", "swarm", "--triangles", str(triangles), "--path-kind", "still", "--frames", str(frames)]
    got = alternated(ARMS, rounds, lambda arm, folder: _run(folder, [*scene, "--balance", arm]))
    rows = []
    for arm in ARMS:
        ratio = np.median([o["emulated_ms"] / d["emulated_ms"] for o, d in zip(got[arm], got["auto"])])
        rows.append({"part": "swarm", "arm": arm, **medians(got[arm]), "default_speedup": float(ratio)})
    return rows


def plant(frames: int, rounds: int, triangles: int) -> list[dict]:
    """Part 3: the plant with 20 % of its objects moving against the still plant."""
    from multigpu.studies.runs import alternated, medians

    scene = ["--triangles", str(triangles), "--frames", str(frames)]
    arms = {"still": [], "20% moving": ["--moving", "0.2"]}
    got = alternated(tuple(arms), rounds, lambda arm, folder: _run(folder, [*scene, *arms[arm]]))
    ratio = float(np.median([m["emulated_ms"] / s["emulated_ms"] for m, s in zip(got["20% moving"], got["still"])]))
    return [{"part": "plant", "arm": arm, **medians(got[arm]), "default_speedup": ratio if arm != "still" else 1.0}
            for arm in arms]


def memory(triangles_plant: int, triangles_swarm: int, frames: int) -> list[dict]:
    """Part 4: peak host memory of each moving scene against the same scene at rest."""
    import tempfile

    from multigpu.studies.memory_bench import measure

    rows = []
    with tempfile.TemporaryDirectory() as cache:
        for name, scene, moving in (("plant", ["--triangles", str(triangles_plant)], ["--moving", "0.2"]),
                                    ("swarm", ["--scene", "swarm", "--triangles", str(triangles_swarm)], [])):
            measure(4, 0, cache, 2, scene=scene)  # the cache built first: both arms map it
            rest = measure(4, 0, cache, frames, scene=[*scene, "--anim-speed", "0"])
            moved = measure(4, 0, cache, frames, scene=[*scene, *moving])
            mib = lambda got: got["peak_pss_host"] / 2**20  # noqa: E731
            rows.append({"part": "memory", "arm": name, "rest_mib": mib(rest), "moving_mib": mib(moved),
                         "ratio": mib(moved) / mib(rest)})
    return rows


#: part 5's models: (name, flags); the morph cube where it is installed
MODELS = (("rigid: pump-running", ["--model", "models/pump-running.glb", "--path-kind", "still"]),
          ("skinned: arm", ["--model", "models/arm.glb", "--path-kind", "orbit"]),
          ("morphed: AnimatedMorphCube", ["--model", "/usr/share/assimp/models/glTF2/glTF-Sample-Models/"
                                          "AnimatedMorphCube-glTF/AnimatedMorphCube.gltf", "--path-kind", "still"]))


def models(frames: int, rounds: int) -> list[dict]:
    """Part 5: each animated model against itself at rest (``--anim-speed 0``), paired by round."""
    from multigpu.studies.runs import alternated, medians

    rows = []
    for name, flags in MODELS:
        if not Path(flags[1]).exists():
            continue
        arms = {"at rest": ["--anim-speed", "0"], "animated": []}
        got = alternated(tuple(arms), rounds, lambda arm, folder: _run(folder, [*flags, "--frames", str(frames),
                                                                                 *arms[arm]]))
        extra = float(np.median([a["emulated_ms"] - r["emulated_ms"] for a, r in zip(got["animated"], got["at rest"])]))
        ratio = float(np.median([a["emulated_ms"] / r["emulated_ms"] for a, r in zip(got["animated"], got["at rest"])]))
        rows.append({"part": "model", "arm": name, **medians(got["animated"]), "extra_ms": extra,
                     "default_speedup": ratio})
    return rows


def bench_moving(quick: bool) -> list[dict]:
    frames, rounds = (60, 1) if quick else (240, 3)
    small, big, plant_tris = (20_000, 200_000, 20_000) if quick else (200_000, 2_000_000, 100_000)
    print(f"bench moving: 2x2 walls of 256x256 (4 ranks), {rounds} alternated round(s); per-rank CPU time, "
          "emulated = the slowest rank's phase CPU per frame (ms); medians over rounds")
    rows = swarm(frames, rounds, small)
    for r in rows:
        print(f"  swarm {small // 20} objects, {r['arm']:>6}: emulated {r['emulated_ms']:.2f} ms, render imbalance "
              f"{r['imbalance']:.2f}; the default is {r['default_speedup']:.2f}x faster")
    big_row = _run(OUT / "swarm-100k", ["--scene", "swarm", "--triangles", str(big), "--path-kind", "still",
                                         "--frames", str(max(frames // 4, 20))])
    rows.append({"part": "100k", "arm": "auto", **big_row, "default_speedup": 1.0})
    print(f"  swarm {big // 20} objects: balancing (posing {big_row['posing_ms']:.2f} ms included) and culling "
          f"{big_row['balancing_share']:.1%} of the emulated frame ({big_row['emulated_ms']:.1f} ms)")
    got = plant(frames, rounds + 2, plant_tris)  # a ratio near its floor: more rounds against the noise
    rows += got
    print(f"  plant, 20% of its objects moving: emulated frame {got[1]['default_speedup']:.3f}x the still plant's")
    for r in (got := models(frames // 2, rounds)):
        print(f"  {r['arm']}: animated {r['emulated_ms']:.2f} ms a frame, {r['extra_ms']:+.2f} ms "
              f"({r['default_speedup']:.3f}x) against itself at rest")
    rows += got
    mem = memory(plant_tris, big, 20 if quick else 60)
    for r in mem:
        print(f"  memory, {r['arm']}: {r['moving_mib']:.0f} MiB moving against {r['rest_mib']:.0f} MiB at rest "
              f"({r['ratio']:.3f}x)")
    OUT.mkdir(parents=True, exist_ok=True)
    keys = sorted({k for r in rows + mem for k in r}, key=lambda k: (k not in ("part", "arm"), k))
    write_csv(OUT / "moving.csv", [{k: r.get(k, "") for k in keys} for r in rows + mem])
    print(f"results in {OUT}/moving.csv")
    return rows + mem
