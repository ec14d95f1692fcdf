"""``multigpu accuracy [--quick]``: every speed-for-accuracy trade, measured, into docs/ACCURACY.md.

Four tables, each from one run in one process (one EGL context; ranks' regions are rendered
one after another, so per-rank figures are honest process CPU times with ``LP_NUM_THREADS=1``):

1. sub-frustum methods (scissor, viewport, offaxis) against a one-rank full render: mismatching
   pixels, maximum colour and depth difference, rendering CPU time, framebuffer memory;
2. balance accuracy against balancer cost: strips from 2 to the pixel width, box against sphere
   bounds, float32 against float64 box corners, at 10^4, 10^5 and 10^6 objects;
3. only what a scene requires: per rank, triangles submitted against triangles its region
   needs (per-triangle projection, ``core/triangles.py``) and the whole scene; needed objects missed;
4. coordinates far from the origin (1e4..1e8): our float64 origin against float32 world
   coordinates, images against the scene at its own coordinates.
"""

from __future__ import annotations

import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multigpu.core.balance import partition
from multigpu.core.bounds import BoxProjector
from multigpu.core.projectors import make_projector
from multigpu.core.regions import overlaps, pixel_spans
from multigpu.core.spheres import SphereProjector
from multigpu.studies.prose import prose
from multigpu.studies.synthetic import median_ms
from multigpu.studies.tables import md_table, write_csv


@dataclass
class Sizes:
    """What one report run measures; ``quick`` is the smoke-test size."""

    quick: bool = False
    triangles: int = 100_000  # the CLI's default plant
    tile: int = 512
    frames: int = 12  # walkthrough frames sampled evenly from a 1200-frame path
    objects: tuple[int, ...] = (10_000, 100_000, 1_000_000)
    views: int = 6
    repeat: int = 5

    @classmethod
    def make(cls, quick: bool) -> "Sizes":
        if quick:
            return cls(quick=True, triangles=20_000, tile=96, frames=3, objects=(10_000,), views=2, repeat=2)
        return cls()


def _cpu_ms(fn):
    t = time.process_time()
    r = fn()
    return r, (time.process_time() - t) * 1e3


#: the shipped model with materials and a repeated texture (mipmapped: its texels' derivatives
#: come from the framebuffer's pixel quads, which the viewport and offaxis methods shift)
PUMP = Path(__file__).resolve().parents[2] / "models" / "pump.glb"


def _world(s: Sizes, model: Path | None = None):
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import walkthrough

    scene, _ = load_scene(SceneSpec(triangles=s.triangles) if model is None else SceneSpec(model=str(model)))
    path = walkthrough(scene, frames=1200)
    frames = np.linspace(0, len(path) - 1, s.frames + 2).astype(int)[1:-1]  # skip the overview ends
    return scene, path, frames


def _compose(renderer, view, proj, light, part, size, depth: bool):
    """The wall as the ranks would compose it, and the slowest / summed per-rank render CPU ms."""
    W, H = size
    img = np.zeros((H, W, 3), dtype=np.uint8)
    z = np.zeros((H, W), dtype=np.float32)
    times = []
    for k, (x0, y0, x1, y1) in enumerate(part.regions):  # ranks, not objects
        r, ms = _cpu_ms(lambda: renderer.render(view, proj, light, (x0, y0, x1, y1), part.visible[k], depth=depth))
        times.append(ms)
        if depth:
            img[y0:y1, x0:x1], z[y0:y1, x0:x1] = r
        else:
            img[y0:y1, x0:x1] = r
    return img, z, times


# ---------------------------------------------------------------- 1. sub-frustum methods

def table_subfrustum(s: Sizes, ctx, out: Path) -> str:
    from multigpu.gpu.render import gl_limits

    limits = gl_limits(ctx)
    rows = []
    worlds = [("plant", _world(s), [(1, 2), (2, 2), (1, 3)])]
    if PUMP.is_file():  # a source checkout: the shipped model, textured
        worlds.append(("pump, textured", _world(s, PUMP), [(2, 2)]))
    for name, (scene, path, frames), grids in worlds:
        _subfrustum_rows(s, ctx, scene, path, frames, grids, name, rows)
    write_csv(out / "subfrustum.csv", rows)
    return _subfrustum_page(ctx, limits, rows, worlds[0][1][0].n_triangles, len(worlds[0][1][2]))


