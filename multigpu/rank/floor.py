"""The MPI side of ``multigpu bench floor``: every rank renders exactly the same work.

Same region, same objects, same camera along the scene's walkthrough (matrices and projected
bounds from the frame loop's ``planner.Planner``), synchronized per frame by the frame loop's
bounded barrier (a rank that dies ends the job, never hangs it); the per-rank render CPU times
are compared exactly as ``report.summarize`` compares them (per frame max/mean, averaged over
frames). Whatever imbalance shows is this machine's measurement noise: the floor under every
strategy's ``imbalance_render_cpu``. ``studies/floor.py`` starts it and prints the table.
"""

from __future__ import annotations

import json
import time

import numpy as np

MARK = "floor-json: "
#: seconds any one wait may last (loading the scene and a frame's render included)
TIMEOUT = 300.0


def measure(spec, path_kind: str, frames: int, tile: int = 256, display: int | None = None) -> dict | None:
    """The worker, on every rank of an MPI job, for the scene of ``spec`` (a ``SceneSpec``)
    along its generated ``path_kind`` path: every rank renders the ``tile``-sided centre region
    of a ``display``-sided display (default twice the tile: a 2x2 wall's); returns the figures
    on rank 0."""
    from mpi4py import MPI

    from multigpu.config import WalkConfig
    from multigpu.core.regions import overlaps, pixel_spans
    from multigpu.gpu.render import RegionRenderer, create_context
    from multigpu.planner import Planner
    from multigpu.rank.exchange import barrier, wait_all
    from multigpu.scene.models import load_scene
    from multigpu.scene.paths import generate

    comm = MPI.COMM_WORLD
    rank = comm.Get_rank()
    if rank == 0:
        load_scene(spec)  # build the cache once
    barrier(comm, TIMEOUT)
    scene, _ = load_scene(spec)
    side = 2 * tile if display is None else int(display)
    size = (side, side)
    ctx, _ = create_context(local_rank=rank, host_ranks=comm.Get_size())  # one host
    renderer = RegionRenderer(ctx, scene, size)
    path = generate(path_kind, scene, frames)
    planner = Planner(WalkConfig(grid=(1, 1), tile=size), scene, rank)  # the frame loop's projection
    at = (side - tile) // 2
    region = (at, at, at + tile, at + tile)  # a tile-sized centre region
    times = np.zeros(frames)
    for f in range(frames):  # frames, not objects
        view, proj, light, rects = planner.frame(path.camera(f))
        spans, onscreen = pixel_spans(rects, size)
        mask = onscreen & overlaps(spans, region)  # the objects a rank rendering the region draws
        barrier(comm, TIMEOUT)
        t0 = time.process_time()
        renderer.render(view, proj, light, region, mask)
        times[f] = (time.process_time() - t0) * 1e3
    allt = np.zeros((comm.Get_size(), frames))  # every rank's buffer: Igather ignores it off the root
    wait_all([comm.Igather(times, allt, root=0)], TIMEOUT, "floor times")
    renderer.release()
    if rank != 0:
        return None
    t = allt.T[min(5, frames - 1):]  # (F, K), first frames warm up
    return {"scene": scene.name, "ranks": int(comm.Get_size()), "frames": int(t.shape[0]), "tile": int(tile),
            "display": side,
            "render_ms_mean": float(t.mean()),
            "imbalance_floor": float(np.mean(t.max(axis=1) / t.mean(axis=1))),
            "noise_cv": float(np.mean(t.std(axis=1) / t.mean(axis=1)))}


def main(spec, path_kind: str, frames: int, tile: int = 256, display: int | None = None) -> None:
    """Measure and print rank 0's figures as one JSON line after ``MARK``."""
    got = measure(spec, path_kind, frames, tile, display)
    if got is not None:
        print(MARK + json.dumps(got), flush=True)
