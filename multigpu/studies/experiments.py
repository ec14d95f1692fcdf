"""The paper's evaluation (Section 7) as runnable experiments: ``multigpu experiment NAME``.

Each experiment launches walkthrough jobs (``mpiexec -n K ... multigpu walkthrough``, each
under a hard timeout) or, for ``overlap``, runs the balancer in process, then writes into
``OUT/NAME/``: ``NAME.csv`` (one row per configuration), PNG plots (matplotlib) and
``NAME.md``, a Markdown fragment with the table and the plots. ``all`` runs every experiment
and joins the fragments into one results page.

Figures and what they are (see report.py): component columns are wall-clock means per rank;
"emulated" figures use each rank's process CPU time and take the slowest rank per frame, the
frame time the run would have with one core (GPU) per rank. Ranks outnumber cores here, so
speedups and efficiencies are computed from emulated figures only.
"""

from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multigpu.errors import InputError
from multigpu.parallel.mpirun import JobTimeout, run_multigpu
from multigpu.parallel.report import COLUMNS, read_timings
from multigpu.studies.tables import md_table, write_csv

# Dong & Peng 2019, Section 7 (quoted for comparison, not measured here)
PAPER = {
    "balance_speedup": 20.95 / 15.95,  # Fig. 7: mean FPS with / without balancing
    "gpus_frame_ms_1": 52.36,  # Table 1: one GPU, 6 power plants
    "gpus_frame_ms_4": 31.89,  # Table 1: four GPUs
    "balancer_share_max": 0.13,  # Fig. 8: balancer at most 13 % of the frame
    "triangles": 254_000_000,
}


@dataclass
class Settings:
    """Sizes of one experiment run; ``quick`` shrinks everything for smoke tests."""

    quick: bool = False
    triangles: int = 100_000  # one plant (the CLI's default scene)
    frames: int = 240  # camera path frames per run (the path is resampled, not cut)
    copies: tuple[int, ...] = (1, 2, 3, 4)
    resolutions: tuple[int, ...] = (512, 1024, 2048, 4096)
    res_frames: int = 40
    strip_frames: int = 120
    timeout: int = 900  # seconds per mpiexec job
    strategies: tuple[str, ...] = field(default_factory=tuple)

    @classmethod
    def make(cls, quick: bool) -> "Settings":
        from multigpu.strategies import REGISTRY

        s = cls(quick=quick, strategies=tuple(REGISTRY))
        if quick:
            s.triangles, s.frames, s.copies = 20_000, 12, (1, 2)
            s.resolutions, s.res_frames, s.strip_frames, s.timeout = (128, 256), 6, 8, 240
        return s


@dataclass
class Run:
    """One finished walkthrough job: its summary and its per-(frame, rank) timing rows."""

    summary: dict
    rows: np.ndarray  # (F, K, C) complete frames only
    out: Path

    def col(self, name: str) -> np.ndarray:
        return self.rows[:, :, COLUMNS.index(name)]

    @property
    def render_max_cpu(self) -> np.ndarray:
        """Per frame, the slowest rank's rendering CPU time (the emulated render component)."""
        return self.col("rendering_cpu_ms").max(axis=1)


def walk(out: Path, grid: tuple[int, int], tile: tuple[int, int], args: list[str], timeout: int) -> Run:
    """Run ``multigpu walkthrough`` on ``rows*cols`` ranks into ``out``; kill it on timeout."""
    import json

    k = grid[0] * grid[1]
    out.mkdir(parents=True, exist_ok=True)
    args = ["walkthrough", "--grid", f"{grid[0]}x{grid[1]}", "--tile", f"{tile[0]}x{tile[1]}", "--out", str(out),
            "--no-progress", *args]
    try:
        job = run_multigpu(k, args, timeout, merge_stderr=True)
    except JobTimeout:
        raise RuntimeError(f"experiment job timed out after {timeout} s: multigpu {' '.join(args)}") from None
    log = job.stdout
    (out / "log.txt").write_text(log)
    if job.returncode != 0:
        tail = "\n".join(log.strip().splitlines()[-5:])
        raise RuntimeError(f"experiment job failed (exit {job.returncode}): multigpu {' '.join(args)}\n{tail}")
    summary = json.loads((out / "summary.json").read_text())
    rows = read_timings(out / "timings.csv")
    rows = rows[np.lexsort((rows[:, 1], rows[:, 0]))]
    frames = rows.shape[0] // k
    return Run(summary, rows[: frames * k].reshape(frames, k, len(COLUMNS)), out)