def _subfrustum_rows(s: Sizes, ctx, scene, path, frames, grids, name: str, rows: list) -> None:
    """Each grid's rows of the sub-frustum table for one scene, appended to ``rows``."""
    from multigpu.core.camera import frame_matrices
    from multigpu.gpu.render import RegionRenderer

    for grid in grids:
        size = (grid[1] * s.tile, grid[0] * s.tile)
        ref = RegionRenderer(ctx, scene, size, "scissor")
        project = BoxProjector(scene.bmin, scene.bmax)
        methods = {m: RegionRenderer(ctx, scene, size, m) for m in ("scissor", "viewport", "offaxis")}
        acc = {m: {"px": 0, "dc": 0, "dz": 0.0, "sum": [], "max": []} for m in methods}
        for f in frames:
            view, proj, light = frame_matrices(path.camera(int(f)), size)
            full, zfull = ref.render(view, proj, light, (0, 0, *size), None, depth=True)
            part = partition(project(view, proj), scene.tris, grid, size)
            for m, r in methods.items():
                img, z, times = _compose(r, view, proj, light, part, size, depth=True)
                bad = (img != full).any(axis=2)
                a = acc[m]
                a["px"] += int(bad.sum())
                a["dc"] = max(a["dc"], int(np.abs(img.astype(np.int16) - full).max()))
                a["dz"] = max(a["dz"], float(np.abs(z - zfull).max()))
                a["sum"].append(sum(times))
                a["max"].append(max(times))
        base = np.median(acc["scissor"]["sum"])
        for m, r in methods.items():
            a = acc[m]
            rows.append({"scene": name, "grid": f"{grid[0]}x{grid[1]}", "display": f"{size[0]}x{size[1]}", "method": m,
                         "frames": len(frames), "mismatch_px": a["px"],
                         "mismatch_share": a["px"] / (len(frames) * size[0] * size[1]),
                         "max_color_diff": a["dc"], "max_depth_diff": a["dz"],
                         "render_cpu_ms": float(np.median(a["sum"])), "slowest_rank_ms": float(np.median(a["max"])),
                         "vs_scissor": float(np.median(a["sum"]) / base), "fbo_mib": r.framebuffer_bytes / 2**20})
            r.release()
        ref.release()


def _subfrustum_page(ctx, limits: dict, rows: list, plant_triangles: int, n_frames: int) -> str:
    from multigpu.gpu.render import choose_method

    vw, vh = limits["viewport"]
    rb = limits["renderbuffer"]
    big = (2 * rb, 1024)
    methods = ("auto", "scissor", "viewport", "offaxis")
    beyond = ", ".join(f"{m}: {_try_method(choose_method, m, big, limits)}" for m in methods)
    return prose(
        "accuracy", "subfrustum", triangles=plant_triangles, frames=n_frames, renderer=ctx.info.get("GL_RENDERER"),
        vw=vw, vh=vh, rb=rb, bounds_low=limits["bounds_low"], rb_gib=rb * rb * 8 / 2**30, big_w=big[0], big_h=big[1],
        beyond=beyond,
        table=md_table(rows, [("scene", "Scene", ""), ("grid", "Grid", ""), ("display", "Display", ""),
                              ("method", "Method", ""), ("mismatch_px", "Mismatching px", ""),
                              ("mismatch_share", "Share", ".2e"), ("max_color_diff", "Max colour diff", ""),
                              ("max_depth_diff", "Max depth diff", ".2e"),
                              ("render_cpu_ms", "Render CPU ms (sum)", ".2f"),
                              ("slowest_rank_ms", "Slowest rank ms", ".2f"), ("vs_scissor", "Time vs scissor", ".3f"),
                              ("fbo_mib", "FBO MiB/rank", ".1f")]))


def _try_method(choose, m, size, limits) -> str:
    from multigpu.errors import InputError

    try:
        return choose(m, size, limits)
    except InputError:
        return "refused with an error"


# ---------------------------------------------------------------- 2. balance accuracy vs cost

def _views(n: int):
    from multigpu.core.camera import look_at, perspective

    eyes = [([-40, -60, 40], [100, 60, 0]), ([100, 60, 90], [100, 60, 0]), ([45, 35, 10], [140, 80, 8]),
            ([210, 130, 25], [40, 92, 8]), ([100, -30, 12], [100, 60, 10]), ([20, 100, 30], [150, 40, 0])]
    proj = perspective(60, 1.0, 0.1, 1000)
    return [(look_at(e, t, [0, 0, 1]), proj) for e, t in eyes[:n]]


