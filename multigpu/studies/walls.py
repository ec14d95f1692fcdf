"""Walls as users build them (``experiment walls``): the default strategy and ``none`` on one
rank and on 2x2, 3x3, 4x4 and 6x6 walls of one display, for the plant walk, the city drive and
a scanned mesh, with what render efficiency is made of and what grows with the wall.

Render efficiency = 1-rank render CPU / (K x slowest rank's render CPU) = 1 / (time overlap x
imbalance), where time overlap = the ranks' render CPU summed / the 1-rank render CPU and
imbalance = slowest / mean rank; triangle overlap = the triangles the ranks drew summed / those
one rank drew. Molnar's prediction of the overlap for square regions, O = ((S + s) / S)^2 with
S = sqrt(W H / K) and s the triangle-weighted footprint of what is drawn whole (a part, or an
object kept whole), beside the paper's 4-GPU figure (a whole frame, not rendering alone). The
fixed CPU per rank (balancing, culling, exchange, display) against K says what grows with the wall.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.studies.prose import prose
from multigpu.studies.runs import PAPER, Settings, _plt, walk
from multigpu.studies.tables import md_table, write_csv

GRIDS = ((2, 2), (3, 3), (4, 4), (6, 6))
QUICK_GRIDS = ((1, 2), (2, 2))  # --quick: 2 and 4 ranks, as the suite runs


def _scenes(s: Settings, out: Path) -> dict[str, tuple[list[str], object]]:
    """The three scenes' flags and their ``SceneSpec`` and path kind (for Molnar's prediction)."""
    from multigpu.scene.models import SceneSpec
    from multigpu.studies.payoff import scenes

    flags = scenes(s, out)
    model = flags["scan"][flags["scan"].index("--model") + 1]
    return {"plant": (flags["plant"], (SceneSpec(triangles=s.triangles), "walkthrough")),
            "city": (flags["city"], (SceneSpec(scene="city", triangles=s.triangles), "walkthrough")),
            "scan": (flags["scan"], (SceneSpec(model=model, split="grid:8"), "orbit"))}


def molnar(spec, kind: str, frames: int, size: int, ranks: list[int]) -> dict[int, float]:
    """Molnar's overlap for square regions at each K, over the frames of the scene's path, with
    the footprint of what is drawn whole: each part (an object kept whole is one part)."""
    from multigpu.core.bounds import BoxProjector
    from multigpu.core.camera import frame_matrices
    from multigpu.scene.models import load_scene
    from multigpu.scene.paths import generate

    scene, _ = load_scene(spec)
    path = generate(kind, scene, frames)
    project = BoxProjector(scene.part_bmin, scene.part_bmax)
    weight = np.maximum(scene.part_count // 3, 1)
    sides = []
    for f in range(len(path)):  # frames, not objects
        view, proj, _ = frame_matrices(path.camera(f), (size, size))
        r = project(view, proj)
        on = ~np.isnan(r[:, 0])
        if on.any():
            w = (np.clip(r[on, 2], 0, 1) - np.clip(r[on, 0], 0, 1)) * size
            h = (np.clip(r[on, 3], 0, 1) - np.clip(r[on, 1], 0, 1)) * size
            sides.append(float(np.sqrt(np.average(w * h, weights=weight[on]))))
    side = float(np.mean(sides)) if sides else 0.0
    return {k: ((np.sqrt(size * size / k) + side) / np.sqrt(size * size / k)) ** 2 for k in ranks}


def _metrics(one, run, k: int) -> dict:
    n = min(len(one.rows), len(run.rows))
    base_t = one.col("triangles")[:n, 0]
    base_r = one.col("rendering_cpu_ms")[:n, 0]
    tris, rend = run.col("triangles")[:n], run.col("rendering_cpu_ms")[:n]
    ok = (base_t > 0) & (rend.mean(axis=1) > 0)
    cpu = run.summary["cpu"]
    return {"triangle_overlap": float((tris.sum(axis=1)[ok] / base_t[ok]).mean()),
            "planned_overlap": float((run.col("planned_triangles")[:n].sum(axis=1)[ok] / base_t[ok]).mean()),
            "time_overlap": float((rend.sum(axis=1)[ok] / base_r[ok]).mean()),
            "imbalance": float((rend.max(axis=1)[ok] / rend.mean(axis=1)[ok]).mean()),
            "efficiency": float((base_r[ok] / (k * rend.max(axis=1)[ok])).mean()),
            "balancing_cpu_ms": cpu["load_balancing_cpu_ms"], "culling_cpu_ms": cpu.get("culling_cpu_ms", 0.0),
            "exchange_cpu_ms": cpu["frame_exchange_cpu_ms"], "display_cpu_ms": cpu["display_cpu_ms"],
            "emulated_ms": run.summary["emulated_frame_ms"]}


def exp_walls(s: Settings, out: Path) -> str:
    """Efficiency, overlaps, imbalance and fixed CPU against the wall size (see the module)."""
    from multigpu.config import WalkConfig

    grids = QUICK_GRIDS if s.quick else GRIDS
    size = 192 if s.quick else 768  # one display, divided by every wall (768 = 6 x 128)
    frames = 6 if s.quick else 160  # long enough that the default's first trial is a small part of a run
    default = WalkConfig().balance
    rows = []
    for scene, (flags, (spec, kind)) in _scenes(s, out).items():
        common = [*flags, "--frames", str(frames), "--mosaic-every", "0"]
        one = walk(out / f"{scene}_1x1", (1, 1), (size, size), common, s.timeout)
        pred = molnar(spec, kind, frames, size, [g[0] * g[1] for g in grids])
        for g in grids:
            k = g[0] * g[1]
            for balance in (default, "none"):
                run = walk(out / f"{scene}_{g[0]}x{g[1]}_{balance}", g, (size // g[1], size // g[0]),
                           [*common, "--balance", balance], s.timeout)
                rows.append({"scene": scene, "grid": f"{g[0]}x{g[1]}", "ranks": k, "balance": balance,
                             "objects": run.summary["config"]["scene"]["objects"], **_metrics(one, run, k),
                             "molnar": pred[k]})
    write_csv(out / "walls.csv", rows)
    _plot(rows, out / "walls.png", default)
    paper = PAPER["gpus_frame_ms_1"] / PAPER["gpus_frame_ms_4"] / 4
    return prose(
        "walls", "walls", frames=frames, size=size, walls=", ".join(f"{a}x{b}" for a, b in grids), default=default,
        paper=paper,
        table=md_table(rows, [("scene", "Scene", ""), ("grid", "Wall", ""), ("balance", "Balance", ""),
                        ("efficiency", "Efficiency", ".1%"), ("time_overlap", "Time overlap", ".2f"),
                        ("imbalance", "Imbalance", ".2f"), ("triangle_overlap", "Triangle overlap", ".2f"),
                        ("planned_overlap", "Planned", ".2f"), ("molnar", "Molnar", ".2f"),
                        ("balancing_cpu_ms", "Balancing", ".2f"), ("culling_cpu_ms", "Culling", ".2f"),
                        ("exchange_cpu_ms", "Exchange", ".2f"), ("emulated_ms", "Frame (emulated) ms", ".2f")]))


def _plot(rows: list[dict], path: Path, default: str) -> None:
    plt = _plt()
    fig, ax = plt.subplots(2, 3, figsize=(14, 7))
    panels = [("efficiency", "render efficiency"), ("time_overlap", "time overlap"),
              ("triangle_overlap", "triangle overlap"), ("imbalance", "render imbalance (max/mean)"),
              ("balancing_cpu_ms", "balancing CPU ms per rank"), ("exchange_cpu_ms", "exchange CPU ms per rank")]
    for a, (key, label) in zip(ax.ravel(), panels):
        for scene in dict.fromkeys(r["scene"] for r in rows):
            for balance, style in ((default, "o-"), ("none", "x--")):
                r = [x for x in rows if x["scene"] == scene and x["balance"] == balance]
                a.plot([x["ranks"] for x in r], [x[key] for x in r], style, label=f"{scene} {balance}")
            if key == "triangle_overlap":
                r = [x for x in rows if x["scene"] == scene and x["balance"] == default]
                a.plot([x["ranks"] for x in r], [x["molnar"] for x in r], ":", color="gray")
        if key == "efficiency":
            a.plot([4], [PAPER["gpus_frame_ms_1"] / PAPER["gpus_frame_ms_4"] / 4], "k*", ms=12,
                   label="paper, 4 GPUs (whole frame)")
        a.set(xlabel="ranks (K)", ylabel=label)
        a.grid(alpha=0.3)
    ax[0, 0].legend(fontsize=7)
    ax[0, 2].set_title("dotted: Molnar's prediction", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


HYBRID_GRIDS = ((2, 2), (4, 4))
DECOMPOSITIONS = ("screen", "hybrid", "db")


def exp_hybrid(s: Settings, out: Path) -> str:
    """The wide objects drawn once (``--decomposition hybrid``) against the screen partition with
    parts culled (``screen``, the default) and sort-last for everything (``db``), each with the
    default strategy, on the ``walls`` scenes at 2x2 and 4x4: what drawing them once saves in
    triangles and what their depth pieces cost in pixels."""
    from multigpu.config import WalkConfig

    grids = HYBRID_GRIDS[:1] if s.quick else HYBRID_GRIDS
    size, frames = (192, 6) if s.quick else (768, 60)
    rows = []
    for scene, (flags, _) in _scenes(s, out).items():
        common = [*flags, "--frames", str(frames), "--mosaic-every", "0"]
        one = walk(out / f"{scene}_1x1", (1, 1), (size, size), common, s.timeout)
        for g in grids:
            k = g[0] * g[1]
            for d in DECOMPOSITIONS:
                run = walk(out / f"{scene}_{g[0]}x{g[1]}_{d}", g, (size // g[1], size // g[0]),
                           [*common, "--decomposition", d], s.timeout)
                rows.append({"scene": scene, "grid": f"{g[0]}x{g[1]}", "ranks": k, "decomposition": d,
                             **_metrics(one, run, k)})
    write_csv(out / "hybrid.csv", rows)
    return prose(
        "walls", "hybrid", frames=frames, size=size, walls=" and ".join(f"{a}x{b}" for a, b in grids),
        default=WalkConfig().balance, verdict=_hybrid_verdict(rows),
        table=md_table(rows, [("scene", "Scene", ""), ("grid", "Wall", ""), ("decomposition", "Decomposition", ""),
                        ("triangle_overlap", "Triangle overlap", ".2f"), ("time_overlap", "Time overlap", ".2f"),
                        ("imbalance", "Imbalance", ".2f"), ("efficiency", "Efficiency", ".1%"),
                        ("exchange_cpu_ms", "Exchange ms", ".2f"), ("emulated_ms", "Frame (emulated) ms", ".2f")]))


def _hybrid_verdict(rows: list[dict]) -> str:
    """Per scene and wall: the fastest decomposition, and what the hybrid saved and cost against screen."""
    cases = []
    for key in dict.fromkeys((r["scene"], r["grid"]) for r in rows):
        by = {r["decomposition"]: r for r in rows if (r["scene"], r["grid"]) == key}
        best = min(by.values(), key=lambda r: r["emulated_ms"])
        screen, hybrid = by["screen"], by["hybrid"]
        cases.append(prose("walls", "hybrid-case", scene=key[0], grid=key[1], best=best["decomposition"],
                           hybrid=hybrid["triangle_overlap"], screen=screen["triangle_overlap"],
                           ratio=hybrid["emulated_ms"] / screen["emulated_ms"]))
    won = sorted({f"{r['scene']} {r['grid']}" for r in rows if r["decomposition"] == "hybrid"
                  and r["emulated_ms"] == min(x["emulated_ms"] for x in rows
                                              if (x["scene"], x["grid"]) == (r["scene"], r["grid"]))})
    verdict = prose("walls", "hybrid-won", won=", ".join(won)) if won else prose("walls", "hybrid-lost")
    return prose("walls", "hybrid-verdict", cases="; ".join(cases), verdict=verdict)


SIXTEEN = ("strips", "shares", "cross", "auto")


def exp_sixteen(s: Settings, out: Path) -> str:
    """Balancing a 16-rank wall against this machine's noise floor for the same work: the plant
    walk on a 4x4 wall of 64x64 tiles (a 256x256 display, so 16 ranks fit two cores), each
    strategy's render imbalance and slowest render beside the imbalance identical work shows
    (``bench floor`` with a 64x64 region of a 256x256 display on 16 ranks), and the efficiency
    that floor alone allows at each run's time overlap; alternated rounds, medians."""
    from multigpu.studies.floor import run as floor_run

    frames, tile, n = (6, 32, 2) if s.quick else (120, 64, 4)  # --quick: a 2x2 wall (the suite runs 2-4 ranks)
    side, k, rounds = n * tile, n * n, s.repeat(5)
    scene = ["--triangles", str(s.triangles)]
    common = [*scene, "--frames", str(frames), "--mosaic-every", "0"]
    got: dict[str, list[dict]] = {name: [] for name in SIXTEEN}
    floors = []
    for r in range(rounds):  # rounds alternate the order, so drift hits every strategy alike
        floors.append(floor_run({"plant": scene}, ranks=k, frames=max(frames // 2, 8), timeout=s.timeout, tile=tile,
                                display=side)[0]["imbalance_floor"])
        one = walk(out / "plant_1x1", (1, 1), (side, side), common, s.timeout)
        for name in (SIXTEEN if r % 2 == 0 else SIXTEEN[::-1]):
            run = walk(out / f"plant_{n}x{n}_{name}", (n, n), (tile, tile), [*common, "--balance", name], s.timeout)
            m = _metrics(one, run, k)
            got[name].append({**m, "render_max_ms": float(run.render_max_cpu.mean()), "floor": floors[-1]})
    floor = float(np.median(floors))
    rows = []
    for name, runs in got.items():
        med = {key: float(np.median([x[key] for x in runs])) for key in runs[0]}
        allowed = 1.0 / (med["time_overlap"] * floor)  # the efficiency were the imbalance at the floor
        rows.append({"balance": name, "imbalance": med["imbalance"], "floor": floor,
                     "render_max_ms": med["render_max_ms"], "time_overlap": med["time_overlap"],
                     "efficiency": med["efficiency"], "allowed": allowed, "of_allowed": med["efficiency"] / allowed,
                     "balancing_cpu_ms": med["balancing_cpu_ms"], "emulated_ms": med["emulated_ms"]})
    write_csv(out / "sixteen.csv", rows)
    best = min(rows, key=lambda r: r["imbalance"])
    fastest = min(rows, key=lambda r: r["emulated_ms"])
    return prose(
        "walls", "sixteen", frames=frames, n=n, tile=tile, side=side, k=k, rounds=rounds, best=best["balance"],
        imbalance=best["imbalance"], floor=floor, fastest=fastest["balance"], fastest_ms=fastest["emulated_ms"],
        table=md_table(rows, [("balance", "Balance", ""), ("imbalance", "Render imbalance", ".2f"),
                        ("floor", "Floor", ".2f"), ("render_max_ms", "Slowest render ms", ".2f"),
                        ("time_overlap", "Time overlap", ".2f"), ("efficiency", "Efficiency", ".1%"),
                        ("allowed", "Allowed", ".1%"), ("of_allowed", "Of allowed", ".2f"),
                        ("balancing_cpu_ms", "Balancing ms", ".2f"), ("emulated_ms", "Frame (emulated) ms", ".2f")]))