def _scene_args(s: Settings, copies: int = 1) -> list[str]:
    """``copies`` plants side by side, each of ``s.triangles`` (so the scene grows with copies)."""
    return ["--triangles", str(s.triangles * copies), "--copies", str(copies)]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _breakdown(run: Run) -> dict:
    s = run.summary
    w = s["wall"]
    return {
        "lb_ms": w["load_balancing_ms"], "render_ms": w["rendering_ms"], "sync_ms": w["synchronization_ms"],
        "exchange_ms": w["frame_exchange_ms"], "display_ms": w["display_ms"], "frame_ms": s["frame_ms"],
        "fps": s["fps"], "lb_cpu_ms": s["cpu"]["load_balancing_cpu_ms"],
        "render_cpu_max_ms": s["render_cpu_max_ms"], "exchange_cpu_ms": s["cpu"]["frame_exchange_cpu_ms"],
        "emulated_ms": s["emulated_frame_ms"], "emulated_fps": s["emulated_fps"],
        "imb_tris": s["imbalance_triangles"], "imb_render": s["imbalance_render_cpu"],
        "bytes_per_frame": s["bytes_sent_per_frame"],
    }


BREAKDOWN_COLS = [("lb_ms", "LB", ".2f"), ("render_ms", "Render", ".2f"), ("sync_ms", "Sync", ".2f"),
                  ("exchange_ms", "Exchange", ".2f"), ("display_ms", "Display", ".2f"),
                  ("frame_ms", "Frame (wall)", ".2f"), ("fps", "FPS (wall)", ".1f"),
                  ("emulated_ms", "Frame (emulated)", ".2f"), ("emulated_fps", "FPS (emulated)", ".1f")]


# --------------------------------------------------------------------------- experiments

def exp_gpus(s: Settings, out: Path) -> str:
    """Table 1: 1, 2, 3, 4 ranks x scene sizes; per-component breakdown, FPS, render speedup."""
    grids = [(1, 1), (1, 2), (1, 3), (2, 2)]
    W, H = (384, 256) if s.quick else (768, 512)  # divisible by 1, 2 and 3 columns
    rows, runs = [], {}
    for copies in s.copies:
        for grid in grids:
            # every strategy at 4 ranks (issue 4 asks for the speedup with and without balancing)
            for bal in (s.strategies if grid == (2, 2) else ("strips",)):
                tile = (W // grid[1], H // grid[0])
                run = walk(out / f"c{copies}-{grid[0]}x{grid[1]}-{bal}", grid, tile,
                           _scene_args(s, copies) + ["--frames", str(s.frames), "--balance", bal,
                                                     "--mosaic-every", "0"], s.timeout)
                runs[(copies, grid, bal)] = run
                base = runs[(copies, (1, 1), "strips")]
                speed = float(base.render_max_cpu.mean() / run.render_max_cpu.mean())
                k = grid[0] * grid[1]
                rows.append({"copies": copies, "triangles": run.summary["config"]["scene"]["triangles"],
                             "ranks": k, "grid": f"{grid[0]}x{grid[1]}", "balance": bal, **_breakdown(run),
                             "render_speedup": speed, "render_efficiency": speed / k})
    write_csv(out / "gpus.csv", rows)
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for copies in s.copies:
        r = [x for x in rows if x["copies"] == copies and x["balance"] == "strips"]
        ax[0].plot([x["ranks"] for x in r], [x["emulated_fps"] for x in r], "o-", label=f"{r[0]['triangles']} tris")
        ax[1].plot([x["ranks"] for x in r], [x["render_speedup"] for x in r], "o-", label=f"{r[0]['triangles']} tris")
    ax[1].plot([1, 4], [1, 4], "k:", label="linear")
    ax[0].set(xlabel="ranks (GPUs)", ylabel="emulated FPS", title="Frame rate (emulated parallel)")
    ax[1].set(xlabel="ranks (GPUs)", ylabel="speedup over 1 rank", title="Rendering component speedup (CPU time)")
    for a in ax:
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "gpus.png", dpi=100)
    plt.close(fig)
    k4 = [x for x in rows if x["ranks"] == 4]
    md = [f"Display {W}x{H}; walkthrough path resampled to {s.frames} frames; plant copies {list(s.copies)}.",
          "Render speedup = mean 1-rank rendering CPU time / mean over frames of the slowest rank's rendering "
          "CPU time (emulated parallel); efficiency = speedup / ranks.", "",
          md_table(rows, [("triangles", "Triangles", ""), ("grid", "Grid", ""), ("balance", "Balance", ""),
                           *BREAKDOWN_COLS, ("render_speedup", "Render speedup", ".2f"),
                           ("render_efficiency", "Efficiency", ".0%")]),
          "", "![gpus](gpus.png)", ""]
    by = {b: ", ".join(f"{x['render_speedup']:.2f}" for x in k4 if x["balance"] == b) for b in s.strategies}
    paper = PAPER["gpus_frame_ms_1"] / PAPER["gpus_frame_ms_4"]
    md.append("4 ranks, rendering-component speedup over 1 rank, by scene size: "
              + "; ".join(f"{b} {v}" for b, v in by.items())
              + f". Paper (Table 1, 6 plants): 52.36 ms on one GPU vs 31.89 ms on four = {paper:.2f}x frame speedup.")
    return "\n".join(md)