def table_balance(s: Sizes, out: Path) -> str:
    from multigpu.studies.synthetic import synthetic_objects

    grid, size = (2, 2), (2048, 2048)
    W = size[0]
    strips = [2, 8, 32, 128, 512, W]
    rows = []
    views = _views(s.views)
    for n in s.objects:
        bmin, bmax, c, rad, tris = synthetic_objects(n)
        projectors = {("box", "float32"): BoxProjector(bmin, bmax, np.float32),
                      ("box", "float64"): BoxProjector(bmin, bmax, np.float64),
                      ("sphere", "float64"): SphereProjector(c, rad)}
        configs = [("box", "float32", q) for q in strips] + [("box", "float64", W), ("sphere", "float64", W)]
        for bounds, dtype, q in configs:
            project = projectors[(bounds, dtype)]
            imb, ovl, ms, err = [], [], [], []
            for view, proj in views:
                rects = np.array(project(view, proj))
                p = partition(rects, tris, grid, size, q)
                visible = tris[~np.isnan(rects[:, 0])].sum()
                imb.append(p.loads.max() / p.loads.mean())
                ovl.append(p.loads.sum() / max(visible, 1))
                ms.append(median_ms(lambda: partition(project(view, proj), tris, grid, size, q), s.repeat))
                if bounds == "box":
                    ref = projectors[("box", "float64")](view, proj)
                    with np.errstate(invalid="ignore"):
                        err.append(float(np.nanmax(np.abs(rects - ref)) * W))
            rows.append({"objects": n, "bounds": bounds, "dtype": dtype, "strips": q,
                         "imbalance": float(np.mean(imb)), "overlap": float(np.mean(ovl)),
                         "balancer_ms": float(np.median(ms)),
                         "rect_err_px": float(max(err)) if err else float("nan")})
    write_csv(out / "balance.csv", rows)
    return prose(
        "accuracy", "balance", views=len(views), w=size[0], h=size[1], W=W,
        table=md_table(rows, [("objects", "Objects", ""), ("bounds", "Bounds", ""), ("dtype", "Corners", ""),
                              ("strips", "Strips", ""), ("imbalance", "Imbalance", ".3f"),
                              ("overlap", "Overlap", ".3f"), ("balancer_ms", "Balancer ms", ".2f"),
                              ("rect_err_px", "Rect error px", ".1e")]))


# ---------------------------------------------------------------- 3. only what a scene requires

def table_needed(s: Sizes, out: Path) -> str:
    from multigpu.core.camera import frame_matrices
    from multigpu.core.triangles import triangle_objects, triangle_rects

    scene, path, frames = _world(s)
    grid = (2, 2)
    size = (grid[1] * s.tile, grid[0] * s.tile)
    tri, obj = triangle_objects(scene)
    world = scene.world_positions()
    tris = scene.tris
    K = grid[0] * grid[1]
    rows = []
    for bounds in ("box", "sphere"):
        project = make_projector(scene, bounds)
        sub = np.zeros((len(frames), K))
        need_t = np.zeros_like(sub)
        need_o = np.zeros_like(sub)
        wasted = np.zeros_like(sub)
        missed = 0
        for i, f in enumerate(frames):
            view, proj, _ = frame_matrices(path.camera(int(f)), size)
            part = partition(project(view, proj), tris, grid, size)
            spans, on = pixel_spans(triangle_rects(world, tri, view, proj), size)
            for k in range(K):  # ranks, not objects
                hit = overlaps(spans, part.regions[k]) & on
                needed = np.zeros(scene.n_objects, dtype=bool)
                needed[obj[hit]] = True
                sub[i, k] = tris[part.visible[k]].sum()
                need_t[i, k] = hit.sum()
                need_o[i, k] = tris[needed].sum()
                wasted[i, k] = (part.visible[k] & ~needed).sum() / max(part.visible[k].sum(), 1)
                missed += int((needed & ~part.visible[k]).sum())
        for k in range(K):
            rows.append({"bounds": bounds, "rank": k, "scene": scene.n_triangles, "submitted": float(sub[:, k].mean()),
                         "needed_objects": float(need_o[:, k].mean()), "needed_triangles": float(need_t[:, k].mean()),
                         "submitted_over_needed_objects": float(sub[:, k].sum() / max(need_o[:, k].sum(), 1)),
                         "submitted_over_needed": float(sub[:, k].sum() / max(need_t[:, k].sum(), 1)),
                         "share_of_scene": float(sub[:, k].mean() / scene.n_triangles),
                         "objects_not_needed": float(wasted[:, k].mean()), "missed": missed})
    write_csv(out / "needed.csv", rows)
    return prose(
        "accuracy", "needed", triangles=scene.n_triangles, objects=scene.n_objects, frames=len(frames), w=size[0],
        h=size[1],
        table=md_table(rows, [("bounds", "Bounds", ""), ("rank", "Rank", ""), ("scene", "Scene tris", ""),
                              ("submitted", "Submitted", ".0f"), ("share_of_scene", "of scene", ".3f"),
                              ("needed_objects", "Needed (objects)", ".0f"),
                              ("needed_triangles", "Needed (triangles)", ".0f"),
                              ("submitted_over_needed_objects", "Submitted / needed objects", ".3f"),
                              ("submitted_over_needed", "Submitted / needed triangles", ".2f"),
                              ("objects_not_needed", "Objects not needed", ".3f"), ("missed", "Missed", "")]))


