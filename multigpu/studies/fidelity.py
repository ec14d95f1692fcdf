"""``multigpu experiment fidelity``: what cheaper frames buy in time and cost in accuracy.

For the plant walk, the city drive, the 4-plant orbit and a large model (4.3 M triangles in 130k
objects), on a 2x2 wall of 512x512 tiles: a full-quality run records its cameras; the same
cameras then run at fixed render scales and level-of-detail bounds, with ``--target-fps`` at 1.5x
and 2x the full run's frame rate, and at half of it (a target already met), and with a lossy wire while the camera moves
(``--compress-moving`` 2, 3 and 4 bits, every piece between ranks a zstd message; its error from
the mosaics against the same run lossless). Time is the wall's
frame period (wall time, the mean over ranks) and the emulated frame (the slowest rank's CPU
time). Error is measured in one process against the full-quality replay of the same camera:
the frame each run showed is rendered again (a scaled, levelled composite is bit for bit one
rank's render with the same settings: tests/test_quality_mpi.py), and PSNR and the share of
pixels that differ are taken. Every frame of the target runs gets its error
(``fidelity_frames.csv``); the fixed settings a sample of frames.

A target's frames are judged after the first two: the share whose period lies within 10 % of the
target's, the share of 10-frame windows whose mean does, and how many frames the controller
took to bring the windowed mean within 10 % at the start (the jump from full quality). The full
run's own spread (the share of its frames within 10 % of its median) is this machine's floor.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from multigpu.studies.prose import prose
from multigpu.studies.runs import Settings, _plt, walk
from multigpu.studies.tables import write_csv

#: fixed settings measured: (render scale, LOD bound px)
FIXED = ((0.75, 0.0), (0.5, 0.0), (0.25, 0.0), (1.0, 1.0), (1.0, 4.0), (0.5, 4.0))
#: colour bits a lossy wire drops while the camera moves (``--compress-moving``), each measured with
#: every piece between ranks a zstd message (``--exchange messages --compress zstd``)
WIRE_BITS = (2, 3, 4)
#: targets, as multiples of the full run's frame rate (0.5: a target already met)
TARGETS = (1.5, 2.0, 0.5)
#: frames in a window of the windowed target share
WINDOW = 10


def scenes(s: Settings) -> dict[str, tuple[list[str], int]]:
    """Scene flags and frames of each scene."""
    big = 20_000 if s.quick else 5_000_000
    every = {"plant": (["--scene", "plant", "--triangles", str(s.triangles)], s.frames),
             "city": (["--scene", "city", "--triangles", str(s.triangles)], s.frames),
             "orbit": (["--triangles", str(s.triangles * 4), "--copies", "4", "--path-kind", "orbit"], s.frames),
             "large": (["--triangles", str(big), "--copies", "4", "--path-kind", "orbit"], max(6, s.frames // 6))}
    # quick: a walk and an orbit (a quick "large" is no larger than the orbit)
    return {k: every[k] for k in ("plant", "orbit")} if s.quick else every


def exp_fidelity(s: Settings, out: Path) -> str:
    tile = (128, 128) if s.quick else (512, 512)
    rows, frames = [], []
    for name, (flags, n) in scenes(s).items():
        r, f = _scene(s, out / name, name, flags, n, tile)
        rows += r
        frames += f
    write_csv(out / "fidelity.csv", rows, ".4f")
    write_csv(out / "fidelity_frames.csv", frames, ".4f")
    _plot(rows, frames, out)
    return _markdown(rows)


def _scene(s: Settings, out: Path, name: str, flags: list[str], n: int, tile) -> tuple[list[dict], list[dict]]:
    """One scene's runs and their errors: (summary rows, per-frame rows)."""
    rec = out / "cameras.json"
    base = walk(out / "full", (2, 2), tile, [*flags, "--frames", str(n), "--mosaic-every", "0", "--record", str(rec)],
                s.timeout)
    path = [*flags, "--path", str(rec), "--mosaic-every", "0"]
    runs = {("full", 1.0, 0.0, None): base}
    # a quick run (the smoke test's) takes each kind once: a scale alone, a scale with levels of detail, a target
    fixed, targets = (FIXED, TARGETS) if not s.quick else (FIXED[1::4], TARGETS[1:2])
    for scale, lod in fixed:
        runs[(f"scale {scale:g}, lod {lod:g} px", scale, lod, None)] = walk(
            out / f"s{scale:g}-l{lod:g}", (2, 2), tile, [*path, "--render-scale", str(scale), "--lod-error", str(lod)],
            s.timeout)
    fps = base.summary["fps"]
    for m in targets:
        runs[(f"target {m:g}x", 1.0, 0.0, m * fps)] = walk(out / f"t{m:g}", (2, 2), tile,
                                                          [*path, "--target-fps", f"{m * fps:.3f}"], s.timeout)
    errors = _errors(flags, rec, runs, (2 * tile[0], 2 * tile[1]), sample=1 if s.quick else 6)
    if s.quick and name != "plant":  # the quick runs check the wire's trade on one scene
        return _rows(name, runs, errors, base)
    every = 1 if s.quick else 6
    wire = [*path, "--mosaic-every", str(every), "--no-overlay", "--exchange", "messages", "--compress", "zstd"]
    exact = walk(out / "wire-exact", (2, 2), tile, wire, s.timeout)  # the same frames, lossless
    for bits in WIRE_BITS if not s.quick else WIRE_BITS[1:2]:
        key = (f"wire lossy {bits} bits", 1.0, 0.0, None)
        runs[key] = walk(out / f"w{bits}", (2, 2), tile, [*wire, "--compress-moving", str(bits)], s.timeout)
        errors[key] = _mosaic_errors(runs[key].out, exact.out)
    return _rows(name, runs, errors, base)


