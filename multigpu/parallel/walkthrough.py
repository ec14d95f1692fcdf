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

import os
import time
from dataclasses import dataclass, field

import numpy as np

from multigpu.config import SUMMARY_EVERY, WalkConfig, setup_timeout
from multigpu.core.bounds import BoxProjector, SphereProjector, make_projector
from multigpu.core.camera import frame_matrices
from multigpu.core.regions import tile_regions
from multigpu.core.work import Work, transfers
from multigpu.decompositions import make_decomposition
from multigpu.errors import InputError, as_flags
from multigpu.parallel.composite import composite
from multigpu.parallel.exchange import agree, barrier, broadcast_partition, wait_all
from multigpu.parallel.mosaic import overlay, save_png, stitch
from multigpu.parallel.outdir import OutputDir
from multigpu.parallel.report import COLUMNS, TimingWriter, summarize, table, write_json
from multigpu.parallel.shared import SharedPieces, composite_shared
from multigpu.scene.models import axis_name, load_scene
from multigpu.scene.paths import CameraPath, check_cameras, generate, load_path


def make_path(cfg: WalkConfig, scene) -> CameraPath:
    if cfg.path:
        path = load_path(cfg.path)
        if cfg.frames is not None:
            if cfg.frames > len(path):
                raise InputError.of("frames", f"{cfg.frames}: the path file {cfg.path} has only {len(path)} frames")
            path = CameraPath(*(a[:cfg.frames] for a in (path.position, path.target, path.up, path.fov,
                                                           path.near, path.far)))
        return path
    return generate(cfg.path_kind, modelled(cfg, scene), cfg.frames)


def modelled(cfg: WalkConfig, scene):
    """The scene as modelled (not cut into clusters for this wall): generated paths follow it,
    so a wall of any size, and its one-rank reference, fly the same camera."""
    if not scene.meta.get("objects", {}).get("cluster"):
        return scene
    import dataclasses

    whole, _ = load_scene(dataclasses.replace(cfg.scene, cluster=0))
    return whole.translated(cfg.offset) if any(cfg.offset) else whole


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


def _check_path(cfg, scene, path) -> None:
    """Every frame's camera is valid (the door, not frame N), and the path sees the scene."""
    check_cameras(path, cfg.path or "the generated path")
    project = projector(cfg, scene)
    for f in np.linspace(0, len(path) - 1, min(len(path), 12)).astype(int):
        view, proj, _ = frame_matrices(path.camera(int(f)), cfg.size)
        if (~np.isnan(project(view, proj)[:, 0])).any():
            return
    raise InputError(f"the camera path never sees the scene ({scene.name}): no visible triangles")


def _fault(rank: int, where: int | str) -> None:
    """Test-only fault injection: MULTIGPU_FAULT='RANK:WHERE[:stop]' with WHERE a frame
    number or 'setup' raises there, or with ':stop' stops the rank (SIGSTOP: a frozen rank; if
    something continues it, it carries on as if nothing happened)."""
    spec = os.environ.get("MULTIGPU_FAULT")
    if spec:
        r, w, *action = spec.split(":")
        if int(r) == rank and w == str(where):
            if action == ["stop"]:
                import signal

                os.kill(os.getpid(), signal.SIGSTOP)
                return
            raise RuntimeError(f"injected fault at {'frame ' if isinstance(where, int) else ''}{where}")


def node_rank(comm) -> int:
    """This rank's index among the ranks on its node (MPI's shared-memory split: any launcher)."""
    from mpi4py import MPI

    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        return node.Get_rank()
    finally:
        node.Free()


def _check_video() -> None:
    try:
        import imageio.v2  # noqa: F401
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except Exception as exc:
        raise InputError.of("video", f"needs imageio with ffmpeg (pip install 'multigpu[video]'): "
                         f"{exc.__class__.__name__}: {exc}") from None


