"""One rank of the parallel renderer: balance, render, synchronize, exchange, display.

Run under ``mpiexec -n K``; ``comm`` and the rank's ``job.Job`` (liveness, interrupts) are
passed in. Setup (output directory, scene, path, GL context) is checked on every rank and
agreed before the first frame, so a bad input ends the whole job with one message and exit
code 2 instead of a hang. Every wait afterwards is bounded (``--timeout``) and watched
(a stalled or failed peer ends it in ``--liveness`` seconds or at once); timing rows reach
``timings.csv`` a whole frame at a time; ``summary.json`` always describes exactly the rows
written, and is rewritten when the run ends however it ends. SIGINT/SIGTERM stop all ranks
after the current frame.
"""

from __future__ import annotations

import json
import os
import socket
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multigpu.config import INTERACTIVE, MONITOR_BESIDE, WalkConfig, setup_timeout
from multigpu.core.bounds import BoxProjector
from multigpu.core.camera import frame_matrices
from multigpu.core.memory import release_heap
from multigpu.core.projectors import make_projector
from multigpu.core.spheres import SphereProjector
from multigpu.core.stereo import eye_canvas
from multigpu.errors import InputError
from multigpu.gpu.buffers import ensure_buffers
from multigpu.rank.exchange import agree, allgather_text
from multigpu.rank.fault import fault
from multigpu.rank.frame_setup import build
from multigpu.rank.frames import Frames
from multigpu.rank.presenters import rank_presenter
from multigpu.rank.spool import NAME as STEP_FILE
from multigpu.rank.spool import Spool, is_stream, spool_dir, spool_glob
from multigpu.records.outdir import OutputDir
from multigpu.records.recovery import mark, restarts
from multigpu.scene.models import load_scene
from multigpu.scene.moves import motion_of, movers_of, moves
from multigpu.scene.paths import CameraPath, check_cameras, generate, load_path


def make_path(cfg: WalkConfig, scene) -> CameraPath:
    """The path file's cameras, or a generated path (``--path interactive``: where the
    hand-flown camera starts; a restarted flight with ``--record`` starts where it was)."""
    if cfg.path == INTERACTIVE and cfg.resume_at and cfg.record and Path(cfg.record).is_file():
        flown = load_path(cfg.record)
        return CameraPath(*(a[-1:] for a in (flown.position, flown.target, flown.up, flown.fov, flown.near,
                                             flown.far))).translated(cfg.offset)
    if cfg.path and cfg.path != INTERACTIVE:
        path = load_path(cfg.path)
        if cfg.frames is not None:
            if cfg.frames > len(path):
                raise InputError.of("frames", f"{cfg.frames}: the path file {cfg.path} has only {len(path)} frames")
            path = CameraPath(*(None if a is None else a[:cfg.frames] for a in (  # a scene's times, a series' steps
                path.position, path.target, path.up, path.fov, path.near, path.far, path.times, path.steps)))
        return path
    return generate(cfg.path_kind, modelled(cfg, scene), None if cfg.path == INTERACTIVE else cfg.frames)


def modelled(cfg: WalkConfig, scene):
    """The scene as modelled (not cut into clusters for this wall): generated paths follow it,
    so a wall of any size, and its one-rank reference, fly the same camera."""
    if not scene.meta.get("objects", {}).get("cluster"):
        return scene
    import dataclasses

    whole, _ = load_scene(dataclasses.replace(cfg.scene, cluster=0))
    return whole.translated(cfg.offset) if any(cfg.offset) else whole


def load_world(cfg: WalkConfig, ready: "Ready | None" = None, given=None):
    """Scene, camera path and load facts, both moved by ``--offset`` (a file path too), so an
    offset run should show the same images as one at the scene's own coordinates. ``ready``: the
    scene and path a standby made while it waited (a flight's start is made now: it is where the
    restart resumes); ``given``: the scene, sent by rank 0 (a stream's first step on another PC)."""
    if ready is not None:
        scene, load_info = ready.scene, ready.load_info
        if ready.path is not None:
            return scene, ready.path, load_info
    else:
        scene, load_info = load_scene(cfg.scene) if given is None else (given, {"seconds": 0.0, "cached": False,
                                                                                "cache": None, "sent": True})
        if any(cfg.offset):
            scene = scene.translated(cfg.offset)
    path = make_path(cfg, scene)
    if cfg.path and cfg.path != INTERACTIVE and any(cfg.offset):
        path = path.translated(cfg.offset)
    return scene, path, load_info


@dataclass
class Ready:
    """What a standby job (``rank/standby.py``) set up while it waited, for a headless run: the
    scene mapped, its buffers file, this rank's place on its host, the GL context and the
    renderer with the scene's buffers. A restart handed to it starts with these."""

    scene: object
    load_info: dict
    path: object  # the camera path (None for a flight: its start is where the restart resumes)
    shared: object
    local: int
    host_ranks: int
    ctx: object
    device: object
    renderer: object