def _mosaic_errors(run: Path, exact: Path) -> list[tuple]:
    """[(frame, psnr, share of pixels that differ, 1.0, 0.0)] of a run's mosaics against the same
    frames' exact ones (a lossy wire: the frames as shown, composed from what crossed)."""
    from PIL import Image

    got = []
    for png in sorted((exact / "mosaic").glob("frame_*.png")):
        want = np.asarray(Image.open(png)).astype(np.int16)
        mine = np.asarray(Image.open(run / "mosaic" / png.name)).astype(np.int16)
        diff = mine - want
        mse = float((diff.astype(np.float64) ** 2).mean())
        psnr = 99.0 if mse == 0 else min(99.0, 10 * math.log10(255.0 ** 2 / mse))
        got.append((int(png.stem.split("_")[1]), psnr, float(diff.any(axis=2).mean()), 1.0, 0.0))
    return got


def _errors(flags: list[str], rec: Path, runs: dict, size, sample: int) -> dict:
    """(config key) -> [(frame, psnr, share of pixels that differ)]: each frame the run showed
    rendered again in this process beside the full-quality one. Target runs: every frame; fixed
    settings: every ``sample``-th."""
    from multigpu.config import WalkConfig
    from multigpu.core.camera import Camera
    from multigpu.core.lod import LevelChooser
    from multigpu.flags import scene_args, spec
    from multigpu.gpu.render import RegionRenderer, create_context
    from multigpu.planner import Planner
    from multigpu.records.report import COLUMNS
    from multigpu.scene.models import load_scene
    from multigpu.scene.paths import load_path

    p = argparse.ArgumentParser()
    scene_args(p)
    scene_spec = dataclasses.replace(spec(p.parse_known_args(flags)[0]), ranks=4)  # as the 4-rank runs load it
    scene, _ = load_scene(scene_spec)
    cfg = WalkConfig(scene=scene_spec, grid=(2, 2), tile=(size[0] // 2, size[1] // 2))
    planner, cams = Planner(cfg, scene), load_path(rec)
    chooser = LevelChooser(scene, size[1])
    ctx, _ = create_context()
    renderer = RegionRenderer(ctx, scene, size)
    col = {c: i for i, c in enumerate(COLUMNS)}

    def image(cam: Camera, scale: float, lod: float) -> np.ndarray:
        view, proj, light, _ = planner.frame(cam)
        levels = chooser.choose(cam, lod)[0]
        return renderer.render(view, proj, light, (0, 0, *size), None, scale=scale, levels=levels).astype(np.int16)

    got: dict = {}
    full_cache: dict = {}
    try:
        for key, run in runs.items():
            label, scale, lod, target = key
            if label == "full":
                continue
            every = range(0, run.rows.shape[0], 1 if target else sample)
            for f in every:  # frames, not objects
                cam = cams.camera(f)
                if target:
                    scale, lod = float(run.rows[f, 0, col["render_scale"]]), float(run.rows[f, 0, col["lod_error_px"]])
                if f not in full_cache:
                    full_cache[f] = image(cam, 1.0, 0.0)
                mine = image(cam, scale, lod)
                diff = mine - full_cache[f]
                mse = float((diff.astype(np.float64) ** 2).mean())
                psnr = 99.0 if mse == 0 else min(99.0, 10 * math.log10(255.0 ** 2 / mse))
                got.setdefault(key, []).append((f, psnr, float(diff.any(axis=2).mean()), scale, lod))
    finally:
        renderer.release()
        ctx.release()
    return got


def _judge(period: np.ndarray, target_ms: float) -> dict:
    """A target's hold over a run's frame periods (after the first two frames)."""
    p = period[2:]
    within = np.abs(p / target_ms - 1.0) <= 0.10
    win = np.convolve(p, np.ones(WINDOW) / WINDOW, mode="valid") if len(p) >= WINDOW else p
    win_ok = np.abs(win / target_ms - 1.0) <= 0.10
    settle = int(np.argmax(win_ok)) + WINDOW if win_ok.any() else -1
    return {"within_band": float(within.mean()), "windowed_within_band": float(win_ok.mean()),
            "settle_frames": settle}


def _rows(name: str, runs: dict, errors: dict, base) -> tuple[list[dict], list[dict]]:
    from multigpu.records.report import COLUMNS

    col = {c: i for i, c in enumerate(COLUMNS)}
    full_period = base.rows[:, :, col["frame_ms"]].mean(axis=1)
    floor = float((np.abs(full_period[2:] / np.median(full_period[2:]) - 1.0) <= 0.10).mean())
    rows, frames = [], []
    for key, run in runs.items():
        label, scale, lod, target = key
        period = run.rows[:, :, col["frame_ms"]].mean(axis=1)
        err = errors.get(key, [])
        s = run.summary
        row = {"scene": name, "config": label, "render_scale": s["quality"]["render_scale_mean"],
               "lod_error_px": s["quality"]["lod_error_px_mean"], "frame_ms": float(period[2:].mean()),
               "speedup": float(full_period[2:].mean() / period[2:].mean()), "emulated_ms": s["emulated_frame_ms"],
               "triangles": s["triangles_per_frame"],
               "choose_share": s["cpu"]["choosing_cpu_ms"] / max(s["emulated_frame_ms"], 1e-9),
               "psnr_median": float(np.median([e[1] for e in err])) if err else 99.0,
               "psnr_min": float(min(e[1] for e in err)) if err else 99.0,
               "differ_share": float(np.mean([e[2] for e in err])) if err else 0.0,
               "target_fps": target or 0.0, "noise_floor": floor, "within_band": "-", "windowed_within_band": "-",
               "settle_frames": "-", "reduced_frames": "-"}  # "-": not a target run
        if target:
            row.update(_judge(period, 1e3 / target))
            row["reduced_frames"] = s["target"]["reduced_frames"]
        rows.append(row)
        for f, psnr, share, sc, lo in err:
            frames.append({"scene": name, "config": label, "frame": f, "frame_ms": float(period[f]),
                           "render_scale": sc, "lod_error_px": lo, "psnr": psnr, "differ_share": share})
    return rows, frames


def _plot(rows: list[dict], frames: list[dict], out: Path) -> None:
    plt = _plt()
    names = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 3.6))
    for ax, name in zip(np.atleast_1d(axes), names):
        mine = [r for r in rows if r["scene"] == name]
        for r in mine:
            marker = "*" if r["target_fps"] else ("o" if r["config"] != "full" else "s")
            ax.scatter(r["frame_ms"], r["psnr_median"], marker=marker, s=60 if marker == "*" else 30)
            ax.annotate(r["config"].replace("scale ", "s").replace(", lod ", " l"), (r["frame_ms"], r["psnr_median"]),
                        fontsize=6, xytext=(3, 3), textcoords="offset points")
        ax.set_title(name)
        ax.set_xlabel("frame period (ms, wall)")
        ax.set_ylabel("PSNR against full quality (dB, median)")
    fig.tight_layout()
    fig.savefig(out / "fidelity.png", dpi=110)
    plt.close(fig)
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 2.2 * len(names)), squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        t = [r for r in rows if r["scene"] == name and r["config"] == "target 2x"]
        mine = [f for f in frames if f["scene"] == name and f["config"] == "target 2x"]
        if not t or not mine:
            continue
        ax.plot([f["frame"] for f in mine], [f["frame_ms"] for f in mine], lw=0.8, label="frame period (ms)")
        ax.axhline(1e3 / t[0]["target_fps"], color="k", ls="--", lw=0.8, label="target")
        ax2 = ax.twinx()
        ax2.plot([f["frame"] for f in mine], [f["render_scale"] for f in mine], color="C1", lw=0.8)
        ax2.set_ylabel("render scale", color="C1")
        ax.set_title(f"{name}: --target-fps {t[0]['target_fps']:.1f} (2x the full run)", fontsize=9)
        ax.set_ylabel("ms")
    axes[-1, 0].set_xlabel("frame")
    fig.tight_layout()
    fig.savefig(out / "fidelity_target.png", dpi=110)
    plt.close(fig)


def _markdown(rows: list[dict]) -> str:
    head = ("| scene | config | scale | LOD px | frame ms (wall) | speedup | emulated ms | PSNR median / min (dB) "
            "| pixels differ | within 10 % (frames / 10-frame windows) | settle (frames) | below full | choose share |")
    lines = [head, "|" + "---|" * 13]
    for r in rows:
        hold = (f"{100 * r['within_band']:.0f} % / {100 * r['windowed_within_band']:.0f} %" if r["target_fps"]
                else f"floor {100 * r['noise_floor']:.0f} %" if r["config"] == "full" else "")
        lines.append(f"| {r['scene']} | {r['config']} | {r['render_scale']:.2f} | {r['lod_error_px']:.2f} | "
                     f"{r['frame_ms']:.2f} | {r['speedup']:.2f}x | {r['emulated_ms']:.2f} | "
                     f"{r['psnr_median']:.1f} / {r['psnr_min']:.1f} | {100 * r['differ_share']:.1f} % | {hold} | "
                     f"{r['settle_frames'] if r['target_fps'] else ''} | "
                     f"{r['reduced_frames'] if r['target_fps'] else ''} | {100 * r['choose_share']:.2f} % |")
    return prose("fidelity", "section", table="\n".join(lines)) + "\n"