def run(cfg: WalkConfig, comm, job) -> dict | None:
    """Render the walkthrough on this rank; rank 0 returns the summary."""
    rank, K = comm.Get_rank(), comm.Get_size()
    if K != cfg.ranks:
        raise InputError.of("grid", f"{cfg.grid[0]}x{cfg.grid[1]} needs {cfg.ranks} ranks but the job has {K} "
                         f"(start it with mpiexec -n {cfg.ranks})")
    wait = setup_timeout(cfg)
    # -- setup: rank 0 takes the output directory and builds the scene cache first
    error = None
    scene = path = out = None
    if rank == 0:
        try:
            out = OutputDir(cfg.out)
            if cfg.video:
                _check_video()
            scene, path, load_info = load_world(cfg)
            _check_path(cfg, scene, path)
        except InputError as exc:
            error = as_flags(exc)
    try:
        _fault(rank, "setup")
        error = agree(comm, error, wait)
        if error:
            raise InputError(error)
        ctx = renderer = None
        try:
            if rank != 0:
                scene, path, load_info = load_world(cfg)
            from multigpu.gpu.render import RegionRenderer, create_context

            ctx, device = create_context(cfg.device, local_rank=node_rank(comm))
            renderer = RegionRenderer(ctx, scene, cfg.size, cfg.subfrustum)
        except (InputError, RuntimeError) as exc:
            error = as_flags(exc)
        error = agree(comm, error, wait)
        if error:
            raise InputError(error)
    except BaseException:
        if out is not None:
            out.abandon()
        raise
    frames = None
    try:
        frames = Frames(cfg, comm, job, scene, path, renderer, out, load_info, device)
        summary = frames.run()
        frames.release(collective=True)  # every rank left the frame loop after the same frame
        return summary
    except BaseException:
        if frames is not None:
            frames.release(collective=False)  # a failing rank must not wait in a collective free
        raise
    finally:
        renderer.release()
        if out is not None:
            out.release()


@dataclass
class Timer:
    """Named phase marks of one frame: wall (perf_counter) and process CPU time."""

    marks: list = field(default_factory=list)

    def mark(self) -> None:
        self.marks.append((time.perf_counter(), time.process_time()))

    def ms(self, i: int, j: int, cpu: bool = False) -> float:
        return (self.marks[j][1 if cpu else 0] - self.marks[i][1 if cpu else 0]) * 1e3