def exp_resolution(s: Settings, out: Path) -> str:
    """Table 2: growing walls, strips = pixel width; Frame Exchange grows with the pixels."""
    rows = []
    for res in s.resolutions:
        run = walk(out / f"r{res}", (2, 2), (res // 2, res // 2),
                   _scene_args(s) + ["--frames", str(s.res_frames), "--strips", str(res), "--mosaic-every", "0"],
                   s.timeout)
        rows.append({"display": f"{res}x{res}", "pixels": res * res, **_breakdown(run)})
    write_csv(out / "resolution.csv", rows)
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    x = np.arange(len(rows))
    bottom = np.zeros(len(rows))
    for key, label in (("lb_ms", "load balancing"), ("render_ms", "rendering"), ("sync_ms", "synchronization"),
                       ("exchange_ms", "frame exchange"), ("display_ms", "display")):
        v = np.array([r[key] for r in rows])
        ax.bar(x, v, bottom=bottom, label=label)
        bottom += v
    ax.set_xticks(x, [r["display"] for r in rows])
    ax.set(ylabel="wall ms per frame (rank mean)", title="Frame breakdown by wall resolution (2x2)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "resolution.png", dpi=100)
    plt.close(fig)
    return "\n".join([f"2x2 wall, strips = display width, {s.res_frames} frames.", "",
                      md_table(rows, [("display", "Display", ""), *BREAKDOWN_COLS,
                                       ("exchange_cpu_ms", "Exchange CPU", ".2f"),
                                       ("bytes_per_frame", "Bytes/frame", ".0f")]),
                      "", "![resolution](resolution.png)"])


def _thumb(run: Run, frame: int) -> Path | None:
    p = run.out / "mosaic" / f"frame_{frame:05d}_partition.png"
    return p if p.exists() else None


def exp_balance(s: Settings, out: Path) -> str:
    """Fig. 7: per-frame FPS over the walkthrough for every strategy, with thumbnails."""
    every = max(1, s.frames // 24)
    runs = {}
    for name in s.strategies:
        runs[name] = walk(out / name, (2, 2), (256, 256), _scene_args(s) + [
            "--frames", str(s.frames), "--balance", name, "--mosaic-every", str(every)], s.timeout)
    per = {n: np.array(r.summary["per_frame_emulated_ms"]) for n, r in runs.items()}
    rows = [{"balance": n, **_breakdown(r), "speedup_vs_none": float(per["none"].mean() / per[n].mean())}
            for n, r in runs.items()]
    write_csv(out / "balance.csv", rows)
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 4))
    for n, v in per.items():
        ax.plot(1000.0 / v, label=f"{n} (mean {1000 / v.mean():.0f} FPS)", lw=1)
    ax.set(xlabel="frame", ylabel="emulated FPS", title="Walkthrough frame rate per strategy (2x2, emulated parallel)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "balance.png", dpi=100)
    plt.close(fig)
    # the saved frames where balancing and no balancing differ most
    saved = np.arange(0, len(per["strips"]), every)
    gap = per["none"][saved] / per["strips"][saved]
    md_thumbs = []
    for f in saved[np.argsort(-gap)[:2]]:
        pair = [_thumb(runs[n], int(f)) for n in ("strips", "none")]
        if all(pair):
            for n, p in zip(("strips", "none"), pair):
                dst = out / f"thumb_{f:05d}_{n}.png"
                shutil.copyfile(p, dst)
            md_thumbs.append(f"Frame {f} (none / strips emulated time {gap[np.flatnonzero(saved == f)[0]]:.2f}x): "
                             f"strips ![]({f'thumb_{f:05d}_strips.png'}) none ![]({f'thumb_{f:05d}_none.png'})")
    sp = rows[[r["balance"] for r in rows].index("strips")]["speedup_vs_none"]
    return "\n".join([f"2x2 wall of 256x256 tiles, walkthrough resampled to {s.frames} frames, plant "
                      f"{runs['strips'].summary['config']['scene']['triangles']} triangles.", "",
                      md_table(rows, [("balance", "Balance", ""), *BREAKDOWN_COLS, ("imb_tris", "Imb. tris", ".3f"),
                                       ("imb_render", "Imb. render", ".3f"),
                                       ("speedup_vs_none", "Speedup vs none", ".2f")]),
                      "", "![balance](balance.png)", "", *md_thumbs, "",
                      f"Emulated frame-time speedup of strips over none: {sp:.2f}x (paper, Fig. 7: "
                      f"{PAPER['balance_speedup']:.2f}x)."])


def exp_strips(s: Settings, out: Path) -> str:
    """Fig. 8: frame rate and balancer time against stripNum, 2 .. pixel width."""
    W = 256 if s.quick else 1024
    counts = [2, 4, 16, 64, W] if s.quick else [2, 4, 8, 16, 32, 64, 128, 256, 512, W]
    rows = []
    for q in counts:
        run = walk(out / f"s{q}", (2, 2), (W // 2, W // 2), _scene_args(s) + [
            "--frames", str(s.strip_frames), "--strips", str(q), "--mosaic-every", "0"], s.timeout)
        b = _breakdown(run)
        rows.append({"strips": q, **b, "balancer_share": b["lb_cpu_ms"] / b["emulated_ms"]})
    write_csv(out / "strips.csv", rows)
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4))
    q = [r["strips"] for r in rows]
    ax.semilogx(q, [r["emulated_fps"] for r in rows], "o-", base=2, label="emulated FPS")
    ax.set(xlabel="stripNum", ylabel="emulated FPS", title=f"Strip count, 2x2 wall of {W}x{W}")
    ax2 = ax.twinx()
    ax2.semilogx(q, [100 * r["balancer_share"] for r in rows], "s--", color="C1", base=2, label="balancer % of frame")
    ax2.set_ylabel("balancer share of the frame (%)")
    fig.legend(loc="lower center", fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "strips.png", dpi=100)
    plt.close(fig)
    last = rows[-1]
    return "\n".join([f"2x2 wall of {W}x{W}, {s.strip_frames} frames per strip count. Balancer share = "
                      "balancer CPU time / emulated frame time.", "",
                      md_table(rows, [("strips", "Strips", ""), ("lb_cpu_ms", "Balancer CPU ms", ".2f"),
                                       ("balancer_share", "Share", ".1%"), ("imb_tris", "Imb. tris", ".3f"),
                                       ("emulated_ms", "Frame (emulated)", ".2f"),
                                       ("emulated_fps", "FPS (emulated)", ".1f"), ("frame_ms", "Frame (wall)", ".2f")]),
                      "", "![strips](strips.png)", "",
                      f"At the largest strip count ({last['strips']}) the balancer takes {last['balancer_share']:.1%} "
                      f"of the emulated frame (paper: at most {PAPER['balancer_share_max']:.0%})."])