def prepare(cfg: WalkConfig, comm, wait: float) -> Ready:
    """A standby's setup before its go, headless (a window, a port or the output directory
    would be the running job's): every rank maps the cached scene (rank 0 makes the buffers
    file first) and makes its GL context and renderer. Raises what a run's setup raises."""
    scene, path, load_info = load_world(cfg)
    if cfg.path == INTERACTIVE:
        path = None
    shared = ensure_buffers(load_info.get("cache"), scene) if comm.Get_rank() == 0 else None
    agree(comm, None, wait, "standby")  # the buffers file is there before the others map it
    if comm.Get_rank() != 0:
        shared = ensure_buffers(load_info.get("cache"), scene)
    local, host_ranks = node_rank(comm, wait)
    ctx, device, renderer = _gl(cfg, comm.Get_rank(), None, scene, shared, local, host_ranks, None)
    return Ready(scene, load_info, path, shared, local, host_ranks, ctx, device, renderer)


def _gl(cfg: WalkConfig, rank: int, presenter, scene, shared, local: int, host_ranks: int, ready: Ready | None):
    """``(context, device, renderer)``: a standby's, made while it waited; else the window's
    context (``presenter``: None before there is one), or an EGL context of this rank's own, and
    a renderer holding the scene's buffers."""
    from multigpu.gpu.render import RegionRenderer, create_context

    if ready is not None:
        return ready.ctx, ready.device, ready.renderer
    if presenter is not None and presenter.context is not None:  # render in the window's context
        ctx, device = presenter.context, f"window on {presenter.display}"
    else:
        ctx, device = create_context(_device(cfg, rank), local_rank=local, host_ranks=host_ranks)
    return ctx, device, RegionRenderer(ctx, scene, eye_canvas(cfg.stereo, cfg.canvas).size, cfg.subfrustum, shared,
                                       cfg.colors, moves(scene, cfg.scene))


def _device(cfg: WalkConfig, rank: int):
    """The EGL device this rank renders on: the wall file's ``gpu`` (a stand-in on a dark tile:
    any), else ``--device``."""
    own = cfg.gpus and cfg.gpus[rank] is not None and rank not in cfg.dark
    return cfg.gpus[rank] if own else cfg.device


def projector(cfg: WalkConfig, scene) -> BoxProjector | SphereProjector:
    """The scene's bounds prepared once for per-frame projection (``--bounds box|sphere``)."""
    return make_projector(scene, cfg.bounds)


def _check_path(cfg, scene, path) -> None:
    """Every frame's camera is valid (the door, not frame N), and the path sees the scene."""
    check_cameras(path, cfg.path or "the generated path")
    project = projector(cfg, scene)
    for f in np.linspace(0, len(path) - 1, min(len(path), 12)).astype(int):
        view, proj, _ = frame_matrices(path.camera(int(f)), cfg.canvas.size)
        if (~np.isnan(project(view, proj)[:, 0])).any():
            return
    raise InputError(f"the camera path never sees the scene ({scene.name}): no visible triangles")


def node_rank(comm, timeout: float) -> tuple[int, int]:
    """This rank's index among the ranks on its host (ranks of one hostname, in rank order),
    and how many ranks that host runs.

    One bounded non-blocking exchange of host names, not MPI's blocking shared-memory split:
    a rank blocked in a collective stalls its heartbeats' delivery across hosts (MPICH over
    TCP), so the liveness check took a slow peer for a dead one."""
    hosts = allgather_text(comm, socket.gethostname(), timeout, "setup")
    mine = hosts[comm.Get_rank()]
    return hosts[: comm.Get_rank()].count(mine), hosts.count(mine)


def _check_video() -> None:
    try:
        import imageio.v2  # noqa: F401
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except Exception as exc:
        raise InputError.of("video", f"needs imageio with ffmpeg (pip install 'multigpu[video]'): "
                         f"{exc.__class__.__name__}: {exc}") from None