class Frames:
    """The frame loop in named phases: plan, render, synchronize, exchange, display, record."""

    def __init__(self, cfg: WalkConfig, comm, job, scene, path, renderer, out: OutputDir | None, load_info, device):
        self.cfg, self.comm, self.job = cfg, comm, job
        self.scene, self.path, self.renderer = scene, path, renderer
        self.rank, self.K = comm.Get_rank(), comm.Get_size()
        tw, th = cfg.tile
        self.tiles = tile_regions(cfg.grid[0], cfg.grid[1], tw, th)
        self.decomposition = make_decomposition(cfg.decomposition, cfg.grid, cfg.size, cfg.strips, scene,
                                                cfg.balance, cfg.bin_size, cfg.bin_pattern, cfg.db_ranges,
                                                rank=self.rank)
        self.broadcast = cfg.partition == "broadcast" and self.K > 1  # screen only (checked at the door)
        self.project = projector(cfg, scene)
        self.coverage = np.ones(scene.n_objects) if self.decomposition.needs_coverage else None
        self.back = np.zeros((th, tw, 3), dtype=np.uint8)  # composed tile
        self.zback = np.ones((th, tw), dtype=np.float32) if self.decomposition.depth else None
        self.background = renderer.render(np.eye(4), np.eye(4), np.array([0.0, 0.0, 1.0]), (0, 0, 1, 1),
                                          np.zeros(scene.n_objects, dtype=bool))[0, 0]  # the clear colour
        self.front = np.zeros_like(self.back)  # what the rank's monitor shows
        self.col = {c: i for i, c in enumerate(COLUMNS)}
        self.row = np.zeros(len(COLUMNS) + 1)  # + stop flag
        self.allrows = np.zeros((self.K, len(COLUMNS) + 1))
        self.gathered = np.zeros((self.K, th, tw, 3), dtype=np.uint8) if self.rank == 0 else None
        self.n_frames = len(path)
        self.done = 0
        self.out = out
        self.history: list[np.ndarray] = []
        self.learn = None  # (frame, work, times) the strategy observes at the start of the next frame
        self.shared = None if cfg.exchange != "shared" else SharedPieces.make(
            comm, cfg.size, self.decomposition.depth, cfg.timeout)
        self.config_doc = _config_doc(cfg, scene, load_info, self.n_frames, device, renderer.method)
        self.config_doc["exchange"] = "shared" if self.shared is not None else "messages"
        self.writer = self.video = self.bar = None

    # -- phases of one frame
    def plan(self, f: int):
        """This frame's work (every rank plans the same, or rank 0 plans and broadcasts)."""
        view, proj, light = frame_matrices(self.path.camera(f), self.cfg.size)
        tris, d = self.scene.tris, self.decomposition
        if self.broadcast:
            part = None
            if self.rank == 0:
                cov = self.coverage
                part = d.strategy.plan(self.project(view, proj, cov) if cov is not None else self.project(view, proj),
                                       tris, cov)
            part = broadcast_partition(self.comm, part, self.K, self.scene.n_objects, self.cfg.timeout)
            return d.plan_from(part, tris), (view, proj, light)
        if self.coverage is None:
            return d.plan(f, self.project(view, proj), tris), (view, proj, light)
        return d.plan(f, self.project(view, proj, self.coverage), tris, self.coverage), (view, proj, light)

    def render(self, work: Work, view, proj, light) -> list:
        """Every piece this rank renders: (rgb, depth or None)."""
        out = []
        for rect, mask in zip(work.rects[self.rank], work.masks[self.rank]):  # pieces, not objects
            got = self.renderer.render(view, proj, light, rect, mask, depth=work.depth)
            out.append(got if work.depth else (got, None))
        return out

    def compose(self, f: int, work: Work, rendered: list) -> tuple[int, int]:
        """Frame exchange: the pieces travel to their tile owners, who copy or depth-merge them
        (through the node-shared window when there is one, else as messages)."""
        if work.depth:
            self.back[:] = self.background
            self.zback[:] = 1.0
        plan = transfers(work, self.tiles)
        zback = self.zback if work.depth else None
        if self.shared is None:
            return composite(self.comm, self.rank, work.rects, rendered, plan, self.tiles[self.rank],
                             self.cfg.timeout, self.back, zback)
        composite_shared(self.shared, f, self.rank, work.rects, plan, self.tiles[self.rank], self.back, zback)
        px = sum(p.pixels for p in plan if p.sender == self.rank and p.receiver != self.rank)  # read by peers
        return px * (7 if work.depth else 3), px * 4 if work.depth else 0

    def record(self, f: int, work: Work, t: Timer, sent: tuple[int, int]) -> None:
        """This rank's row by column name, gathered so every rank sees every rank's row."""
        box = work.bounds(self.rank)
        values = {"frame": f, "rank": self.rank, "triangles": work.loads[self.rank],
                  "x0": box[0], "y0": box[1], "x1": box[2], "y1": box[3],
                  "load_balancing_ms": t.ms(0, 1), "rendering_ms": t.ms(1, 2), "synchronization_ms": t.ms(3, 4),
                  "frame_exchange_ms": t.ms(2, 3) + t.ms(4, 5), "display_ms": t.ms(5, 6), "frame_ms": t.ms(0, 6),
                  "load_balancing_cpu_ms": t.ms(0, 1, True), "rendering_cpu_ms": t.ms(1, 2, True),
                  "frame_exchange_cpu_ms": t.ms(2, 3, True) + t.ms(4, 5, True), "display_cpu_ms": t.ms(5, 6, True),
                  "bytes_sent": sent[0], "objects": work.objects(self.rank), "pieces": len(work.rects[self.rank]),
                  "depth_bytes": sent[1], "load_cv": work.load_cv}
        for c, v in values.items():
            self.row[self.col[c]] = v
        self.row[-1] = float(self.job.signum or 0)  # a signal seen here stops every rank after this frame
        wait_all([self.comm.Iallgather(self.row, self.allrows)], self.cfg.timeout, "timing gather")

    def show(self, f: int, part) -> None:
        """Mosaic PNGs and video frames: every rank joins the gather on the same frames."""
        cfg = self.cfg
        mosaic_due = bool(cfg.mosaic_every) and (f % cfg.mosaic_every == 0 or f == self.n_frames - 1)
        if not (mosaic_due or cfg.video):
            return
        wait_all([self.comm.Igather(self.front, self.gathered, root=0)], cfg.timeout, "mosaic gather")
        if self.rank != 0:
            return
        img = stitch(self.gathered, self.tiles, cfg.size)
        if mosaic_due:
            save_png(img, self.out.path / "mosaic" / f"frame_{f:05d}.png")
            if cfg.overlay:
                save_png(overlay(img, part.rects), self.out.path / "mosaic" / f"frame_{f:05d}_partition.png")
        if self.video is not None:
            self.video.append_data(img)

    def frame(self, f: int) -> None:
        t = Timer()
        t.mark()
        _fault(self.rank, f)
        if self.learn is not None:  # the strategy learns from the last frame's times: balancing CPU too
            self.decomposition.observe(*self.learn)
            self.learn = None
        work, (view, proj, light) = self.plan(f)
        t.mark()
        rendered = self.render(work, view, proj, light)
        t.mark()
        if self.shared is not None:  # pieces into the shared window before the barrier (exchange)
            self.shared.publish(f, self.rank, rendered)
        t.mark()
        barrier(self.comm, self.cfg.timeout)
        t.mark()
        sent = self.compose(f, work, rendered)
        t.mark()
        np.copyto(self.front, self.back)  # present the composed tile
        t.mark()
        self.record(f, work, t, sent)
        self.learn = (f, work, self.allrows[:, self.col["rendering_cpu_ms"]].copy())
        if self.rank == 0:  # rows first: the summary always matches the CSV
            rows = self.allrows[:, :len(COLUMNS)]
            self.writer.write(rows)
            self.history.append(rows.copy())
        self.done = f + 1
        self.show(f, work)
        if self.rank == 0:
            if self.bar is not None:
                self.bar.update(1)
                self.bar.set_postfix(fps=f"{1e3 / max(self.allrows[:, self.col['frame_ms']].max(), 1e-9):.1f}")
            if f % SUMMARY_EVERY == SUMMARY_EVERY - 1:
                self.write_summary(complete=False)

    def release(self, collective: bool) -> None:
        """Give the shared window back: freed with the peers after a run every rank finished,
        only unlocked on a failure (the job ends anyway; a collective free would wait on ranks
        that are gone or still in the frame loop)."""
        if self.shared is not None:
            self.shared.close(collective)
            self.shared = None

    # -- the run
    def open_outputs(self) -> None:
        self.out.clear_previous()
        self.writer = TimingWriter(self.out.path / "timings.csv")
        self.write_summary(complete=False)
        if self.cfg.video:
            import imageio.v2 as imageio

            self.video = imageio.get_writer(str(self.out.path / "mosaic.mp4"), fps=30, macro_block_size=1)
        if self.cfg.progress:
            from tqdm import tqdm

            self.bar = tqdm(total=self.n_frames, unit="frame", desc=f"{self.K} ranks", dynamic_ncols=True,
                            mininterval=1.0)

    def close_outputs(self, complete: bool, stopped_by: str | None) -> dict:
        for thing in (self.bar, self.writer, self.video):
            if thing is not None:
                try:
                    thing.close()
                except Exception:  # closing must not hide the run's own error
                    pass
        return self.write_summary(complete=complete, stopped_by=stopped_by)

    def write_summary(self, complete: bool, stopped_by: str | None = None) -> dict:
        rows = np.concatenate(self.history) if self.history else np.zeros((0, len(COLUMNS)))
        summary = summarize(rows, self.K)
        doc = {"complete": complete, "frames_written": self.done, "config": self.config_doc,
               "decomposition": self.decomposition.report(), **summary}
        if stopped_by:
            doc["stopped_by"] = stopped_by
        write_json(self.out.path / "summary.json", doc)
        return summary

    def _what(self) -> str:
        cfg = self.cfg
        if cfg.decomposition == "screen":
            return f"balance={cfg.balance}"
        if cfg.decomposition == "bins":
            return f"bins {cfg.bin_pattern} {cfg.bin_size}px"
        return f"db ({cfg.db_ranges} ranges)"

    def run(self) -> dict | None:
        if self.rank == 0:
            self.open_outputs()
        complete, stopped_by = False, None
        self.job.in_frames = True
        try:
            for f in range(self.n_frames):
                self.frame(f)
                if self.allrows[:, -1].any():  # a rank was interrupted: all stop after this frame
                    self.job.signum = self.job.signum or int(self.allrows[:, -1].max())
                    break
            complete = self.done == self.n_frames
            if not complete:
                import signal

                stopped_by = f"signal {signal.Signals(self.job.signum).name}"
        except BaseException as exc:
            stopped_by = f"{exc.__class__.__name__}: {exc}"
            raise
        finally:
            if self.rank == 0:
                summary = self.close_outputs(complete, stopped_by)
        if self.rank != 0:
            return None
        cfg, scene = self.cfg, self.scene
        state = "" if complete else f" (stopped after {self.done} of {self.n_frames} frames)"
        print(table(summary, f"multigpu walkthrough: {scene.name}, {scene.n_triangles} triangles in "
                             f"{scene.n_objects} objects, {cfg.grid[0]}x{cfg.grid[1]} wall of {cfg.size[0]}x"
                             f"{cfg.size[1]}, {self._what()}{state}"), flush=True)
        print(f"outputs in {self.out.path}/ (timings.csv, summary.json, mosaic/)", flush=True)
        return summary


