"""One rank of the parallel renderer: balance, render, synchronize, exchange, display.

Run under ``mpiexec -n K``; ``comm`` is passed in. Setup (scene, path, output, GL context) is
checked on every rank and agreed before the first frame, so a bad input ends the whole job
with one message and exit code 2 instead of a hang. Every wait afterwards is bounded
(``--timeout``); timing rows reach ``timings.csv`` frame by frame; ``summary.json`` and images
are written atomically; SIGINT/SIGTERM stop all ranks after the current frame.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np

from .bounds import BoxProjector, SphereProjector, make_projector
from .config import WalkConfig
from .errors import InputError
from .exchange import barrier, broadcast_partition, exchange, wait_all
from .models import load_scene
from .mosaic import overlay, save_png, stitch
from .paths import CameraPath, load_path, orbit, walkthrough
from .regions import tile_regions, transfers
from .report import COLUMNS, TimingWriter, summarize, table, write_json
from .strategies import make_strategy

STOP = {"flag": False}


def _on_signal(signum, frame):
    STOP["flag"] = True


def agree(comm, error: str | None, timeout: float) -> str | None:
    """Every rank's setup outcome; the first error (with its rank) or None, on all ranks."""
    wait_all([comm.Ibarrier()], timeout, "setup")
    errors = comm.allgather(error)
    bad = [(r, e) for r, e in enumerate(errors) if e]
    if not bad:
        return None
    r, e = bad[0]
    return e if len(set(e for _, e in bad)) == 1 else f"rank {r}: {e}"


def make_path(cfg: WalkConfig, scene) -> CameraPath:
    if cfg.path:
        path = load_path(cfg.path)
        if cfg.frames is not None:
            if cfg.frames > len(path):
                raise InputError(f"--frames {cfg.frames}: the path file {cfg.path} has only {len(path)} frames")
            path = CameraPath(*(a[:cfg.frames] for a in (path.position, path.target, path.up, path.fov,
                                                           path.near, path.far)))
        return path
    gen = walkthrough if cfg.path_kind == "walkthrough" else orbit
    return gen(scene, frames=cfg.frames or (1200 if cfg.path_kind == "walkthrough" else 300))


def load_world(cfg: WalkConfig):
    """Scene, camera path and load facts, both moved by ``--offset`` (a file path too), so an
    offset run should show the same images as one at the scene's own coordinates."""
    scene, load_info = load_scene(cfg.scene)
    if any(cfg.offset):
        scene = scene.translated(cfg.offset)
    path = make_path(cfg, scene)
    if cfg.path and any(cfg.offset):
        path = path.translated(cfg.offset)
    return scene, path, load_info


def projector(cfg: WalkConfig, scene) -> BoxProjector | SphereProjector:
    """The scene's bounds prepared once for per-frame projection (``--bounds box|sphere``)."""
    return make_projector(scene, cfg.bounds)


def _check_visible(cfg, scene, path) -> None:
    from .render import frame_matrices

    project = projector(cfg, scene)
    for f in np.linspace(0, len(path) - 1, min(len(path), 12)).astype(int):
        view, proj, _ = frame_matrices(path.camera(int(f)), cfg.size)
        if (~np.isnan(project(view, proj)[:, 0])).any():
            return
    raise InputError(f"the camera path never sees the scene ({scene.name}): no visible triangles")


def _fault(rank: int, frame: int) -> None:
    """Test-only fault injection: MULTIGPU_FAULT='RANK:FRAME' raises there."""
    spec = os.environ.get("MULTIGPU_FAULT")
    if spec:
        r, f = (int(v) for v in spec.split(":"))
        if r == rank and f == frame:
            raise RuntimeError(f"injected fault at frame {frame}")


