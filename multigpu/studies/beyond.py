"""Experiments beyond the paper: triangle overlap against Molnar's model, the fitted cost
model on triangle- and fill-bound scenes, K=4 over K=1 speedup, redundant vs broadcast
partitioning."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from multigpu.studies.prose import prose
from multigpu.studies.runs import Settings, _breakdown, _plt, _scene_args, walk
from multigpu.studies.tables import md_table, write_csv


def exp_overlap(s: Settings, out: Path) -> str:
    """Triangles rendered summed over ranks / visible triangles, against ranks and strips,
    beside Molnar's O = ((S + sqrt(rho a)) / S)^2. In process: balancer only, no rendering."""
    from multigpu.core.balance import partition
    from multigpu.core.bounds import BoxProjector
    from multigpu.core.camera import frame_matrices
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import walkthrough

    scene, _ = load_scene(SceneSpec(triangles=s.triangles))
    path = walkthrough(scene, frames=s.frames)
    project = BoxProjector(scene.bmin, scene.bmax)
    size = (1024, 1024)
    W, H = size
    grids = [(1, 2), (2, 2), (2, 4), (4, 4)]
    counts = [4, 16, 64, 256, 1024]
    tris = scene.tris
    acc = {(g, q): [] for g in grids for q in counts}
    molnar = {g: [] for g in grids}
    for f in range(len(path)):  # frames of the path, not objects
        view, proj, _ = frame_matrices(path.camera(f), size)
        rects = project(view, proj)
        on = ~np.isnan(rects[:, 0])
        visible = int(tris[on].sum())
        if visible == 0:
            continue
        # triangle-weighted mean object footprint in pixels (Molnar's rho * a at object granularity)
        wpx = (rects[on, 2] - rects[on, 0]) * W
        hpx = (rects[on, 3] - rects[on, 1]) * H
        s_obj = float(np.sqrt(np.average(wpx * hpx, weights=np.maximum(tris[on], 1))))
        for g in grids:
            k = g[0] * g[1]
            S = np.sqrt(W * H / k)
            molnar[g].append(((S + s_obj) / S) ** 2)
            for q in counts:
                p = partition(rects, tris, g, size, q)
                acc[(g, q)].append(p.loads.sum() / visible)
    rows = []
    for g in grids:
        for q in counts:
            rows.append({"ranks": g[0] * g[1], "grid": f"{g[0]}x{g[1]}", "strips": q,
                         "overlap": float(np.mean(acc[(g, q)])), "molnar": float(np.mean(molnar[g]))})
    write_csv(out / "overlap.csv", rows)
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4))
    ks = [g[0] * g[1] for g in grids]
    for q in counts:
        ax.plot(ks, [r["overlap"] for r in rows if r["strips"] == q], "o-", label=f"measured, {q} strips")
    ax.plot(ks, [float(np.mean(molnar[g])) for g in grids], "k--", label="Molnar, square regions")
    ax.set(xlabel="ranks", ylabel="overlap O (rendered / visible triangles)", title=f"Overlap, {W}x{H} walkthrough")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "overlap.png", dpi=100)
    plt.close(fig)
    return prose("beyond", "overlap", frames=len(path), triangles=scene.n_triangles, W=W, H=H,
                 table=md_table(rows, [("grid", "Grid", ""), ("strips", "Strips", ""), ("overlap", "Measured O", ".3f"),
                                       ("molnar", "Molnar O", ".3f")]))