# ---------------------------------------------------------------- 4. far from the origin

def table_offsets(s: Sizes, ctx, out: Path) -> str:
    from dataclasses import replace

    from multigpu.core.camera import frame_matrices
    from multigpu.gpu.render import RegionRenderer

    scene, path, frames = _world(s)
    grid = (2, 2)
    size = (grid[1] * s.tile, grid[0] * s.tile)
    base = RegionRenderer(ctx, scene, size, "scissor")
    refs, parts = [], []
    project0 = BoxProjector(scene.bmin, scene.bmax)
    for f in frames:
        view, proj, light = frame_matrices(path.camera(int(f)), size)
        refs.append(base.render(view, proj, light, (0, 0, *size), None))
        parts.append(partition(project0(view, proj), scene.tris, grid, size))
    base.release()
    rows = []
    for off in (1e4, 1e6, 1e8):
        delta = np.array([off, off, 0.0])
        moved = scene.translated(delta)
        naive = replace(moved, vertices=np.concatenate([moved.world_positions(), moved.vertices[:, 3:]], axis=1)
                        .astype(np.float32), origin=np.zeros(3))
        mpath = path.translated(delta)
        project = BoxProjector(moved.bmin, moved.bmax)
        for label, sc in (("float64 origin (ours)", moved), ("float32 world coordinates", naive)):
            r = RegionRenderer(ctx, sc, size, "scissor")
            px = dc = same = 0
            for i, f in enumerate(frames):
                view, proj, light = frame_matrices(mpath.camera(int(f)), size)
                part = partition(project(view, proj), moved.tris, grid, size)
                same += int(np.array_equal(part.regions, parts[i].regions)
                            and np.array_equal(part.visible, parts[i].visible))
                img, _, _ = _compose(r, view, proj, light, part, size, depth=False)
                px += int((img != refs[i]).any(axis=2).sum())
                dc = max(dc, int(np.abs(img.astype(np.int16) - refs[i]).max()))
            r.release()
            rows.append({"offset": f"{off:.0e}", "vertices": label, "mismatch_px": px,
                         "mismatch_share": px / (len(frames) * size[0] * size[1]), "max_color_diff": dc,
                         "same_partition": f"{same}/{len(frames)}"})
    write_csv(out / "offsets.csv", rows)
    return prose(
        "accuracy", "offsets", frames=len(frames), w=size[0], h=size[1],
        table=md_table(rows, [("offset", "Offset d", ""), ("vertices", "Vertices", ""),
                              ("mismatch_px", "Mismatching px", ""), ("mismatch_share", "Share", ".2e"),
                              ("max_color_diff", "Max colour diff", ""), ("same_partition", "Same partition", "")]))




def run(out: Path, page: Path | None, quick: bool = False) -> int:
    """All four tables into ``out`` (CSV) and the Markdown ``page``."""
    from multigpu.gpu.render import create_context

    s = Sizes.make(quick)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    page = Path(page) if page else out / "ACCURACY.md"
    ctx, _ = create_context()
    sections = []
    t_all = time.perf_counter()
    for name, fn, title in (("subfrustum", lambda: table_subfrustum(s, ctx, out),
                             "1. Sub-frustum rendering: pixels against speed"),
                            ("balance", lambda: table_balance(s, out), "2. Balance accuracy against balancer cost"),
                            ("needed", lambda: table_needed(s, out), "3. Only what a scene requires"),
                            ("offsets", lambda: table_offsets(s, ctx, out), "4. Coordinates far from the origin")):
        t = time.perf_counter()
        print(f"accuracy: {name} ...", flush=True)
        md = fn()
        dt = time.perf_counter() - t
        data = os.path.relpath(out / (name + ".csv"), page.parent)
        sections.append(prose("accuracy", "section", title=title, body=md, seconds=dt, data=data) + "\n")
        print(f"accuracy: {name}: {dt:.0f} s", flush=True)
    cmd = "launch/accuracy" + (" --quick" if quick else "")
    page.parent.mkdir(parents=True, exist_ok=True)
    page.write_text(prose("accuracy", "page", cmd=cmd, minutes=(time.perf_counter() - t_all) / 60,
                          machine=platform.machine(), cores=os.cpu_count(), python=platform.python_version(),
                          renderer=ctx.info.get("GL_RENDERER"), threads=os.environ.get("LP_NUM_THREADS"),
                          sections="\n".join(sections)))
    print(f"accuracy page: {page}")
    return 0
