"""``multigpu bench stereo``: what a stereo frame costs beside a mono frame of the same wall.

The plant on a 2x2 wall of 256x256 tiles (4 ranks, headless), mono and each stereo mode, in
rotating order over the rounds (this machine is shared and noisy: ratios within a round, medians
over rounds). Per-rank CPU time per frame is the sum of a rank's phase CPU times (balancing,
rendering, exchange, display), averaged over ranks and frames; the emulated frame is the slowest
rank's phase CPU time; wall is the wall-clock frame. Each stereo row gives its ratio to mono
(the issue's goal: at most 1.7x in per-rank CPU time). The modes run as a user runs them (``--eyes
auto``: on this wall the ranks split by eye); the ``joint`` arms give every rank both eyes of its
region instead (``--eyes joint``), so the two ways of sharing the eyes meet in one run; ``passive
own`` gives each eye of each tile a rank of its own (``--eyes own``: 8 ranks, each drawing one
eye of one tile, as a passive wall's projectors each get a GPU), its per-rank CPU against mono's
4 ranks. Figures only, no asserts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.studies.tables import Columns, write_csv

ARMS = ("mono", "side-by-side", "top-bottom", "anaglyph", "passive", "passive own", "side-by-side joint",
        "anaglyph joint")
#: where the results go (stereo.csv); docs/results/stereo/ holds the published ones
OUT = Path("out/stereo")
PHASES = ("load_balancing_cpu_ms", "rendering_cpu_ms", "frame_exchange_cpu_ms", "display_cpu_ms")


def _one(out: Path, arm: str, frames: int, scene: list[str]) -> dict:
    from multigpu.studies.runs import walk

    args = ["--frames", str(frames), "--mosaic-every", "0", "--screen-size", "1.6,1.6", *scene,
            *(["--stereo", arm.split()[0]] if arm != "mono" else []),
            *(["--eyes", arm.split()[1]] if " " in arm else [])]
    run = walk(out, (2, 2), (256, 256), args, 1800, ranks=8 if arm.endswith(" own") else None)
    s = run.summary
    cpu = s["cpu"]
    return {"cpu_ms": sum(cpu[k] for k in PHASES), "render_cpu_ms": cpu["rendering_cpu_ms"],
            "balance_cpu_ms": cpu["load_balancing_cpu_ms"], "exchange_cpu_ms": cpu["frame_exchange_cpu_ms"],
            "emulated_ms": s["emulated_frame_ms"], "wall_ms": s["frame_ms"],
            "bytes": s["bytes_sent_per_frame"]}


def measure(frames: int, rounds: int, scene: list[str]) -> list[dict]:
    """Every arm in rotating order over ``rounds``: each arm's medians and its ratio to mono."""
    from multigpu.studies.runs import alternated, medians

    got = alternated(ARMS, rounds, lambda arm, folder: _one(folder, arm, frames, scene))
    rows = []
    for arm in ARMS:
        row = medians(got[arm])
        row["ratio"] = float(np.median([a["cpu_ms"] / m["cpu_ms"] for a, m in zip(got[arm], got["mono"])]))
        rows.append({"arm": arm, **row})
    return rows


def bench_stereo(quick: bool) -> list[dict]:
    frames, rounds = (40, 1) if quick else (300, 3)
    scene = ["--triangles", "20000"] if quick else []
    print(f"bench stereo: the plant on a 2x2 wall of 256x256, {frames} frames, {rounds} alternated rounds; "
          "cpu = per-rank CPU time per frame (ms, every phase), emulated = slowest rank's phase CPU (ms), wall = "
          "wall-clock frame (ms); medians over rounds; x mono = the ratio of per-rank CPU to mono's in each round")
    table = Columns(("arm", "stereo", "<19"), ("cpu_ms", "cpu", "7.2f"), ("ratio", "x mono", "7.2f"),
                    ("render_cpu_ms", "render", "7.2f"), ("balance_cpu_ms", "balance", "8.2f"),
                    ("exchange_cpu_ms", "exchange", "9.2f"), ("emulated_ms", "emulated", "9.2f"),
                    ("wall_ms", "wall", "7.2f"), ("bytes", "bytes/frame", "12.0f"))
    rows = measure(frames, rounds, scene)
    print(table.header())
    for row in rows:
        print(table.row(row))
    OUT.mkdir(parents=True, exist_ok=True)
    write_csv(OUT / "stereo.csv", [{"frames": frames, "rounds": rounds, **r} for r in rows])
    print(f"results in {OUT}/stereo.csv")
    return rows


def exp_stereo(s, out: Path) -> str:
    """``multigpu experiment stereo``: the stereo modes' cost beside mono (``measure``), for the
    results page."""
    from multigpu.studies.prose import prose
    from multigpu.studies.tables import md_table

    frames, rounds = (40, s.repeat(3)) if s.quick else (s.frames, s.repeat(3))
    rows = measure(frames, rounds, ["--triangles", str(s.triangles)])
    write_csv(out / "stereo.csv", [{"frames": frames, "rounds": rounds, **r} for r in rows])
    by = {r["arm"]: r for r in rows}
    return prose("stereo", "stereo", frames=frames, rounds=rounds, triangles=s.triangles,
                 sbs=by["side-by-side"]["ratio"], tb=by["top-bottom"]["ratio"], ana=by["anaglyph"]["ratio"],
                 passive=by["passive"]["ratio"], own=by["passive own"]["ratio"],
                 sbs_joint=by["side-by-side joint"]["ratio"],
                 ana_joint=by["anaglyph joint"]["ratio"],
                 table=md_table(rows, [("arm", "Stereo", ""), ("cpu_ms", "Per-rank CPU ms", ".2f"),
                                       ("ratio", "x mono", ".2f"), ("render_cpu_ms", "Render ms", ".2f"),
                                       ("balance_cpu_ms", "Balancing ms", ".2f"),
                                       ("exchange_cpu_ms", "Exchange ms", ".2f"),
                                       ("emulated_ms", "Frame (emulated) ms", ".2f"),
                                       ("wall_ms", "Frame (wall) ms", ".2f")]))