def exp_orbit(s: Settings, out: Path) -> str:
    """The circular path keeping the whole scene in view; every strategy side by side."""
    rows = []
    for name in s.strategies:
        run = walk(out / name, (2, 2), (256, 256), _scene_args(s) + [
            "--path-kind", "orbit", "--frames", str(s.frames), "--balance", name, "--mosaic-every", "0"], s.timeout)
        rows.append({"balance": name, **_breakdown(run)})
    write_csv(out / "orbit.csv", rows)
    return "\n".join([f"2x2 wall of 256x256 tiles, orbit path ({s.frames} frames) with the whole plant in view.", "",
                      md_table(rows, [("balance", "Balance", ""), *BREAKDOWN_COLS, ("imb_tris", "Imb. tris", ".3f"),
                                       ("imb_render", "Imb. render", ".3f")])])


def exp_overlap(s: Settings, out: Path) -> str:
    """Triangles rendered summed over ranks / visible triangles, against ranks and strips,
    beside Molnar's O = ((S + sqrt(rho a)) / S)^2. In process: balancer only, no rendering."""
    from multigpu.core.balance import partition
    from multigpu.core.bounds import BoxProjector
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import walkthrough
    from multigpu.core.camera import frame_matrices

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
    return "\n".join([f"Walkthrough ({len(path)} frames) of the {scene.n_triangles}-triangle plant on a {W}x{H} "
                      "display, balancer only. Molnar's prediction uses S = sqrt(W H / K) and, for sqrt(rho a), the "
                      "triangle-weighted RMS footprint of the visible objects' screen rects (we cull whole objects, "
                      "so the object is the primitive).", "",
                      md_table(rows, [("grid", "Grid", ""), ("strips", "Strips", ""), ("overlap", "Measured O", ".3f"),
                                       ("molnar", "Molnar O", ".3f")]), "", "![overlap](overlap.png)"])


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
                "--path-kind", path_kind, "--frames", str(s.frames), "--balance", name, "--mosaic-every", "0"], s.timeout)
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
        md_depth.append(f"| {scene_name} | {st.get('coverage', 0):.1%} | {st['mean_d']:.2f} | {st['max_d']} | "
                        f"{st['mean_o']:.2f} | {st['model_o']:.2f} | ![]({scene_name}_depth_complexity.png) |")
        (out / f"depth-{scene_name}.json").write_text(json.dumps(st))
    write_csv(out / "cost.csv", rows)
    fill = {r["balance"]: r for r in rows if r["scene"] == "fill"}
    plant = {r["balance"]: r for r in rows if r["scene"] == "plant"}
    return "\n".join([
        f"2x2 wall of {tile[0]}x{tile[1]} tiles, {s.frames} frames: the plant on its walkthrough (triangle-bound) "
        "and the fill scene (24 screen-filling panels beside a dense sphere cluster) on its orbit. "
        "`Imb. render` is max/mean of the measured per-rank rendering CPU time, averaged over frames; "
        "`vs strips` divides it by strips' on the same scene; `LB extra` is the extra balancer CPU ms per frame.", "",
        md_table(rows, [("scene", "Scene", ""), ("balance", "Balance", ""), ("imb_tris", "Imb. tris", ".3f"),
                         ("imb_render", "Imb. render", ".3f"), ("imb_vs_strips", "vs strips", ".2f"),
                         ("render_cpu_max_ms", "Slowest render CPU", ".2f"),
                         ("emulated_ms", "Frame (emulated)", ".2f"), ("lb_cpu_ms", "LB CPU", ".2f"),
                         ("lb_extra_ms", "LB extra", "+.2f"), ("terms", "Cost terms kept", ""),
                         ("pixel_frames", "Frames with pixel term", ".0%")]), "",
        f"Fill scene: cost model render imbalance {fill['cost']['imb_render']:.3f} vs strips "
        f"{fill['strips']['imb_render']:.3f} (target: at most half of strips' excess over 1 would be "
        f"{1 + (fill['strips']['imb_render'] - 1) / 2:.3f}); plant: cost {plant['cost']['imb_render']:.3f} vs strips "
        f"{plant['strips']['imb_render']:.3f} ({plant['cost']['imb_render'] / plant['strips']['imb_render'] - 1:+.1%}).",
        "", "Depth complexity of the middle frame (`multigpu depth`):", "",
        "| Scene | Coverage | mean d | max d | measured o | model o(d) = 1 + 1/2 + ... + 1/d | d image |",
        "|---:|---:|---:|---:|---:|---:|---:|", *md_depth])


