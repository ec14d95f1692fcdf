"""``multigpu bench frame``: where one rank's per-frame CPU goes, phase by phase, outside GL.

One process plays rank 0 of a 2x2 wall along the scene's walkthrough, planning through the
frame loop's own ``core.planner.Planner``: learn (the strategy observes the last frame's
per-rank times, random here), project the bounds (the camera's matrices included), plan
(strategy: tree walk, masks, loads, the frame's work on the canvas), the draw list (run-merged
commands of the rank's mask), the transfer plan and the timing row. learn + project + plan is
the frame loop's balance phase. Each phase is timed with
``time.process_time`` (CPU) per frame; medians are printed, with the C-level calls (numpy
functions and methods, builtins) one frame makes, counted with ``sys.setprofile`` on every
tenth frame (left out of the times).
Rendering and MPI waits are not in it: this is the fixed CPU cost balancing adds to a frame.
``cold`` flushes the caches before every frame, as rendering does in a run; ``fixed`` plans 16
of the scene's objects that way, so it shows what a cold frame costs per step, whatever the
scene holds.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from multigpu.studies.tables import Columns

PHASES = ("learn", "project", "plan", "drawlist", "transfers", "row")


#: objects of a scene ``bench frame``'s ``fixed`` column plans (spread evenly through the scene):
#: what a frame's balancing costs with the caches cold whatever the scene's objects
FEW = 16

#: bytes written between frames by ``frame_phases(cold=True)``: past this machine's caches, as a
#: rank's rendering and its neighbours on the same cores are between two balance phases
EVICT = 64 << 20


def frame_phases(scene, strategy: str = "strips", grid=(2, 2), tile=(256, 256), frames: int = 60,
                 cold: bool = False, path=None) -> dict:
    """Median CPU ms of each per-frame phase (and their total) for rank 0, planned by the frame
    loop's own ``Planner``; ``cold``: the caches are flushed before every frame (``EVICT``
    bytes written, not timed), as in a run, where the renderer runs between two plans;
    ``path``: the camera path (None: the scene's walkthrough of ``frames`` frames)."""
    from multigpu.config import WalkConfig
    from multigpu.core.drawlist import DrawList
    from multigpu.core.work import transfers
    from multigpu.planner import Planner
    from multigpu.records.report import COLUMNS
    from multigpu.scene.paths import generate

    cfg = WalkConfig(grid=tuple(grid), tile=tuple(tile), balance=strategy)
    path = generate("walkthrough", scene, frames) if path is None else path
    planner = Planner(cfg, scene, rank=0)
    draws = DrawList(scene)
    tiles = cfg.canvas.tiles()
    row = np.zeros(len(COLUMNS) + 1)
    col = {c: i for i, c in enumerate(COLUMNS)}
    times = {p: [] for p in PHASES}
    rng = np.random.default_rng(0)
    calls = [0]
    counted = []

    def count(frame, event, arg):  # C-level calls (numpy functions and methods, builtins)
        if event == "c_call":
            calls[0] += 1

    sweep = np.zeros(EVICT, dtype=np.uint8) if cold else None
    for f in range(len(path)):  # frames, not objects
        counting = f % 10 == 9  # every 10th frame counts its calls and is left out of the times
        if sweep is not None:
            sweep += 1
        if counting:
            calls[0] = 0
            sys.setprofile(count)
        camera = path.camera(f)
        marks = [time.process_time()]
        if f:  # the last frame's (random) times, observed where the frame loop does
            planner.observe(f - 1, 1.0 + rng.random(len(tiles)))
        marks.append(time.process_time())
        rects = planner.frame(camera)[3]  # the camera's matrices too, as in the frame loop's balance phase
        marks.append(time.process_time())
        work = planner.work(f, rects)
        marks.append(time.process_time())
        for m in work.masks[0]:
            draws.commands(m)
        marks.append(time.process_time())
        transfers(work, tiles)
        marks.append(time.process_time())
        values = {"frame": f, "rank": 0, "triangles": work.loads[0], "objects": work.objects(0),
                  "pieces": len(work.rects[0]), "load_cv": work.load_cv}
        for c, v in values.items():
            row[col[c]] = v
        marks.append(time.process_time())
        if counting:
            sys.setprofile(None)
            counted.append(calls[0])
            continue
        for p, a, b in zip(PHASES, marks[:-1], marks[1:]):
            times[p].append((b - a) * 1e3)
    med = {p: float(np.median(v)) for p, v in times.items()}
    med["calls"] = int(np.median(counted)) if counted else 0
    med["total"] = float(np.median(np.sum([times[p] for p in PHASES], axis=0)))
    med["balancing"] = float(np.median(np.sum([times[p] for p in ("learn", "project", "plan")], axis=0)))
    return med


def bench_frame(quick: bool) -> list[dict]:
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import generate

    scenes = [("plant", SceneSpec(triangles=20_000 if quick else 100_000)),
              ("city", SceneSpec(scene="city", triangles=20_000 if quick else 100_000))]
    if not quick:  # the 4-plant scene of 4.28 M triangles (issue 24's 130k objects)
        scenes.append(("plant4", SceneSpec(triangles=5_000_000, copies=4)))
    frames = 20 if quick else 120
    rows = []
    print("per-frame CPU ms of rank 0 on a 2x2 wall of 512x512 (process CPU time, median over frames)")
    print("'cold': the balancing with the caches flushed before every frame (64 MiB written, as the renderer and "
          "the ranks sharing the cores do between two plans in a run); 'fixed': the same, cold, with "
          f"{FEW} of the scene's objects (spread through it): what a frame costs whatever its objects")
    table = Columns(("scene", "scene", ">6"), ("objects", "objects", "8d"), ("strategy", "strategy", ">9"),
                    *((p, p, "9.3f") for p in (*PHASES, "total", "balancing")), ("cold", "cold", "6.3f"),
                    ("fixed", "fixed", "6.3f"), ("calls", "calls", "6d"))
    print(table.header())
    for name, spec in scenes:
        scene, _ = load_scene(spec)
        few = scene.objects(np.linspace(0, scene.n_objects - 1, FEW).astype(np.int64))
        path = generate("walkthrough", scene, frames)  # the whole scene's, for its few objects too
        for strategy in ("strips", "time", "cross", "cost", "adaptive", "none") if name != "plant4" else \
                ("strips", "cross", "none"):
            med = frame_phases(scene, strategy, frames=frames)
            cold = frame_phases(scene, strategy, frames=frames, cold=True)["balancing"]
            fixed = frame_phases(few, strategy, frames=frames, cold=True, path=path)["balancing"]
            rows.append({"scene": name, "objects": scene.n_objects, "strategy": strategy, **med, "cold": cold,
                         "fixed": fixed})
            print(table.row(rows[-1]))
    return rows


def bench_growth(quick: bool) -> list[dict]:
    """Per-frame balancer cost (projection + partition, wall ms, median of 5) and peak memory
    against objects, ranks and strips, with the fitted growth."""
    import tracemalloc

    from multigpu.core.balance import partition
    from multigpu.core.bounds import BoxProjector
    from multigpu.core.camera import look_at, perspective
    from multigpu.studies.synthetic import median_ms, synthetic_objects

    sizes = [1_000, 10_000, 100_000] if quick else [1_000, 10_000, 100_000, 1_000_000]
    grids = [(2, 2), (3, 3), (4, 4)]
    view = look_at([-40, -60, 40], [100, 60, 0], [0, 0, 1])
    proj = perspective(60, 1.0, 0.1, 1000)
    rows = []
    table = Columns(("objects", "objects", "9d"), ("ranks", "ranks", "5d"), ("strips", "strips", "6d"),
                    ("ms", "ms", "9.3f"), ("mib", "peak MiB", "9.2f"), ("per_object", "B/object", "9.1f"))
    print(table.header())
    for n in sizes:
        bmin, bmax, _, _, tris = synthetic_objects(n)
        project = BoxProjector(bmin, bmax)
        for g in grids:
            size = (g[1] * 512, g[0] * 512)
            for strips in (64, 2048):
                run = lambda: partition(project(view, proj), tris, g, size, strips)
                ms = median_ms(run, 3 if n >= 1_000_000 else 5)
                tracemalloc.start()
                run()
                peak = tracemalloc.get_traced_memory()[1]
                tracemalloc.stop()
                rows.append({"objects": n, "ranks": g[0] * g[1], "strips": strips, "ms": ms, "peak_bytes": peak})
                print(table.row({**rows[-1], "mib": peak / 2**20, "per_object": peak / n}))
    for k in (4, 9, 16):
        r = [x for x in rows if x["ranks"] == k and x["strips"] == 2048]
        big = [x for x in r if x["objects"] >= 10_000]
        slope = np.polyfit(np.log([x["objects"] for x in big]), np.log([x["ms"] for x in big]), 1)[0]
        print(f"ranks {k:2d}: time grows as objects^{slope:.2f} from 10^4 objects up (fixed cost below)")
    for n in sizes:
        t = {x["ranks"]: x["ms"] for x in rows if x["objects"] == n and x["strips"] == 2048}
        print(f"{n:9d} objects: 16 ranks / 4 ranks = {t[16] / t[4]:.2f}x "
              f"(tree levels 4 / 2 = 2.00x, ranks 16 / 4 = 4.00x)")
    return rows