def run(cfg: WalkConfig, comm) -> dict | None:
    """Render the walkthrough on this rank; rank 0 returns the summary."""
    rank, K = comm.Get_rank(), comm.Get_size()
    if K != cfg.ranks:
        raise InputError(f"--grid {cfg.grid[0]}x{cfg.grid[1]} needs {cfg.ranks} ranks but the job has {K} "
                         f"(start it with mpiexec -n {cfg.ranks})")
    # -- setup: rank 0 builds the scene cache first, then every rank loads and checks
    error = None
    scene = path = out = None
    if rank == 0:
        try:
            out = cfg.check_output()
            scene, path, load_info = load_world(cfg)
            _check_visible(cfg, scene, path)
        except InputError as exc:
            error = str(exc)
    error = agree(comm, error, max(cfg.timeout, 600.0))
    if error:
        raise InputError(error)
    ctx = renderer = None
    try:
        if rank != 0:
            scene, path, load_info = load_world(cfg)
        from .render import RegionRenderer, create_context

        ctx, device = create_context(cfg.device)
        renderer = RegionRenderer(ctx, scene, cfg.size, cfg.subfrustum)
    except (InputError, RuntimeError) as exc:
        error = str(exc)
    error = agree(comm, error, max(cfg.timeout, 600.0))
    if error:
        raise InputError(error)
    return _frames(cfg, comm, scene, path, renderer, out, load_info, device)


def _frames(cfg, comm, scene, path, renderer, out, load_info, device) -> dict | None:
    from .render import frame_matrices

    rank, K = comm.Get_rank(), comm.Get_size()
    size = cfg.size
    tw, th = cfg.tile
    tiles = tile_regions(cfg.grid[0], cfg.grid[1], tw, th)
    my_tile = tiles[rank]
    strategy = make_strategy(cfg.balance, cfg.grid, size, cfg.strips)
    broadcast = cfg.partition == "broadcast" and K > 1
    tris = scene.tris
    project = projector(cfg, scene)
    coverage = None
    if strategy.needs_coverage:
        coverage = np.ones(scene.n_objects)
    back = np.zeros((th, tw, 3), dtype=np.uint8)  # composed tile
    front = np.zeros_like(back)  # what the rank's monitor shows
    n_frames = len(path)
    ncol = len(COLUMNS)
    row = np.zeros(ncol + 1)  # + stop flag
    allrows = np.zeros((K, ncol + 1))
    gathered = np.zeros((K, th, tw, 3), dtype=np.uint8) if rank == 0 else None
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)

    writer = video = bar = None
    history: list[np.ndarray] = []
    config_doc = _config_doc(cfg, scene, load_info, n_frames, device, renderer.method)
    if rank == 0:
        (out / "mosaic").mkdir(exist_ok=True)
        writer = TimingWriter(out / "timings.csv")
        if cfg.video:
            video = _open_video(out / "mosaic.mp4")
        if cfg.progress:
            from tqdm import tqdm

            bar = tqdm(total=n_frames, unit="frame", desc=f"{K} ranks", dynamic_ncols=True, mininterval=1.0)
    complete = False
    done = 0
    summary = {"frames": 0}
    try:
        for f in range(n_frames):
            w0, c0 = time.perf_counter(), time.process_time()
            _fault(rank, f)
            view, proj, light = frame_matrices(path.camera(f), size)
            part = None
            if rank == 0 or not broadcast:  # redundant: every rank plans the same partition
                if coverage is None:
                    part = strategy.plan(project(view, proj), tris)
                else:
                    part = strategy.plan(project(view, proj, coverage), tris, coverage)
            if broadcast:
                part = broadcast_partition(comm, part, K, scene.n_objects, cfg.timeout)
            w1, c1 = time.perf_counter(), time.process_time()
            region = part.regions[rank]
            mask = part.visible[rank]
            pixels = renderer.render(view, proj, light, region, mask)
            w2, c2 = time.perf_counter(), time.process_time()
            barrier(comm, cfg.timeout)
            w3, c3 = time.perf_counter(), time.process_time()
            plan = transfers(part.regions, tiles, include_self=True)
            sent = exchange(comm, rank, pixels, region, my_tile, plan, cfg.timeout, back)
            w4, c4 = time.perf_counter(), time.process_time()
            np.copyto(front, back)  # present the composed tile
            w5, c5 = time.perf_counter(), time.process_time()
            row[:] = [f, rank, part.loads[rank], *region,
                      (w1 - w0) * 1e3, (w2 - w1) * 1e3, (w3 - w2) * 1e3, (w4 - w3) * 1e3, (w5 - w4) * 1e3,
                      (w5 - w0) * 1e3, (c1 - c0) * 1e3, (c2 - c1) * 1e3, (c4 - c3) * 1e3, (c5 - c4) * 1e3,
                      sent, int(mask.sum()), float(STOP["flag"])]
            wait_all([comm.Iallgather(row, allrows)], cfg.timeout, "timing gather")
            strategy.observe(part, allrows[:, COLUMNS.index("rendering_cpu_ms")])
            done = f + 1
            mosaic_due = cfg.mosaic_every and (f % cfg.mosaic_every == 0 or f == n_frames - 1)
            if mosaic_due or video is not None:
                wait_all([comm.Igather(front, gathered, root=0)], cfg.timeout, "mosaic gather")
            if rank == 0:
                writer.write(allrows[:, :ncol])
                history.append(allrows[:, :ncol].copy())
                if mosaic_due or video is not None:
                    img = stitch(gathered, tiles, size)
                    if mosaic_due:
                        save_png(img, out / "mosaic" / f"frame_{f:05d}.png")
                        if cfg.overlay:
                            save_png(overlay(img, part.regions), out / "mosaic" / f"frame_{f:05d}_partition.png")
                    if video is not None:
                        video.append_data(img)
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix(fps=f"{1e3 / max(allrows[:, COLUMNS.index('frame_ms')].max(), 1e-9):.1f}")
                if f % 50 == 49:
                    _write_summary(out, history, K, {**config_doc, "strategy": strategy.report()}, complete=False)
            if allrows[:, -1].any():
                break
        complete = done == n_frames
    finally:
        if rank == 0:
            if bar is not None:
                bar.close()
            if writer is not None:
                writer.close()
            if video is not None:
                video.close()
            if history:
                summary = _write_summary(out, history, K, {**config_doc, "strategy": strategy.report()}, complete=complete)
        if renderer is not None:
            renderer.release()
    if rank == 0:
        state = "" if complete else f" (stopped after {done} of {n_frames} frames)"
        print(table(summary, f"multigpu walkthrough: {scene.name}, {scene.n_triangles} triangles in "
                             f"{scene.n_objects} objects, {cfg.grid[0]}x{cfg.grid[1]} wall of {size[0]}x{size[1]}, "
                             f"balance={cfg.balance}{state}"), flush=True)
        print(f"outputs in {out}/ (timings.csv, summary.json, mosaic/)", flush=True)
        return summary
    return None