def exp_speedup(s: Settings, out: Path) -> str:
    """Issue 4's target: rendering speedup of 4 ranks over 1 on the default plant, per strategy,
    with objects as modelled and clustered (``--cluster 64``), repeated in alternating rounds
    (1 rank, then every 4-rank configuration, then again) so slow drifts of a shared machine
    hit all configurations alike; medians and ranges over rounds."""
    rounds = 1 if s.quick else 3
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
    return "\n".join([
        f"Default plant ({s.triangles} requested triangles), walkthrough resampled to {s.frames} frames, 1 rank "
        f"against a 2x2 wall of the same display, {rounds} alternating rounds. Speedup = mean 1-rank rendering "
        "CPU time / mean over frames of the slowest of 4 ranks' rendering CPU time (emulated parallel; per-rank "
        "CPU time with `LP_NUM_THREADS=1`). `Cluster 64`: objects above 64 triangles split into spatial clusters "
        "(`--cluster 64`, same triangles and images, less overlap). Time imbalance: per frame max/mean of the 4 "
        "ranks' rendering CPU time, averaged.", "",
        md_table(rows, [("display", "Display", ""), ("balance", "Balance", ""), ("cluster", "Cluster", ""),
                         ("k1_render_ms", "1 rank ms", ".2f"), ("k4_mean_rank_ms", "4 ranks: mean rank ms", ".2f"),
                         ("time_imbalance", "Time imbalance", ".3f"), ("speedup_median", "Speedup (median)", ".2f"),
                         ("speedup_min", "min", ".2f"), ("speedup_max", "max", ".2f")]), "",
        f"Best: {best['balance']} with cluster {best['cluster']} at {best['display']}: {best['speedup_median']:.2f}x "
        f"(target 3x)."])


