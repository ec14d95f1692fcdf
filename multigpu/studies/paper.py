"""The paper's evaluation (Dong & Peng 2019, Section 7) on this machine: ranks, resolution,
balancing on/off, strip counts, the orbit path."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from multigpu.studies.prose import prose
from multigpu.studies.runs import BREAKDOWN_COLS, PAPER, Run, Settings, _breakdown, _plt, _scene_args, walk
from multigpu.studies.tables import md_table, write_csv


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
    by = {b: ", ".join(f"{x['render_speedup']:.2f}" for x in k4 if x["balance"] == b) for b in s.strategies}
    table = md_table(rows, [("triangles", "Triangles", ""), ("grid", "Grid", ""), ("balance", "Balance", ""),
                            *BREAKDOWN_COLS, ("render_speedup", "Render speedup", ".2f"),
                            ("render_efficiency", "Efficiency", ".0%")])
    return prose("paper", "gpus", W=W, H=H, frames=s.frames, copies=list(s.copies), table=table,
                 by="; ".join(f"{b} {v}" for b, v in by.items()),
                 paper=PAPER["gpus_frame_ms_1"] / PAPER["gpus_frame_ms_4"])


def exp_resolution(s: Settings, out: Path) -> str:
    """Table 2: growing walls, strips = pixel width; Frame Exchange grows with the pixels."""
    rows = []
    for res in s.resolutions:
        run = walk(out / f"r{res}", (2, 2), (res // 2, res // 2),
                   _scene_args(s) + ["--frames", str(s.res_frames), "--strips", str(res), "--balance", "strips",
                                     "--mosaic-every", "0"],
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
    return prose("paper", "resolution", frames=s.res_frames,
                 table=md_table(rows, [("display", "Display", ""), *BREAKDOWN_COLS,
                                       ("exchange_cpu_ms", "Exchange CPU", ".2f"),
                                       ("bytes_per_frame", "Bytes/frame", ".0f")]))


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
    per = {n: r.emulated for n, r in runs.items()}
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
            md_thumbs.append(prose("paper", "thumb", frame=f, gap=gap[np.flatnonzero(saved == f)[0]],
                                   strips=f"thumb_{f:05d}_strips.png", none=f"thumb_{f:05d}_none.png"))
    sp = rows[[r["balance"] for r in rows].index("strips")]["speedup_vs_none"]
    return prose("paper", "balance", frames=s.frames, triangles=runs["strips"].summary["config"]["scene"]["triangles"],
                 table=md_table(rows, [("balance", "Balance", ""), *BREAKDOWN_COLS, ("imb_tris", "Imb. tris", ".3f"),
                                       ("imb_render", "Imb. render", ".3f"),
                                       ("speedup_vs_none", "Speedup vs none", ".2f")]),
                 thumbs="".join(t + "\n" for t in md_thumbs), speedup=sp, paper=PAPER["balance_speedup"])


def exp_strips(s: Settings, out: Path) -> str:
    """Fig. 8: frame rate and balancer time against stripNum, 2 .. pixel width."""
    W = 256 if s.quick else 1024
    counts = [2, 4, 16, 64, W] if s.quick else [2, 4, 8, 16, 32, 64, 128, 256, 512, W]
    rows = []
    for q in counts:
        run = walk(out / f"s{q}", (2, 2), (W // 2, W // 2), _scene_args(s) + [
            "--frames", str(s.strip_frames), "--strips", str(q), "--balance", "strips", "--mosaic-every", "0"],
            s.timeout)
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
    return prose("paper", "strips", W=W, frames=s.strip_frames, strips=last["strips"], share=last["balancer_share"],
                 paper=PAPER["balancer_share_max"],
                 table=md_table(rows, [("strips", "Strips", ""), ("lb_cpu_ms", "Balancer CPU ms", ".2f"),
                                       ("balancer_share", "Share", ".1%"), ("imb_tris", "Imb. tris", ".3f"),
                                       ("emulated_ms", "Frame (emulated)", ".2f"),
                                       ("emulated_fps", "FPS (emulated)", ".1f"), ("frame_ms", "Frame (wall)", ".2f")]))


def exp_orbit(s: Settings, out: Path) -> str:
    """The circular path keeping the whole scene in view; every strategy side by side."""
    rows = []
    for name in s.strategies:
        run = walk(out / name, (2, 2), (256, 256), _scene_args(s) + [
            "--path-kind", "orbit", "--frames", str(s.frames), "--balance", name, "--mosaic-every", "0"], s.timeout)
        rows.append({"balance": name, **_breakdown(run)})
    write_csv(out / "orbit.csv", rows)
    return prose("paper", "orbit", frames=s.frames,
                 table=md_table(rows, [("balance", "Balance", ""), *BREAKDOWN_COLS, ("imb_tris", "Imb. tris", ".3f"),
                                       ("imb_render", "Imb. render", ".3f")]))