def _config_doc(cfg, scene, load_info, n_frames, device, renderer_method) -> dict:
    return {"grid": list(cfg.grid), "tile": list(cfg.tile), "size": list(cfg.size), "strips": cfg.strips,
            "balance": cfg.balance, "bounds": cfg.bounds, "frames_planned": n_frames,
            "subfrustum": renderer_method, "offset": list(cfg.offset), "partition": cfg.partition,
            "scene": {"name": scene.name, "objects": scene.n_objects, "triangles": scene.n_triangles,
                      "load_seconds": round(load_info["seconds"], 3), "cached": load_info["cached"],
                      "warnings": scene.meta.get("warnings", [])},
            "path": cfg.path or cfg.path_kind, "egl_device": device,
            "lp_num_threads": os.environ.get("LP_NUM_THREADS")}


def _write_summary(out: Path, history, K, config_doc, complete: bool) -> dict:
    summary = summarize(np.concatenate(history), K)
    doc = {"complete": complete, "config": config_doc, **summary}
    write_json(out / "summary.json", doc)
    return summary


def _open_video(path: Path):
    try:
        import imageio.v2 as imageio

        return imageio.get_writer(str(path), fps=30, macro_block_size=1)
    except Exception as exc:  # imageio or its ffmpeg missing: say so, render on
        print(f"multigpu: --video disabled: {exc.__class__.__name__}: {exc}", flush=True)
        return None