def exp_partition(s: Settings, out: Path) -> str:
    """DESIGN.md's open choice: every rank computes the partition (redundant) or rank 0 computes
    and broadcasts it. Alternating rounds, 2x2 wall, the default plant and 4 plants."""
    rounds = 1 if s.quick else 2
    W, H = (128, 128) if s.quick else (512, 512)
    rows = []
    acc: dict = {}
    for copies in ((1,) if s.quick else (1, 4)):
        for rnd in range(rounds):
            for mode in ("redundant", "broadcast"):
                run = walk(out / f"c{copies}-r{rnd}-{mode}", (2, 2), (W // 2, H // 2),
                           _scene_args(s, copies) + ["--frames", str(s.frames), "--mosaic-every", "0",
                                                     "--partition", mode], s.timeout)
                b = _breakdown(run)
                acc.setdefault((copies, mode), []).append(
                    (float(run.col("load_balancing_ms").mean()), float(run.col("load_balancing_cpu_ms").mean()),
                     float(run.col("load_balancing_cpu_ms").sum(axis=1).mean()), b["emulated_ms"], b["frame_ms"],
                     run.summary["config"]["scene"]["objects"]))
    for (copies, mode), v in acc.items():
        a = np.median(np.array(v), axis=0)
        rows.append({"copies": copies, "objects": int(a[5]), "partition": mode, "lb_wall_ms": a[0],
                     "lb_cpu_ms_per_rank": a[1], "lb_cpu_ms_all_ranks": a[2], "emulated_ms": a[3], "frame_wall_ms": a[4]})
    write_csv(out / "partition.csv", rows)
    return "\n".join([
        f"2x2 wall of {W}x{H}, walkthrough resampled to {s.frames} frames, {rounds} alternating round(s), medians. "
        "LB wall: load-balancing phase per rank and frame (for broadcast: rank 0's plan plus the broadcast, "
        "which the other ranks spend waiting); LB CPU: process CPU time in that phase, per rank and summed over "
        "the 4 ranks; emulated: slowest rank's CPU time per frame.", "",
        md_table(rows, [("copies", "Plants", ""), ("objects", "Objects", ""), ("partition", "Partition", ""),
                         ("lb_wall_ms", "LB wall ms", ".2f"), ("lb_cpu_ms_per_rank", "LB CPU ms/rank", ".2f"),
                         ("lb_cpu_ms_all_ranks", "LB CPU ms, 4 ranks", ".2f"), ("emulated_ms", "Frame (emulated) ms", ".2f"),
                         ("frame_wall_ms", "Frame (wall) ms", ".2f")])])


EXPERIMENTS = {"gpus": exp_gpus, "resolution": exp_resolution, "balance": exp_balance, "strips": exp_strips,
               "orbit": exp_orbit, "overlap": exp_overlap, "cost": exp_cost,
               "speedup": exp_speedup, "partition": exp_partition}


def run(name: str, out: Path, quick: bool = False, results: Path | None = None) -> int:
    """Run one experiment (or ``all``) into ``out``; ``all`` also writes the results page."""
    if name != "all" and name not in EXPERIMENTS:
        raise InputError(f"experiment: unknown experiment '{name}' (known: all, {', '.join(EXPERIMENTS)})")
    s = Settings.make(quick)
    names = list(EXPERIMENTS) if name == "all" else [name]
    out = Path(out)
    sections = []
    t_all = time.perf_counter()
    for n in names:
        d = out / n
        d.mkdir(parents=True, exist_ok=True)
        t = time.perf_counter()
        print(f"experiment {n} ...", flush=True)
        md = EXPERIMENTS[n](s, d)
        dt = time.perf_counter() - t
        md = f"## {n}\n\n{md}\n\n_{dt:.0f} s wall for this experiment._\n"
        (d / f"{n}.md").write_text(md)
        sections.append((n, md))
        print(f"experiment {n}: {dt:.0f} s, outputs in {d}/", flush=True)
    if name == "all":
        page = Path(results) if results else out / "RESULTS.md"
        page.parent.mkdir(parents=True, exist_ok=True)
        page.write_text(_results_page(sections, out, page, s, time.perf_counter() - t_all))
        print(f"results page: {page}")
    return 0


def _results_page(sections, out: Path, page: Path, s: Settings, seconds: float) -> str:
    import platform

    rel = os.path.relpath(out, page.parent)
    body = []
    for n, md in sections:
        # image links in the fragments are relative to OUT/NAME/
        body.append(md.replace("](", f"]({rel}/{n}/").replace(f"]({rel}/{n}/http", "](http"))
    cmd = "launch/experiments" + (" --quick" if s.quick else "")
    return "\n".join([
        "# Results", "",
        f"Regenerate with `{cmd}` (runs `multigpu experiment all`, {seconds / 60:.1f} min here).", "",
        "Machine: " + f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, Mesa "
        "llvmpipe (no GPU), `LP_NUM_THREADS=1`, MPI ranks emulate GPUs and outnumber cores.", "",
        "How to read the figures: `LB`, `Render`, `Sync`, `Exchange`, `Display`, `Frame (wall)` are wall-clock "
        "means per rank per frame (distorted by ranks sharing 2 cores); `Frame (emulated)` is, per frame, the "
        "slowest rank's CPU time for balancing + rendering + exchange + display (what one core per rank would "
        "give), averaged over frames. Speedups and efficiencies use emulated figures.", "",
        f"Scale: the paper rendered {PAPER['triangles'] / 1e6:.0f} M triangles on four GTX 980 Ti; here one plant "
        f"is {s.triangles} requested triangles (about 85 %% generated) and llvmpipe draws a few M triangles/s per core, "
        f"so scenes are scaled down by about {PAPER['triangles'] / s.triangles:.0f}x; each experiment keeps the "
        "paper's shape (ranks, resolutions, strips, balancing on/off).".replace("%%", "%"), "",
        *body])