def run(cfg: WalkConfig, comm, job, ready: Ready | None = None) -> dict | None:
    """Render the walkthrough on this rank; rank 0 returns the summary. ``ready``: what a
    standby set up while it waited (the same on every rank: all have it, or none)."""
    rank, K = comm.Get_rank(), comm.Get_size()
    if K != cfg.processes:
        own = " (a rank for each eye of each tile: --eyes own)" if cfg.eyes == "own" else ""
        raise InputError.of("grid", f"{cfg.grid[0]}x{cfg.grid[1]} needs {cfg.processes} ranks{own} but the job has "
                            f"{K} (start it with mpiexec -n {cfg.processes})")
    wait = setup_timeout(cfg)
    # -- setup: rank 0 takes the output directory and builds the scene cache first (a stream's first step first)
    error, out, scene, path, load_info, shared, spool = _first(cfg, ready) if rank == 0 else (None,) * 7
    presenter = renderer = monitor = panel = tracker = None
    try:
        fault(rank, "setup")
        error = agree(comm, error, wait)
        if error:
            raise InputError(error)
        cfg, first = stream_setup(cfg, comm, wait)  # a stream's steps: the series rank 0 keeps of them
        try:
            from multigpu.gpu.render import raster_threads

            if rank != 0:
                scene, path, load_info = load_world(cfg, ready, first)
                shared = ready.shared if ready is not None else ensure_buffers(load_info.get("cache"), scene)

            local, host_ranks = (ready.local, ready.host_ranks) if ready is not None else node_rank(comm, wait)
            raster_threads(host_ranks)  # before any GL context, the window's included
            presenter = rank_presenter(cfg, rank)
            if rank == 0 and cfg.monitor is not None:
                monitor = _monitor(cfg, presenter)
            if rank == 0 and cfg.panel is not None:
                panel = _panel(cfg, scene, out)
            if rank == 0 and cfg.head_tracker is not None:
                tracker = _tracker(cfg)
            ctx, device, renderer = _gl(cfg, rank, presenter, scene, shared, local, host_ranks, ready)
            scene = scene.without_geometry()  # the GL buffers hold it now: its mapped pages go
            if rank == 0:
                mark("gl")
            from multigpu import kernels

            load_info = {**load_info, "kernel_seconds": kernels.warm()}  # compiled here, never in a frame
            release_heap()  # setup's freed temporaries leave the heap before the first frame
        except (InputError, RuntimeError) as exc:
            error = str(exc)
        error = agree(comm, error, wait)
        if error:
            raise InputError(error)
        placement = [json.loads(t) for t in allgather_text(comm, json.dumps(
            {"host": socket.gethostname(), "node_rank": local, "egl_device": device,
             "gl_renderer": ctx.info.get("GL_RENDERER"), "gl_buffers": renderer.storage}), wait, "setup")]
    except BaseException:
        _close(renderer, presenter, monitor, panel, tracker, spool)
        if out is not None:
            out.abandon()
        raise
    setup = None
    try:
        scene.movers = movers_of(scene, cfg.scene)  # the order sort-last ranges follow (core.drawlist.drawn_order)
        setup = build(cfg, comm, scene, path, renderer, presenter, out, load_info, placement, monitor, panel,
                      tracker)
        setup.spool, spool = spool, None  # rank 0's stream reader: the frame loop's now
        setup.first = first
        summary = Frames(cfg, comm, job, scene, path, renderer, presenter, setup).run()
        if panel is not None:
            panel.finish(summary)
        setup.release(collective=True)  # every rank left the frame loop after the same frame
        return summary
    except BaseException:
        if setup is not None:
            setup.release(collective=False)  # a failing rank must not wait in a collective free
        raise
    finally:
        _close(renderer, presenter, monitor, panel, tracker, spool)
        if out is not None:
            out.release()


def _first(cfg: WalkConfig, ready: Ready | None = None) -> tuple:
    """Rank 0's setup before the others': ``(error, out, scene, path, load_info, buffers file,
    stream reader)`` (``error``: the bad input's line; the output directory is then released).
    ``ready``: a standby's scene and buffers file. A stream's first step is kept before the scene
    is made of it (``rank/spool.py``)."""
    mark("imported")  # a restarted job's steps (records/recovery.py)
    out = scene = path = load_info = shared = spool = None
    try:
        out = OutputDir(cfg.out)
        if cfg.video:
            _check_video()
        if cfg.record:
            check_record(cfg.record)
        if is_stream(cfg.scene.model):
            spool = Spool(cfg.scene.model, spool_dir(cfg.out), setup_timeout(cfg))
            spool.first()
            cfg = streamed(cfg)
        scene, path, load_info = load_world(cfg, ready)
        mark("scene")
        motion_of(scene, cfg.scene)  # a model's animations checked here: bad input ends the job now, in one line
        warn_once(cfg, scene)
        _check_path(cfg, scene, path)
        # once, before the others map it
        shared = ready.shared if ready is not None else ensure_buffers(load_info.get("cache"), scene)
    except InputError as exc:
        if spool is not None:
            spool.close()
        return str(exc), out, scene, path, load_info, shared, None
    return None, out, scene, path, load_info, shared, spool