def exp_cost(s: Settings, out: Path) -> str:
    """Issue 8: every strategy on the triangle-bound plant and the fill-bound scene: measured
    render-time imbalance, emulated frame time, the cost model's kept terms, balancer cost."""
    import json

    from multigpu.gpu import depth
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import orbit, walkthrough

    cases = [("plant", "walkthrough", _scene_args(s)),
             ("fill", "orbit", ["--scene", "fill", "--triangles", str(s.triangles)])]
    tile = (128, 128) if s.quick else (512, 512)
    rows, md_depth = [], []
    for scene_name, path_kind, args in cases:
        base = None
        for name in s.strategies:
            run = walk(out / f"{scene_name}-{name}", (2, 2), tile, args + [
                "--path-kind", path_kind, "--frames", str(s.frames), "--balance", name, "--mosaic-every", "0"],
               s.timeout)
            b = _breakdown(run)
            strat = run.summary["config"].get("strategy", {})
            if name == "strips":
                base = b
            rows.append({"scene": scene_name, "balance": name, **b,
                         "terms": "+".join(strat.get("terms", [])) or "-",
                         "pixel_frames": strat.get("pixel_term_frames_share", float("nan"))})
        for r in rows:
            if r["scene"] == scene_name and base is not None:
                r["imb_vs_strips"] = r["imb_render"] / base["imb_render"]
                r["lb_extra_ms"] = r["lb_cpu_ms"] - base["lb_cpu_ms"]
        # depth complexity of a representative frame
        sc, _ = load_scene(SceneSpec(scene=scene_name, triangles=s.triangles))
        path = (walkthrough if path_kind == "walkthrough" else orbit)(sc, frames=s.frames)
        st = depth.run(sc, path.camera(len(path) // 2), (tile[0] * 2, tile[1] * 2), out / f"depth-{scene_name}")
        for img in ("depth_complexity", "overdraw"):
            shutil.copyfile(out / f"depth-{scene_name}" / f"{img}.png", out / f"{scene_name}_{img}.png")
        md_depth.append(prose("beyond", "depth-row", scene=scene_name, coverage=st.get("coverage", 0),
                              mean_d=st["mean_d"], max_d=st["max_d"], mean_o=st["mean_o"], model_o=st["model_o"]))
        (out / f"depth-{scene_name}.json").write_text(json.dumps(st))
    write_csv(out / "cost.csv", rows)
    fill = {r["balance"]: r for r in rows if r["scene"] == "fill"}
    plant = {r["balance"]: r for r in rows if r["scene"] == "plant"}
    fs, ps = fill["strips"]["imb_render"], plant["strips"]["imb_render"]
    return prose(
        "beyond", "cost", tw=tile[0], th=tile[1], frames=s.frames, fill_cost=fill["cost"]["imb_render"],
        fill_strips=fs, fill_target=1 + (fs - 1) / 2, plant_cost=plant["cost"]["imb_render"], plant_strips=ps,
        plant_change=plant["cost"]["imb_render"] / ps - 1, depth="\n".join(md_depth),
        table=md_table(rows, [("scene", "Scene", ""), ("balance", "Balance", ""), ("imb_tris", "Imb. tris", ".3f"),
                         ("imb_render", "Imb. render", ".3f"), ("imb_vs_strips", "vs strips", ".2f"),
                         ("render_cpu_max_ms", "Slowest render CPU", ".2f"),
                         ("emulated_ms", "Frame (emulated)", ".2f"), ("lb_cpu_ms", "LB CPU", ".2f"),
                         ("lb_extra_ms", "LB extra", "+.2f"), ("terms", "Cost terms kept", ""),
                         ("pixel_frames", "Frames with pixel term", ".0%")]))


def exp_speedup(s: Settings, out: Path) -> str:
    """Issue 4's target: rendering speedup of 4 ranks over 1 on the default plant, per strategy,
    with objects as modelled and clustered (``--cluster 64``), repeated in alternating rounds
    (1 rank, then every 4-rank configuration, then again) so slow drifts of a shared machine
    hit all configurations alike; medians and ranges over rounds."""
    rounds = s.repeat(3)
    displays = [(128, 128)] if s.quick else [(512, 512), (1024, 1024)]
    configs = [("strips", 0), ("adaptive", 0), ("time", 0), ("none", 0), ("strips", 64), ("adaptive", 64)]
    base_args = _scene_args(s) + ["--frames", str(s.frames), "--mosaic-every", "0"]
    speed: dict = {}
    for W, H in displays:
        for rnd in range(rounds):
            k1 = {}
            for cl in sorted({c for _, c in configs}):
                run = walk(out / f"{W}-r{rnd}-k1-c{cl}", (1, 1), (W, H), base_args + ["--cluster", str(cl)], s.timeout)
                k1[cl] = float(run.render_max_cpu.mean())
            for bal, cl in configs:
                run = walk(out / f"{W}-r{rnd}-{bal}-c{cl}", (2, 2), (W // 2, H // 2),
                           base_args + ["--balance", bal, "--cluster", str(cl)], s.timeout)
                c = run.col("rendering_cpu_ms")
                speed.setdefault((W, bal, cl), []).append(
                    (k1[cl] / float(c.max(axis=1).mean()), float((c.max(axis=1) / c.mean(axis=1)).mean()),
                     float(c.mean()), k1[cl]))
    rows = []
    for (W, bal, cl), v in speed.items():
        a = np.array(v)
        rows.append({"display": f"{W}x{W}", "balance": bal, "cluster": cl, "rounds": len(v),
                     "k1_render_ms": float(np.median(a[:, 3])), "k4_mean_rank_ms": float(np.median(a[:, 2])),
                     "time_imbalance": float(np.median(a[:, 1])), "speedup_median": float(np.median(a[:, 0])),
                     "speedup_min": float(a[:, 0].min()), "speedup_max": float(a[:, 0].max())})
    write_csv(out / "speedup.csv", rows)
    best = max(rows, key=lambda r: r["speedup_median"])
    return prose(
        "beyond", "speedup", triangles=s.triangles, frames=s.frames, rounds=rounds, balance=best["balance"],
        cluster=best["cluster"], display=best["display"], speedup=best["speedup_median"],
        table=md_table(rows, [("display", "Display", ""), ("balance", "Balance", ""), ("cluster", "Cluster", ""),
                         ("k1_render_ms", "1 rank ms", ".2f"), ("k4_mean_rank_ms", "4 ranks: mean rank ms", ".2f"),
                         ("time_imbalance", "Time imbalance", ".3f"), ("speedup_median", "Speedup (median)", ".2f"),
                         ("speedup_min", "min", ".2f"), ("speedup_max", "max", ".2f")]))


def exp_partition(s: Settings, out: Path) -> str:
    """DESIGN.md's open choice: every rank computes the partition (redundant) or rank 0 computes
    and broadcasts it. Alternating rounds, 2x2 wall, the default plant and 4 plants."""
    rounds = s.repeat(2)
    W, H = (128, 128) if s.quick else (512, 512)
    rows = []
    acc: dict = {}
    for copies in ((1,) if s.quick else (1, 4)):
        for rnd in range(rounds):
            for mode in ("redundant", "broadcast"):
                run = walk(out / f"c{copies}-r{rnd}-{mode}", (2, 2), (W // 2, H // 2),
                           _scene_args(s, copies) + ["--frames", str(s.frames), "--mosaic-every", "0",
                                                     "--partition", mode, "--balance", "strips"], s.timeout)
                b = _breakdown(run)
                acc.setdefault((copies, mode), []).append(
                    (float(run.col("load_balancing_ms").mean()), float(run.col("load_balancing_cpu_ms").mean()),
                     float(run.col("load_balancing_cpu_ms").sum(axis=1).mean()), b["emulated_ms"], b["frame_ms"],
                     run.summary["config"]["scene"]["objects"]))
    for (copies, mode), v in acc.items():
        a = np.median(np.array(v), axis=0)
        rows.append({"copies": copies, "objects": int(a[5]), "partition": mode, "lb_wall_ms": a[0],
                     "lb_cpu_ms_per_rank": a[1], "lb_cpu_ms_all_ranks": a[2], "emulated_ms": a[3],
                     "frame_wall_ms": a[4]})
    write_csv(out / "partition.csv", rows)
    return prose(
        "beyond", "partition", W=W, H=H, frames=s.frames, rounds=rounds,
        table=md_table(rows, [("copies", "Plants", ""), ("objects", "Objects", ""), ("partition", "Partition", ""),
                         ("lb_wall_ms", "LB wall ms", ".2f"), ("lb_cpu_ms_per_rank", "LB CPU ms/rank", ".2f"),
                         ("lb_cpu_ms_all_ranks", "LB CPU ms, 4 ranks", ".2f"),
                         ("emulated_ms", "Frame (emulated) ms", ".2f"),
                         ("frame_wall_ms", "Frame (wall) ms", ".2f")]))
