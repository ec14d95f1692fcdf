"""``multigpu bench passes``: what a second render pass costs, and what joining a rank's pieces
and weighing this frame's rects save ``cross``.

Part 1, one pass against two. Along each scene's walkthrough (plant and city, a 2x2 wall of
256x256 tiles), one rank renders its tile alone; its tile and a separate piece of ``w`` pixels
beside it (a second pass: its own clear, draw of every object the piece touches, whole, and
read-back); and the tile and that strip as one rect (one pass). Printed: the extra CPU time of
each over the tile alone, medians over frames.

Part 2, ``cross`` as Equalizer built it and as it is here. One process plays the wall's four
ranks in turn: each renders its pieces (process CPU time) and the strategy learns from those
times, as in a run, in three variants alternated over rounds: ``equalizer`` (Equalizer's layout,
tiles in label order and helpers from a segment's low end, every overlap a helper and every
piece its own pass, and its time model, a rank's time spread evenly over its pixels), ``uniform``
(the joined layout of ``strategies/cross.py`` with that time model) and ``joined`` (the joined
layout and the weighted time model: the default). Printed: render passes per rank, triangles
drawn, mean and slowest rank's render CPU per frame (the slowest is the emulated render),
medians over rounds. The render phase alone: no MPI, no exchange, and the ranks do not share
cores, so the figures are steadier than a run's. It prints figures and asserts nothing.
"""

from __future__ import annotations

import time

import numpy as np

from multigpu.studies.tables import Columns

GRID, TILE = (2, 2), (256, 256)
WIDTHS = (3, 26, 64)  # pixels of the second piece
#: part 2's variants of ``cross``: their options
VARIANTS = {"equalizer": {"layout": "equalizer", "model": "uniform", "min_help": 0.0},  # every overlap helps
            "uniform": {"model": "uniform"}, "joined": {}}


def bench_passes(quick: bool) -> list[dict]:
    from multigpu.gpu.render import RegionRenderer, create_context
    from multigpu.scene.models import SceneSpec, load_scene

    frames, rounds, triangles = (24, 1, 20_000) if quick else (240, 3, 100_000)
    ctx, _ = create_context()
    rows: list[dict] = []
    print(f"bench passes: 2x2 wall of 256x256, walkthrough of {frames} frames, process CPU time; "
          "part 1: one rank's tile with a w-pixel piece as a second pass or joined (extra ms over the tile alone, "
          "median over frames)")
    table = Columns(("scene", "scene", "<6"), ("tile_ms", "tile ms", "8.2f"),
                    *(c for w in WIDTHS for c in ((f"pass_{w}", f"+{w}px pass", "11.3f"),
                                                  (f"joined_{w}", f"+{w}px joined", "12.3f"))))
    print(table.header())
    scenes = {name: load_scene(SceneSpec(scene=name, triangles=triangles))[0] for name in ("plant", "city")}
    for name, scene in scenes.items():
        renderer = RegionRenderer(ctx, scene, (GRID[1] * TILE[0], GRID[0] * TILE[1]))
        row = _pass_cost(scene, renderer, frames)
        rows.append({"scene": name, "part": "passes", **row})
        print(table.row(rows[-1]))
        renderer.release()
    print(f"part 2: cross as Equalizer built it (layout and time model), the joined layout with that time model, "
          f"and the default, {rounds} alternated rounds (medians), render CPU ms per frame")
    table = Columns(("scene", "scene", "<6"), ("variant", "variant", "<10"), ("passes", "passes/rank", "11.2f"),
                    ("tris", "tris/frame", "10.0f"), ("mean_ms", "mean", "7.2f"), ("slowest_ms", "slowest", "8.2f"),
                    ("imb", "imb", "6.3f"))
    print(table.header())
    for name, scene in scenes.items():
        renderer = RegionRenderer(ctx, scene, (GRID[1] * TILE[0], GRID[0] * TILE[1]))
        got: dict[str, list[dict]] = {v: [] for v in VARIANTS}
        for r in range(rounds):
            for variant in (list(VARIANTS) if r % 2 == 0 else list(VARIANTS)[::-1]):
                got[variant].append(_emulate(scene, renderer, frames, VARIANTS[variant]))
        for variant, runs in got.items():
            row = {k: float(np.median([x[k] for x in runs])) for k in runs[0]}
            rows.append({"scene": name, "part": "variants", "variant": variant, **row})
            print(table.row({**rows[-1], "imb": row["slowest_ms"] / row["mean_ms"]}))
        renderer.release()
    return rows


