"""Benchmarks (``multigpu bench balance|scene|render [--quick]``): they print figures, never assert.

Figures are wall time (``time.perf_counter``) medians over repeats in one process, so ratios
between rows of one run are the meaningful comparison on a shared machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from multigpu.errors import InputError
from multigpu.studies.synthetic import median_ms, synthetic_objects
from multigpu.studies.tables import Columns


def bench_balance(quick: bool) -> list[dict]:
    from multigpu.core.balance import partition
    from multigpu.core.bounds import BoxProjector
    from multigpu.core.camera import look_at, perspective
    from multigpu.core.memory import keep_heap
    from multigpu.core.spheres import SphereProjector

    sizes = [10_000, 100_000] if quick else [100_000, 1_000_000]
    view = look_at([-40, -60, 40], [100, 60, 0], [0, 0, 1])
    proj = perspective(60, 1.0, 0.1, 1000)
    rows = []
    heap = keep_heap()
    print("per-frame wall time, median of 7; bounds prepared once per scene (not timed); "
          f"allocator: {'heap kept (memory.keep_heap)' if heap else 'glibc default (MULTIGPU_MALLOC=default)'}")
    from multigpu import kernels

    warmed = f"compiled/loaded in {kernels.warm():.2f} s" if kernels.available() else "absent"
    print(f"compiled kernel (numba): {warmed}"
          "; 'numpy ms' is the reference partition, 'partition ms' the one runs use")
    table = Columns(("objects", "objects", "9d"), ("grid", "grid", "<5"), ("bounds", "bounds", ">7"),
                    ("project_ms", "project ms", "11.1f"), ("numpy_ms", "numpy ms", "9.1f"),
                    ("partition_ms", "partition ms", "13.1f"), ("total_ms", "total ms", "9.1f"),
                    ("target", "target ms", ">10"))
    print(table.header())
    for n in sizes:
        bmin, bmax, c, r, tris = synthetic_objects(n)
        for grid in [(2, 2), (4, 4)]:
            size = (1024 * grid[1], 1024 * grid[0])
            for kind in ("box", "sphere"):
                project = BoxProjector(bmin, bmax) if kind == "box" else SphereProjector(c, r)
                rects = project(view, proj)
                t_proj = median_ms(lambda: project(view, proj), 7)
                t_ref = median_ms(lambda: partition(rects, tris, grid, size, 2048, compiled=False), 7)
                t_part = median_ms(lambda: partition(rects, tris, grid, size, 2048), 7)
                t_all = median_ms(lambda: partition(project(view, proj), tris, grid, size, 2048), 7)
                target = 30.0 if (n, grid, kind) == (1_000_000, (2, 2), "box") else None  # issue 24's target
                rows.append({"objects": n, "grid": f"{grid[0]}x{grid[1]}", "bounds": kind, "project_ms": t_proj,
                             "numpy_ms": t_ref, "partition_ms": t_part, "total_ms": t_all, "target_ms": target,
                             "heap_kept": heap})
                print(table.row({**rows[-1], "target": "" if target is None else f"{target:.0f}"}))
    return rows


_SCENE_CHILD = """
import json, resource, sys, time
from multigpu.scene.models import SceneSpec, load_scene
spec = SceneSpec(triangles=int(sys.argv[1]))
t = time.perf_counter(); scene, info = load_scene(spec); dt = time.perf_counter() - t
print(json.dumps({"seconds": dt, "cached": info["cached"], "triangles": scene.n_triangles,
                  "bytes": scene.nbytes, "peak_rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
"""


def bench_scene(quick: bool) -> list[dict]:
    """First (built) and cached load of the plant, each in a fresh process for honest peak memory."""
    import tempfile

    sizes = [100_000, 1_000_000] if quick else [1_000_000, 10_000_000]
    rows = []
    base = json.loads(subprocess.run([sys.executable, "-c",
                                      "import resource, json, multigpu.scene.models, multigpu.scene.plant;"
                                      "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)"],
                                     capture_output=True, text=True, check=True).stdout)
    print(f"interpreter + imports peak RSS: {base / 2**20:.0f} MiB")
    table = Columns(("target", "target tris", "12d"), ("triangles", "triangles", "10d"), ("load", "load", ">7"),
                    ("seconds", "seconds", "8.2f"), ("mib", "arrays MiB", "11.1f"), ("per_tri", "B/tri", "6.1f"),
                    ("rss_mib", "peak RSS MiB", "13.0f"), ("above", "(RSS-base)/tri", "15.1f"))
    print(table.header())
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "MULTIGPU_CACHE": cache}
        for n in sizes:
            for attempt in ("first", "cached"):
                out = subprocess.run([sys.executable, "-c", _SCENE_CHILD, str(n)], capture_output=True, text=True,
                                     env=env, check=True).stdout
                d = json.loads(out)
                d.update(target=n, load=attempt)
                rows.append(d)
                print(table.row({**d, "mib": d["bytes"] / 2**20, "per_tri": d["bytes"] / d["triangles"],
                                 "rss_mib": d["peak_rss"] / 2**20, "above": (d["peak_rss"] - base) / d["triangles"]}))
    return rows


def _quad_grid_scene(g: int, blocks: int):
    """The same ``2 g^2`` triangles (a ``g x g`` grid of quads over NDC [-1, 1]^2, depths
    varying) grouped into ``blocks^2`` objects of ``(g/blocks)^2`` quads each."""
    from multigpu.scene.layout import assemble

    b = g // blocks
    n = blocks * blocks
    oi, oj = np.divmod(np.arange(n), blocks)  # object block row / column
    qi, qj = np.divmod(np.arange(b * b), b)  # quad within the block
    x0 = ((oj[:, None] * b + qj[None, :]) / g * 2 - 1)  # (n, b*b)
    y0 = ((oi[:, None] * b + qi[None, :]) / g * 2 - 1)
    d = 2 / g
    z = 0.5 * np.sin(x0 * 7.0) * np.cos(y0 * 5.0)
    pos = np.zeros((n, b * b, 4, 3))
    for k, (dx, dy) in enumerate(((0, 0), (d, 0), (d, d), (0, d))):  # 4 corners, not objects
        pos[:, :, k, 0], pos[:, :, k, 1], pos[:, :, k, 2] = x0 + dx, y0 + dy, z
    pos = pos.reshape(n, b * b * 4, 3)
    nrm = np.zeros_like(pos)
    nrm[..., 2] = 1
    quad = np.array([0, 1, 2, 0, 2, 3])
    idx = (np.arange(b * b)[:, None] * 4 + quad[None, :]).ravel()
    rng = np.random.default_rng(0)
    return assemble([(pos, nrm, idx, rng.uniform(0.3, 0.9, (n, 3)))], f"quads-{n}", {})


def bench_render(quick: bool) -> list[dict]:
    """Per-frame cost against object count, and the indirect path against one bare draw.

    The same triangles are drawn as about 10^3 and 10^5 objects, in three frames: everything
    visible on the whole display; one rank's quarter region with the objects that overlap it
    (what a 2 x 2 wall's rank draws); and a scattered half of the objects (the worst case for
    merged runs). Wall time per frame including the region's read-back, median of 7.
    """
    from multigpu.gpu.render import RegionRenderer, create_context

    ctx, _ = create_context()
    g = 320 if quick else 640
    size = (512, 512)
    W, H = size
    eye, light = np.eye(4), np.array([0, 0, 1.0])
    rows = []
    print("wall ms per frame, median of 7; 'bare' is one vao.render of every triangle (no culling)")
    table = Columns(("frame", "frame", ">9"), ("objects", "objects", "8d"), ("triangles", "triangles", "10d"),
                    ("commands", "commands", "9d"), ("indirect_ms", "indirect ms", "12.2f"),
                    ("bare_ms", "bare ms", "8.2f"), ("vs_bare", "vs bare", "8.2f"))
    print(table.header())
    for blocks in (32, 320):  # 1024 and 102400 objects
        scene = _quad_grid_scene(g, blocks)
        n = scene.n_objects
        r = RegionRenderer(ctx, scene, size, "scissor")  # one full-size framebuffer, as 'bare' uses
        total = scene.indices.size

        def bare():
            r.fbo.use()
            r.fbo.viewport = (0, 0, *size)
            r.fbo.scissor = (0, 0, *size)
            r.fbo.clear(0, 0, 0, 1, depth=1.0)
            r.prog["mvp"].write(np.eye(4, dtype=np.float32))
            r.cbo.bind_to_storage_buffer(0)
            r.vao.render(vertices=total)
            r.fbo.read(viewport=(0, 0, *size), components=3, alignment=1)

        t_bare = median_ms(bare, 7)
        quarter = (scene.bmin[:, 0] <= 0) & (scene.bmin[:, 1] <= 0)
        scattered = np.random.default_rng(1).random(n) < 0.5
        for frame, region, mask in (("all", (0, 0, W, H), np.ones(n, bool)),
                                    ("quarter", (0, 0, W // 2, H // 2), quarter),
                                    ("scattered", (0, 0, W, H), scattered)):
            t = median_ms(lambda: r.render(eye, eye, light, region, mask), 7)
            rows.append({"frame": frame, "objects": n, "triangles": int(scene.tris[mask].sum()),
                         "commands": r.last_commands, "indirect_ms": t, "bare_ms": t_bare})
            print(table.row({**rows[-1], "vs_bare": t / t_bare}))
        r.release()
    by = {(d["frame"], d["objects"]): d["indirect_ms"] for d in rows}
    for frame in ("all", "quarter", "scattered"):
        ratio = by[(frame, 102400)] / by[(frame, 1024)]
        print(f"{frame}: 10^5 / 10^3 objects frame time {ratio:.2f}")
    return rows


def help_for(name: str, bench) -> str:
    """``multigpu bench NAME --help``: what the benchmark measures and the flags it reads (the
    ``bench`` parser's own entries for them)."""
    import argparse

    from multigpu.studies.registry import BENCH_FLAGS, BENCHES

    p = argparse.ArgumentParser(prog=f"multigpu bench {name}", description=BENCHES[name][1])
    wanted = set(BENCH_FLAGS.get(name, ("--quick",)))
    for action in bench._actions:  # a dozen
        if wanted & set(action.option_strings):
            p._add_action(action)
    return p.format_help()


def run_args(args) -> int:
    """``multigpu bench NAME ...``: the benchmark ``args.what`` with the command line's arguments
    (those that take only ``--quick`` through ``main``)."""
    if args.what == "floor" and args.worker:  # the MPI side, started by bench floor
        from multigpu.flags import spec
        from multigpu.rank import floor

        floor.main(spec(args), args.path_kind, args.frames or 120, args.tile, args.display)
        return 0
    if args.what == "latency":
        from multigpu.studies.latency import bench_latency

        bench_latency(args.quick, out=args.out if args.out != "out/peer" else "out/latency",
                      rounds=args.rounds)
        return 0
    if args.what == "simplify":
        from multigpu.studies.simplify import bench_simplify

        bench_simplify(args.model, args.quick, out=args.out if args.out != "out/peer" else "out/simplify")
        return 0
    if args.what == "timeline":
        from multigpu.studies.timeline import bench_timeline

        bench_timeline(args.quick, out=args.out if args.out != "out/peer" else "out/timeline")
        return 0
    if args.what == "peer":
        from multigpu.studies.peer import bench_peer

        if not args.model:
            raise InputError("bench peer: --model FILE is needed (the model both renderers draw)")
        bench_peer(args.model, args.split, tuple(ranks_list(args.ranks)), args.frames or 150,
                   rounds=args.rounds, out=args.out)
        return 0
    if args.what == "floor":
        return _bench_floor(args)
    return main(args.what, quick=args.quick)


def _bench_floor(args) -> int:
    """``bench floor`` with its sizes checked at the door."""
    from multigpu.studies.floor import bench_floor

    if args.tile < 1 or (args.display is not None and args.display < args.tile):
        raise InputError(f"bench floor: --tile must be >= 1 and --display >= the tile, got --tile {args.tile} "
                         f"--display {args.display}")
    bench_floor(args.quick, args.frames, ranks_list(args.ranks), args.tile, args.display)
    return 0


def ranks_list(text: str) -> list[int]:
    """``--ranks 4,9,16`` as numbers of at least 1, or a one-line error."""
    try:
        got = [int(v) for v in str(text).split(",")]
    except ValueError:
        got = []
    if not got or min(got) < 1:
        raise InputError.of("ranks", f"must be rank counts of at least 1, e.g. 4,9,16; got '{text}'")
    return got


def main(what: str, quick: bool = False) -> int:
    """Run the benchmark ``what`` (``registry.BENCHES``: those that take only ``quick``)."""
    from multigpu.studies.registry import BENCHES, load

    simple = [n for n, (where, _) in BENCHES.items() if where is not None]
    if what not in BENCHES:
        raise InputError(f"bench: unknown benchmark '{what}' (known: {', '.join(BENCHES)})")
    if what not in simple:
        raise InputError(f"bench {what}: started by the command line with its own arguments (multigpu bench {what})")
    load(BENCHES[what][0])(quick)
    return 0