def _config_doc(cfg, scene, load_info, n_frames, device, renderer_method) -> dict:
    return {"grid": list(cfg.grid), "tile": list(cfg.tile), "size": list(cfg.size), "strips": cfg.strips,
            "decomposition": cfg.decomposition, "balance": cfg.balance if cfg.decomposition == "screen" else None,
            "bin_size": cfg.bin_size if cfg.decomposition == "bins" else None,
            "bin_pattern": cfg.bin_pattern if cfg.decomposition == "bins" else None,
            "db_ranges": cfg.db_ranges if cfg.decomposition == "db" else None, "bounds": cfg.bounds,
            "frames_planned": n_frames,
            "subfrustum": renderer_method, "offset": list(cfg.offset), "partition": cfg.partition,
            "scene": {"name": scene.name, "objects": scene.n_objects, "triangles": scene.n_triangles,
                      "load_seconds": round(load_info["seconds"], 3), "cached": load_info["cached"],
                      "warnings": scene.meta.get("warnings", []), "objects_from": scene.meta.get("objects"),
                      "up": axis_name(scene.meta.get("up", [0, 0, 1])), "up_source": scene.meta.get("up_source")},
            "path": cfg.path or cfg.path_kind, "egl_device": device,
            "lp_num_threads": os.environ.get("LP_NUM_THREADS")}