def stream_setup(cfg: WalkConfig, comm, wait: float) -> tuple:
    """Every rank's ``(cfg, first step)`` of a stream's run (``streamed``, coloured over rank 0's
    range); the first step as rank 0 sent it where this rank's PC cannot read rank 0's kept file
    (``rank/pushed.first_step``), else None."""
    if not is_stream(cfg.scene.model):
        return cfg, None
    from multigpu.rank.pushed import first_step

    rank = comm.Get_rank()
    mine = json.dumps(streamed(cfg).scene.color_range) if rank == 0 else ""
    live = streamed(cfg, json.loads(allgather_text(comm, mine, wait, "a stream's colours")[0]))
    have = rank == 0 or (spool_dir(cfg.out) / STEP_FILE.format(0)).is_file()
    return live, first_step(comm, lambda: load_scene(live.scene)[0], have, wait)


def streamed(cfg: WalkConfig, known=None) -> WalkConfig:
    """A stream's run (``--model adios2:NAME``) as the series of the steps rank 0 keeps in its outputs
    (every rank the same): coloured over ``--range``, else over the first step's own range
    (``known``: rank 0's, found already)."""
    if not is_stream(cfg.scene.model):
        return cfg
    import dataclasses

    from multigpu.scene.series import first_range

    spec, fixed = cfg.scene, cfg.scene.color_range if known is None else tuple(known)
    if spec.color_by is not None and fixed is None:
        fixed = first_range(spool_dir(cfg.out) / STEP_FILE.format(0), spec.color_by)
    live = dataclasses.replace(spec, model=spool_glob(cfg.out), color_range=fixed, live=True)
    return dataclasses.replace(cfg, scene=live)


def warn_once(cfg: WalkConfig, scene) -> None:
    """The model's warnings (a texture missing, faces dropped) on the console, one line each, at
    the job's first start (a restarted job has said them): they are in summary.json too."""
    if restarts():
        return
    name = cfg.scene.model or scene.name
    for w in scene.meta.get("warnings", []):
        print(f"multigpu: warning: {name}: {w}", file=sys.stderr, flush=True)


def _monitor(cfg: WalkConfig, presenter):
    """Rank 0's operator view on its display, at ``--monitor X,Y`` (default: right of the wall),
    or on a PC of its own (the launcher started it there: ``launcher/operator.py``)."""
    from multigpu.display import Monitor
    from multigpu.rank.live import monitor_size

    if os.environ.get("MULTIGPU_MONITOR"):
        from multigpu.display.remote import TOKEN_ENV, RemoteMonitor

        return RemoteMonitor(os.environ["MULTIGPU_MONITOR"], os.environ.get(TOKEN_ENV, ""))

    where = cfg.monitor if cfg.monitor != MONITOR_BESIDE else (cfg.canvas.size[0], 0)
    return Monitor(monitor_size(cfg.canvas.size, cfg.canvas.tiles(), cfg.tile), where, presenter)


def check_record(record: str) -> None:
    """``--record FILE`` can be written: its directory exists and takes files."""
    import os
    from pathlib import Path

    where = Path(record).expanduser().absolute()
    if where.is_dir():
        raise InputError.of("record", f"{record}: is a directory, not a path file")
    if not where.parent.is_dir():
        raise InputError.of("record", f"{record}: the directory {where.parent} does not exist")
    probe = where.parent / f".write-test-{os.getpid()}"
    try:  # a file made and removed: access() says yes to root, and to /proc, where nothing can be made
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
        os.unlink(probe)
    except OSError as exc:
        raise InputError.of("record", f"{record}: cannot write in {where.parent} ({exc.strerror or exc})") from None


def _panel(cfg: WalkConfig, scene, out):
    """Rank 0's operator page (``--panel``), serving once this returns (its URL printed)."""
    from multigpu.planner import balances_of
    from multigpu.rank.panel_link import PanelLink, legend
    from multigpu.records.record import run_title

    events = [f"restart {restarts()}: resumed at frame {cfg.resume_at}"] if cfg.resume_at else []
    if cfg.dark:
        events.append(f"dark tiles (their PC gone): {', '.join(map(str, cfg.dark))}")
    try:
        return PanelLink.open(cfg, run_title(cfg, scene), balances_of(cfg), out.path, events, legend(scene.meta),
                              scene.meta.get("series", {}).get("steps", 0))
    except OSError as exc:
        address, port = cfg.panel
        raise InputError.of("panel", f"cannot serve the page on {address}:{port} ({exc})") from None


def _tracker(cfg: WalkConfig):
    """Rank 0's UDP socket for the head's poses (``--head-tracker``)."""
    from multigpu.rank.head_link import HeadLink

    address, port = cfg.head_tracker
    try:
        return HeadLink.listen(address, port)
    except OSError as exc:
        raise InputError.of("head_tracker", f"cannot listen on udp {address}:{port} ({exc})") from None


def _close(renderer, presenter, monitor=None, panel=None, tracker=None, spool=None) -> None:
    for part in (tracker, spool):
        if part is not None:
            part.close()
    if panel is not None:
        panel.close()
    if renderer is not None:
        renderer.release()
    if monitor is not None:
        monitor.close()
    if presenter is not None:
        presenter.close()
