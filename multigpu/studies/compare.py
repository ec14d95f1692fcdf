"""The paper's Section 7 comparison, in one pipeline: screen partitioning (strips) against
Equalizer's 2D load equalizer (``time``), cross-segment balancing (``cross``), sort-last
database decomposition (``db``), the wide objects drawn once (``hybrid``) and static bin patterns
(``bins``), on one scene, path and wall, with the same timings and outputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.studies.prose import prose
from multigpu.studies.runs import BREAKDOWN_COLS, Settings, _breakdown, _plt, _scene_args, walk
from multigpu.studies.tables import md_table, write_csv

# Dong & Peng 2019, Section 7: FPS on a circular path keeping every triangle in view (quoted)
PAPER_FPS = {"screen+strips": 22.16, "screen+time": 17.65, "screen+cross": 11.71, "db": 10.72}


def configs(quick: bool) -> list[tuple[str, list[str]]]:
    """(label, walkthrough flags) of every configuration compared."""
    bins = [(p, b) for p in ("diagonal", "vandercorput") for b in ((32, 128) if quick else (16, 64))]
    return ([("screen+strips", ["--balance", "strips"]), ("screen+time", ["--balance", "time"]),
             ("screen+cross", ["--balance", "cross"]), ("screen+none", ["--balance", "none"]),
             ("db", ["--decomposition", "db"]), ("hybrid", ["--decomposition", "hybrid"])]
            + [(f"bins {p} {b}px", ["--decomposition", "bins", "--bin-pattern", p, "--bin-size", str(b)])
               for p, b in bins])


def exp_compare(s: Settings, out: Path) -> str:
    copies = 2 if s.quick else 4
    rows = []
    for label, flags in configs(s.quick):
        run = walk(out / label.replace(" ", "_").replace("+", "_"), (2, 2), (256, 256), _scene_args(s, copies) + [
            "--path-kind", "orbit", "--frames", str(s.frames), "--mosaic-every", "0", *flags], s.timeout)
        sm = run.summary
        rows.append({"config": label, **_breakdown(run), "depth_bytes_per_frame": sm["depth_bytes_per_frame"],
                     "load_cv": sm["load_cv"], "pieces_per_rank": float(run.col("pieces").mean()),
                     "paper_fps": PAPER_FPS.get(label, float("nan"))})
    base = next(r for r in rows if r["config"] == "screen+strips")
    for r in rows:
        r["vs_strips"] = r["emulated_fps"] / base["emulated_fps"]
        r["paper_vs_strips"] = r["paper_fps"] / PAPER_FPS["screen+strips"]
    write_csv(out / "compare.csv", rows)
    _plot(rows, out / "compare.png")
    return prose("compare", "section", copies=copies, triangles=s.triangles * copies, frames=s.frames,
                 discussion=_discussion(rows),
                 table=md_table(rows, [("config", "Configuration", ""), *BREAKDOWN_COLS,
                                       ("bytes_per_frame", "Bytes/frame", ".0f"),
                                       ("depth_bytes_per_frame", "of which depth", ".0f"),
                                       ("imb_tris", "Imb. tris", ".3f"), ("imb_render", "Imb. render", ".3f"),
                                       ("load_cv", "c_v", ".3f"), ("vs_strips", "FPS / strips", ".2f"),
                                       ("paper_vs_strips", "paper: FPS / strips", ".2f")]))


def _plot(rows: list[dict], path: Path) -> None:
    plt = _plt()
    labels = [r["config"] for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
    y = np.arange(len(rows))
    ax[0].barh(y, [r["emulated_fps"] for r in rows], color="tab:blue")
    ax[0].set(yticks=y, yticklabels=labels, xlabel="FPS (emulated parallel)", title="Frame rate")
    ax[0].invert_yaxis()
    left = np.zeros(len(rows))
    for key, name in (("lb_cpu_ms", "load balancing"), ("render_cpu_max_ms", "render (slowest rank)"),
                      ("exchange_cpu_ms", "exchange / compositing")):
        vals = np.array([r[key] for r in rows])
        ax[1].barh(y, vals, left=left, label=name)
        left += vals
    ax[1].set(yticks=y, yticklabels=[""] * len(rows), xlabel="CPU ms per frame", title="Where a frame goes")
    ax[1].invert_yaxis()
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _discussion(rows: list[dict]) -> str:
    """Where the measured ranking agrees with the paper's and where not, with the measured why."""
    by = {r["config"]: r for r in rows}
    paper_order = sorted(PAPER_FPS, key=PAPER_FPS.get, reverse=True)
    ours = sorted(paper_order, key=lambda c: by[c]["emulated_fps"], reverse=True)
    agree = ours == paper_order
    strips, time, cross, db, hybrid = (by[c] for c in
                                       ("screen+strips", "screen+time", "screen+cross", "db", "hybrid"))
    bins = [r for r in rows if r["config"].startswith("bins")]
    best_bins = max(bins, key=lambda r: r["emulated_fps"])
    worst_bins = min(bins, key=lambda r: r["emulated_fps"])
    everyone = ", ".join("{} {:.1f}".format(r["config"], r["emulated_fps"])
                         for r in sorted(rows, key=lambda r: -r["emulated_fps"]))
    fps = [by[c]["emulated_fps"] for c in paper_order]
    close = prose("compare", "close", spread=max(fps) / min(fps) - 1, paper_spread=22.16 / 10.72) \
        if max(fps) / min(fps) < 1.10 else ""
    return prose(
        "compare", "discussion", paper_order=" > ".join(paper_order), ours=" > ".join(ours),
        order="the same order" if agree else "a different order", everyone=everyone, close=close,
        time_vs=time["vs_strips"], paper_time=17.65 / 22.16, cross_vs=cross["vs_strips"], paper_cross=11.71 / 22.16,
        strips_imb=strips["imb_render"], time_imb=time["imb_render"], cross_imb=cross["imb_render"],
        cross_pieces=cross["pieces_per_rank"], db_vs=db["vs_strips"], paper_db=10.72 / 22.16, db_tris=db["imb_tris"],
        db_mb=db["bytes_per_frame"] / 1e6, db_depth_mb=db["depth_bytes_per_frame"] / 1e6,
        strips_mb=strips["bytes_per_frame"] / 1e6, db_exchange=db["exchange_cpu_ms"],
        strips_exchange=strips["exchange_cpu_ms"], db_imb=db["imb_render"], hybrid_vs=hybrid["vs_strips"],
        hybrid_tris=hybrid["imb_tris"], hybrid_mb=hybrid["bytes_per_frame"] / 1e6,
        hybrid_exchange=hybrid["exchange_cpu_ms"], best=best_bins["config"], best_vs=best_bins["vs_strips"],
        best_cv=best_bins["load_cv"], worst=worst_bins["config"], worst_vs=worst_bins["vs_strips"],
        worst_cv=worst_bins["load_cv"], bin_sizes=_bin_size_effect(bins))


def _bin_size_effect(bins: list[dict]) -> str:
    """What the measured c_v says about bin size, per pattern."""
    out = []
    for pattern in sorted({r["config"].split()[1] for r in bins}):
        size = lambda r: int(r["config"].split()[2][:-2])
        rs = sorted((r for r in bins if r["config"].split()[1] == pattern), key=size)
        small, big = rs[0], rs[-1]
        trend = "lower" if small["load_cv"] < big["load_cv"] else "higher"
        out.append(prose("compare", "bin-size", pattern=pattern, small=small["config"].split()[2], trend=trend,
                         big=big["config"].split()[2], small_cv=small["load_cv"], big_cv=big["load_cv"],
                         small_fps=small["emulated_fps"], big_fps=big["emulated_fps"]))
    return " ".join(out)