def _frames(scene, frames: int, balance: str):
    from multigpu.config import WalkConfig
    from multigpu.planner import Planner
    from multigpu.scene.paths import generate

    cfg = WalkConfig(grid=GRID, tile=TILE, balance=balance)
    return Planner(cfg, scene, rank=None), generate("walkthrough", scene, frames), cfg


def _pass_cost(scene, renderer, frames: int) -> dict:
    """Extra CPU ms of a w-pixel piece beside the tile, as a second pass and joined (medians)."""
    from multigpu.core.regions import pixel_spans

    planner, path, cfg = _frames(scene, frames, "none")
    tile = tuple(int(v) for v in cfg.canvas.tiles()[1])  # the bottom-left tile; the pieces right of it

    def mask(spans, on, box):
        x0, y0, x1, y1 = box
        return on & (spans[:, 0] < x1) & (spans[:, 2] >= x0) & (spans[:, 1] < y1) & (spans[:, 3] >= y0)

    def cpu(fn) -> float:
        t0 = time.process_time()
        fn()
        return (time.process_time() - t0) * 1e3

    x0, y0, x1, y1 = tile
    got: dict[str, list[float]] = {"tile_ms": []}
    for f in range(len(path)):  # frames, not objects
        view, proj, light, rects = planner.frame(path.camera(f))
        spans, on = pixel_spans(rects, cfg.canvas.size)  # once a frame, outside the timed passes

        def draw(box):
            renderer.render(view, proj, light, box, mask(spans, on, box))

        alone = cpu(lambda: draw(tile))
        got["tile_ms"].append(alone)
        for w in WIDTHS:
            got.setdefault(f"pass_{w}", []).append(cpu(lambda: (draw(tile), draw((x1, y0, x1 + w, y1)))) - alone)
            got.setdefault(f"joined_{w}", []).append(cpu(lambda: draw((x0, y0, x1 + w, y1))) - alone)
    return {k: float(np.median(v)) for k, v in got.items()}


def rank_times(renderer, work, view, proj, light) -> np.ndarray:
    """(K,) process CPU ms of each rank rendering its pieces of ``work``, one rank after another."""
    times = np.zeros(work.ranks)
    for r in range(work.ranks):  # ranks and their pieces: not objects
        t0 = time.process_time()
        for rect, m in zip(work.rects[r], work.masks[r]):
            renderer.render(view, proj, light, rect, m)
        times[r] = (time.process_time() - t0) * 1e3
    return times


def _emulate(scene, renderer, frames: int, options: dict) -> dict:
    """The wall's ranks in turn under ``cross`` with ``options``: their render CPU fed back."""
    from multigpu.strategies.cross import CrossSegment

    planner, path, cfg = _frames(scene, frames, "cross")
    planner.decomposition.strategy = CrossSegment(cfg.grid, cfg.size, cfg.strips, **options)
    slowest, mean, passes, tris = [], [], [], []
    for f in range(len(path)):  # frames, then ranks and their pieces: not objects
        view, proj, light, rects = planner.frame(path.camera(f))
        work = planner.work(f, rects)
        times = rank_times(renderer, work, view, proj, light)
        planner.observe(f, times)
        if f >= 8:  # past the first frames (cross starts from the paper's strips)
            slowest.append(times.max())
            mean.append(times.mean())
            passes.append(np.mean([len(p) for p in work.rects]))
            tris.append(work.loads.sum())
    return {"passes": float(np.mean(passes)), "tris": float(np.mean(tris)), "mean_ms": float(np.mean(mean)),
            "slowest_ms": float(np.mean(slowest))}
