"""Benchmarks (``multigpu bench balance|scene|render [--quick]``): they print figures, never assert.

Figures are wall time (``time.perf_counter``) medians over repeats in one process, so ratios
between rows of one run are the meaningful comparison on a shared machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np

from .errors import InputError


def _median_ms(fn, repeat: int) -> float:
    fn()  # warm up (first-touch page faults, caches)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times) * 1e3)


def synthetic_objects(n: int, seed: int = 0):
    """Clustered boxes in a 200 x 120 x 30 plant-sized volume, heavy-tailed triangle counts."""
    rng = np.random.default_rng(seed)
    halls = np.array([[45, 35, 8], [140, 80, 8], [40, 92, 8]])
    dense = rng.random(n) < 0.8
    c = np.where(dense[:, None], halls[rng.integers(0, 3, n)] + rng.normal(0, [12, 8, 5], (n, 3)),
                 rng.random((n, 3)) * [200, 120, 30])
    h = rng.exponential(0.6, (n, 3)) + 0.05
    tris = (rng.pareto(1.1, n) * 20 + 12).astype(np.int64)
    return c - h, c + h, c, np.linalg.norm(h, axis=1), tris


def bench_balance(quick: bool) -> list[dict]:
    from .balance import partition
    from .bounds import BoxProjector, SphereProjector
    from .camera import look_at, perspective
    from .memory import keep_heap

    sizes = [10_000, 100_000] if quick else [100_000, 1_000_000]
    view = look_at([-40, -60, 40], [100, 60, 0], [0, 0, 1])
    proj = perspective(60, 1.0, 0.1, 1000)
    rows = []
    heap = os.environ.get("MULTIGPU_MALLOC", "keep") != "default" and keep_heap()
    print("per-frame wall time, median of 7; bounds prepared once per scene (not timed); "
          f"allocator: {'heap kept (memory.keep_heap)' if heap else 'glibc default (MULTIGPU_MALLOC=default)'}")
    print(f"{'objects':>9} {'grid':>5} {'bounds':>7} {'project ms':>11} {'partition ms':>13} {'total ms':>9} {'target ms':>10}")
    for n in sizes:
        bmin, bmax, c, r, tris = synthetic_objects(n)
        for grid in [(2, 2), (4, 4)]:
            size = (1024 * grid[1], 1024 * grid[0])
            for kind in ("box", "sphere"):
                project = BoxProjector(bmin, bmax) if kind == "box" else SphereProjector(c, r)
                rects = project(view, proj)
                t_proj = _median_ms(lambda: project(view, proj), 7)
                t_part = _median_ms(lambda: partition(rects, tris, grid, size, 2048), 7)
                t_all = _median_ms(lambda: partition(project(view, proj), tris, grid, size, 2048), 7)
                target = 15 * n / 100_000 if grid == (2, 2) else None
                rows.append({"objects": n, "grid": f"{grid[0]}x{grid[1]}", "bounds": kind, "project_ms": t_proj,
                             "partition_ms": t_part, "total_ms": t_all, "target_ms": target, "heap_kept": heap})
                print(f"{n:9d} {grid[0]}x{grid[1]:<3} {kind:>7} {t_proj:11.1f} {t_part:13.1f} {t_all:9.1f} "
                      f"{'' if target is None else f'{target:.0f}':>10}")
    return rows


_SCENE_CHILD = """
import json, resource, sys, time
from multigpu.models import SceneSpec, load_scene
spec = SceneSpec(triangles=int(sys.argv[1]))
t = time.perf_counter(); scene, info = load_scene(spec); dt = time.perf_counter() - t
print(json.dumps({"seconds": dt, "cached": info["cached"], "triangles": scene.n_triangles,
                  "bytes": scene.nbytes, "peak_rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
"""


def bench_scene(quick: bool) -> list[dict]:
    """First (built) and cached load of the plant, each in a fresh process for honest peak memory."""
    import os
    import tempfile

    sizes = [100_000, 1_000_000] if quick else [1_000_000, 10_000_000]
    rows = []
    base = json.loads(subprocess.run([sys.executable, "-c", "import resource, json, multigpu.models, multigpu.plant;"
                                      "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)"],
                                     capture_output=True, text=True, check=True).stdout)
    print(f"interpreter + imports peak RSS: {base / 2**20:.0f} MiB")
    print(f"{'target tris':>12} {'triangles':>10} {'load':>7} {'seconds':>8} {'arrays MiB':>11} {'B/tri':>6} {'peak RSS MiB':>13} {'(RSS-base)/tri':>15}")
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "MULTIGPU_CACHE": cache}
        for n in sizes:
            for attempt in ("first", "cached"):
                out = subprocess.run([sys.executable, "-c", _SCENE_CHILD, str(n)], capture_output=True, text=True,
                                     env=env, check=True).stdout
                d = json.loads(out)
                d.update(target=n, load=attempt)
                rows.append(d)
                print(f"{n:12d} {d['triangles']:10d} {attempt:>7} {d['seconds']:8.2f} {d['bytes'] / 2**20:11.1f} "
                      f"{d['bytes'] / d['triangles']:6.1f} {d['peak_rss'] / 2**20:13.0f} "
                      f"{(d['peak_rss'] - base) / d['triangles']:15.1f}")
    return rows


def bench_render(quick: bool) -> list[dict]:
    """Per-frame overhead independent of object count, and indirect draw vs one bare draw."""
    from .render import RegionRenderer, create_context
    from .scene import assemble

    ctx, _ = create_context()
    total = 200_000 if quick else 1_000_000
    size = (512, 512)
    rows = []
    print(f"{'objects':>8} {'triangles':>10} {'indirect ms':>12} {'bare draw ms':>13} {'ratio':>6}")
    for n in (1_000, 100_000):
        per = total // n
        # n objects, each a strip of `per` thin triangles over a grid cell, facing the camera
        k = int(np.ceil(np.sqrt(n)))
        i = np.arange(n)
        cx, cy = (i % k) / k * 2 - 1, (i // k) / k * 2 - 1
        t = np.arange(per)
        x = cx[:, None] + (t[None, :] / per) * (2 / k)
        y = cy[:, None]
        pos = np.zeros((n, per * 3, 3))
        pos[:, 0::3, 0], pos[:, 0::3, 1] = x, y
        pos[:, 1::3, 0], pos[:, 1::3, 1] = x + 2 / k / per, y
        pos[:, 2::3, 0], pos[:, 2::3, 1] = x, y + 2 / k
        nrm = np.zeros_like(pos)
        nrm[..., 2] = 1
        scene = assemble([(pos, nrm, np.arange(per * 3), np.full((n, 3), 0.7))], "bench", {})
        r = RegionRenderer(ctx, scene, size)
        mvp, light = np.eye(4), np.array([0, 0, 1.0])
        mask = np.ones(n, dtype=bool)
        t_ind = _median_ms(lambda: r.render(mvp, light, (0, 0, *size), mask), 7)

        def bare():
            r.fbo.use()
            r.fbo.viewport = (0, 0, *size)
            r.fbo.scissor = (0, 0, *size)
            r.fbo.clear(0, 0, 0, 1, depth=1.0)
            r.prog["mvp"].write(np.eye(4, dtype=np.float32))
            r.vao.render(vertices=scene.indices.size)
            r.fbo.read(viewport=(0, 0, *size), components=3, alignment=1)

        # the bare draw needs one index list over one vertex range: base vertex 0 for all
        r.ibo.write((scene.indices.reshape(n, -1) + scene.base_vertex[:, None]).astype(np.uint32).ravel())
        t_bare = _median_ms(bare, 7)
        r.release()
        rows.append({"objects": n, "triangles": scene.n_triangles, "indirect_ms": t_ind, "bare_ms": t_bare})
        print(f"{n:8d} {scene.n_triangles:10d} {t_ind:12.2f} {t_bare:13.2f} {t_ind / t_bare:6.2f}")
    return rows


def main(what: str, quick: bool = False) -> int:
    fns = {"balance": bench_balance, "scene": bench_scene, "render": bench_render}
    if what not in fns:
        raise InputError(f"bench: unknown benchmark '{what}' (known: {', '.join(fns)})")
    fns[what](quick)
    return 0
