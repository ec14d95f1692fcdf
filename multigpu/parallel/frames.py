"""The frame loop of one rank: plan, render, sync, exchange, present, record, in named phases.

Built by ``walkthrough.run`` once setup has been agreed on every rank; every wait is bounded
(``--timeout``), a signal or a window event stops every rank after the same frame, and rank 0's
``RunRecord`` holds whole frames only.
"""

from __future__ import annotations

import itertools
import os

import numpy as np

from multigpu.config import INTERACTIVE, WalkConfig
from multigpu.core import jit
from multigpu.core.camera import Camera
from multigpu.core.culling import PartCuller
from multigpu.core.work import Work, transfers
from multigpu.errors import WriteFailed
from multigpu.parallel.backends import Exchange, Projection
from multigpu.parallel.composite import Messages
from multigpu.parallel.exchange import agree, barrier, broadcast_partition, wait_all
from multigpu.parallel.mosaic import stitch
from multigpu.parallel.outdir import OutputDir
from multigpu.parallel.projection import make_projection
from multigpu.parallel.record import RunRecord
from multigpu.parallel.report import BALANCE_NAMES, COLUMNS
from multigpu.parallel.shared import SharedPieces
from multigpu.parallel.timer import Timer
from multigpu.planner import Planner
from multigpu.scene.models import axis_name

#: the test-only fault to inject, read once: a lookup in ``os.environ`` (its miss is a KeyError
#: caught inside) costs ~10 us of CPU per frame with the caches cold, 4 % of a city frame's balancing
FAULT_SPEC = os.environ.get("MULTIGPU_FAULT")
#: the phases a frame's balancing is timed in, in order (their sum is the Load Balancing
#: column): learning from the last frame's measured times, projecting the object bounds,
#: planning the partition (the strategy and the decomposition)
BALANCE_PHASES = ("learn", "project", "plan")


def fault(rank: int, where: int | str) -> None:
    """Test-only fault injection: MULTIGPU_FAULT='RANK:WHERE[:stop]' (in the job's environment
    at start) with WHERE a frame number or 'setup' raises there, or with ':stop' stops the rank
    (SIGSTOP: a frozen rank; if something continues it, it carries on as if nothing happened)."""
    spec = FAULT_SPEC
    if spec:
        r, w, *action = spec.split(":")
        if int(r) == rank and w == str(where):
            if action == ["stop"]:
                import signal

                os.kill(os.getpid(), signal.SIGSTOP)
                return
            raise RuntimeError(f"injected fault at {'frame ' if isinstance(where, int) else ''}{where}")


#: the stop flag of a frame's row: > 0 a signal number, < 0 a window event (STOPS)
STOPS = {-1: "escape key", -2: "window closed", -3: "escape key (the monitor)", -4: "window closed (the monitor)",
         -5: "an output could not be written"}
STOP_FLAG = {why: flag for flag, why in STOPS.items()}


class Frames:
    """The frame loop in named phases: balance, render, sync, exchange, display, record."""

    def __init__(self, cfg: WalkConfig, comm, job, scene, path, renderer, presenter, out: OutputDir | None,
                 load_info, placement: list[dict], monitor=None):
        self.cfg, self.comm, self.job = cfg, comm, job
        self._beat_cpu = job.thread_cpu
        self.scene, self.path, self.renderer, self.presenter = scene, path, renderer, presenter
        self.rank, self.K = comm.Get_rank(), comm.Get_size()
        tw, th = cfg.tile
        self.canvas = cfg.canvas
        self.tiles = self.canvas.tiles()
        self.planner = Planner(cfg, scene, self.rank)  # MPI-free: projection, strategy, decomposition
        self.culler = PartCuller(scene) if renderer.draws.parts else None  # objects cut into parts
        self.drawn = 0  # triangles this rank drew in the last frame
        self.balance_ids = [BALANCE_NAMES.index(b) for b in self.planner.balances]  # the CSV's balance column
        self.relay = self._relay if cfg.partition == "broadcast" and self.K > 1 else None  # screen only (door)
        depth = self.planner.decomposition.depth
        self.back = np.zeros((th, tw, 3), dtype=np.uint8)  # composed tile
        self.zback = np.ones((th, tw), dtype=np.float32) if depth else None
        self.background = renderer.render(np.eye(4), np.eye(4), np.array([0.0, 0.0, 1.0]), (0, 0, 1, 1),
                                          np.zeros(scene.n_objects, dtype=bool))[0, 0]  # the clear colour
        self.col = {c: i for i, c in enumerate(COLUMNS)}
        self.row = np.zeros(len(COLUMNS) + 1)  # + stop flag
        self.allrows = np.zeros((self.K, len(COLUMNS) + 1))
        self.gathered = np.zeros((self.K, th, tw, 3), dtype=np.uint8) if self.rank == 0 else None
        self.interactive = cfg.path == INTERACTIVE
        self.n_frames = cfg.frames if self.interactive else len(path)  # None: until the user stops it
        self.done = 0
        self.learn = None  # (frame, times): observed at the start of the next frame
        # the exchange backend: a node-shared segment where asked for and possible, else messages
        shared, why = None, None
        if cfg.exchange != "messages":
            shared, why = SharedPieces.make(comm, self.canvas.size, depth, cfg.timeout, cfg.exchange == "shared")
        self.exchange: Exchange = shared or Messages(comm, cfg.timeout)
        # the bounds' projection: a slice per rank of a host into one shared array, where it can be
        self.projection: Projection
        self.projection, projection_why = make_projection(cfg, comm, self.planner, scene.n_objects)
        self.window = presenter.mode == "window"
        self.live = None
        if self.window:
            from multigpu.parallel.live import Live

            controls = start = None
            if self.rank == 0:  # rank 0's windows take the keyboard and mouse
                from multigpu.display import take_input

                controls = take_input(presenter, *([monitor.window] if monitor is not None else []))
                if self.interactive:
                    start = _unshifted(path.camera(0), cfg.offset)
            self.live = Live(cfg, comm, scene, self.planner.balances, self.planner.using, controls, monitor, start)
        doc = _config_doc(cfg, scene, load_info, self.n_frames, placement, renderer.method)
        doc["exchange"] = self.exchange.name
        if why:
            doc["exchange_why"] = f"messages: no shared segment ({why})"
        doc["projection"] = self.projection.name
        if projection_why:
            doc["projection_why"] = projection_why
        self.config_doc = doc
        self.record = None
        if self.rank == 0:
            self.record = RunRecord(out, self.K, self.n_frames, doc, self.planner.report, cfg.video,
                                    cfg.progress, cfg.overlay, cfg.record)

    def _relay(self, partition):
        """``--partition broadcast``: rank 0 computes the partition, every rank receives it."""
        part = partition() if self.rank == 0 else None
        return broadcast_partition(self.comm, part, self.K, self.scene.n_objects, self.cfg.timeout)

    # -- phases of one frame

    def render(self, t: Timer, work: Work, view, proj, light) -> list:
        """Every piece this rank renders: (rgb, depth or None). Of a scene cut into parts, the
        parts each piece needs are found first (the ``cull`` phase); ``drawn`` counts the
        triangles the pieces drew."""
        out, self.drawn, parts = [], 0, None
        if self.culler is not None:
            with t.phase("cull"):
                self.culler.frame(view, proj, self.canvas.size)
        for rect, mask in zip(work.rects[self.rank], work.masks[self.rank]):  # pieces, not objects
            if self.culler is not None:
                with t.phase("cull"):
                    parts = self.culler.seen(rect)
            with t.phase("render"):
                got = self.renderer.render(view, proj, light, rect, mask, depth=work.depth, seen=parts)
            self.drawn += self.renderer.last_triangles
            out.append(got if work.depth else (got, None))
        return out

    def compose(self, f: int, work: Work, rendered: list, plan: list) -> tuple[int, int]:
        """Frame exchange: the pieces travel to their tile owners, who copy or depth-merge them
        (the exchange backend: messages, or the node-shared segment). Returns (bytes sent, of
        which depth)."""
        if work.depth:
            self.back[:] = self.background
            self.zback[:] = 1.0
        return self.exchange.compose(f, self.rank, work.rects, rendered, plan, self.tiles[self.rank], self.back,
                                     self.zback if work.depth else None)

    def present(self, t: Timer, work: Work, control) -> tuple[float, int]:
        """Display: the composed tile (and the overlays that are on) into the back buffer, the
        swap barrier (every tile composed before any swaps), the swap; then window events and
        the operator's monitor. Returns when the swap returned and the stop flag of a window
        event (0: none)."""
        with t.phase("display"):
            shown = self.back if self.live is None else self.live.tile(self.back, work, control, self.allrows)
            self.presenter.show(shown)
        if self.window:
            with t.phase("swap_wait"):
                barrier(self.comm, self.cfg.timeout)
        with t.phase("display"):
            swapped = self.presenter.swap()
            why = self.presenter.poll()
            if self.live is not None:
                seen = self.live.show_monitor(self.back, work, control, self.allrows)
                if seen and not why:
                    return swapped, STOP_FLAG[f"{seen} (the monitor)"]
        return swapped, STOP_FLAG.get(why, 0)

    def gather_row(self, f: int, work: Work, t: Timer, sent: tuple[int, int], swapped: float, stop: int) -> None:
        """This rank's row by column name, gathered so every rank sees every rank's row."""
        box = work.bounds(self.rank)
        values = {"frame": f, "rank": self.rank, "triangles": self.drawn, "planned_triangles": work.loads[self.rank],
                  "x0": box[0], "y0": box[1], "x1": box[2], "y1": box[3],
                  "load_balancing_ms": t.ms(*BALANCE_PHASES), "rendering_ms": t.ms("cull", "render"),
                  "synchronization_ms": t.ms("sync"), "frame_exchange_ms": t.ms("exchange"),
                  "display_ms": t.ms("display", "swap_wait"), "frame_ms": t.total_ms,
                  "load_balancing_cpu_ms": t.cpu_ms(*BALANCE_PHASES), "rendering_cpu_ms": t.cpu_ms("cull", "render"),
                  "culling_cpu_ms": t.cpu_ms("cull"),
                  "learning_cpu_ms": t.cpu_ms("learn"), "projection_cpu_ms": t.cpu_ms("project"),
                  "planning_cpu_ms": t.cpu_ms("plan"),
                  "frame_exchange_cpu_ms": t.cpu_ms("exchange"), "display_cpu_ms": t.cpu_ms("display"),
                  "bytes_sent": sent[0], "objects": work.objects(self.rank), "pieces": len(work.rects[self.rank]),
                  "depth_bytes": sent[1], "load_cv": work.load_cv, "present_ms": t.ms("display"),
                  "swap_wait_ms": t.ms("swap_wait"), "swap_ms": swapped if self.window else 0.0,
                  "input_ms": t.ms("input"), "heartbeat_cpu_ms": self._heartbeat_cpu(),
                  "balance": self.balance_ids[self.planner.using]}
        for c, v in values.items():
            self.row[self.col[c]] = v
        # a signal or a window event seen here stops every rank after this frame
        failed = self.record is not None and self.record.failed is not None
        self.row[-1] = float(self.job.signum or stop or (STOP_FLAG[STOPS[-5]] if failed else 0))
        wait_all([self.comm.Iallgather(self.row, self.allrows)], self.cfg.timeout, "timing gather")

    def _heartbeat_cpu(self) -> float:
        """CPU ms of this rank's heartbeat thread since the last frame's row."""
        now = self.job.thread_cpu
        spent, self._beat_cpu = (now - self._beat_cpu) * 1e3, now
        return spent

    def show(self, f: int, work: Work) -> None:
        """Mosaic PNGs and video frames: every rank joins the gather on the same frames."""
        cfg = self.cfg
        last = self.n_frames is not None and f == self.n_frames - 1
        mosaic_due = bool(cfg.mosaic_every) and (f % cfg.mosaic_every == 0 or last)
        if not (mosaic_due or cfg.video):
            return
        wait_all([self.comm.Igather(self.back, self.gathered, root=0)], cfg.timeout, "mosaic gather")
        if self.rank == 0:
            self._write(self.record.image, f, stitch(self.gathered, self.tiles, self.canvas.size), work.rects,
                        mosaic_due)

    def _write(self, write, *args) -> None:
        """Rank 0's outputs: the first write that fails is kept (``record.failed``) and stops every
        rank after the next frame (its row's stop flag); nothing more is written after it, so
        what is on disk stays whole and the summary matches the CSV."""
        if self.record.failed is None:
            try:
                write(*args)
            except WriteFailed as exc:
                self.record.failed = exc

    def _camera(self, f: int, t: Timer):
        """The input phase of a window run (every rank the same camera and settings), then
        this frame's camera: the hand-flown one, or the path's."""
        control = None
        if self.live is not None:
            with t.phase("input"):
                control = self.live.control()
            if control.balance != self.planner.using:  # every rank switches at this frame
                self.planner.use(control.balance)
        camera = control.camera if control is not None and control.camera is not None else self.path.camera(f)
        return camera, control

    def frame(self, f: int) -> None:
        t = Timer()
        camera, control = self._camera(f, t)
        # balancing in three named phases (``BALANCE_PHASES``): learning from the last frame's times,
        # projecting the bounds, planning the partition
        with t.phase("learn"):
            if FAULT_SPEC:
                fault(self.rank, f)
            if self.learn is not None:  # the last frame's times, to what planned it
                self.planner.observe(*self.learn)
                self.learn = None
        view, proj, light, rects = self.projection.project(f, camera, t)  # the bounds' rects (project, sync)
        with t.phase("plan"):
            work = self.planner.work(f, rects, self.relay)
        rendered = self.render(t, work, view, proj, light)
        with t.phase("exchange"):  # parts for peers into the shared segment before the barrier (messages: nothing)
            plan = transfers(work, self.tiles)
            self.exchange.publish(f, self.rank, work.rects, rendered, plan)
        with t.phase("sync"):
            barrier(self.comm, self.cfg.timeout)
        with t.phase("exchange"):
            sent = self.compose(f, work, rendered, plan)
        swapped, stop = self.present(t, work, control)
        self.gather_row(f, work, t, sent, swapped, stop)
        self.learn = (f, self.allrows[:, self.col["rendering_cpu_ms"]].copy())
        if self.rank == 0:  # rows first: the summary always matches the CSV
            rows = self.allrows[:, :len(COLUMNS)].copy()
            if self.window:  # swap moments after the frame's first swap; the skew on every row
                at = rows[:, self.col["swap_ms"]].copy()
                rows[:, self.col["swap_ms"]] = (at - at.min()) * 1e3
                rows[:, self.col["swap_skew_ms"]] = (at.max() - at.min()) * 1e3
            if self.cfg.record:  # the camera first: a rewritten path file never lags the rows
                live = self.live.recorded() if self.live is not None and self.interactive else None
                self.record.camera(live if live is not None else _unshifted(camera, self.cfg.offset))
            self._write(self.record.rows, f, rows)
        self.done = f + 1
        self.show(f, work)

    def release(self, collective: bool) -> None:
        """Let the shared segment and the live state go; ``collective``: every rank finished the
        run and does so together (on a failure the job ends anyway, and a collective step would
        wait on ranks that are gone or still in the frame loop)."""
        if self.exchange is not None:
            self.exchange.close(collective)
            self.exchange = None
        if self.live is not None:
            self.live.close(collective)
        if self.projection is not None:
            self.projection.close(collective)
            self.projection = None

    def _what(self) -> str:
        cfg = self.cfg
        if cfg.decomposition == "screen":
            return f"balance={cfg.balance}"
        if cfg.decomposition == "bins":
            return f"bins {cfg.bin_pattern} {cfg.bin_size}px"
        return f"db ({cfg.db_ranges} ranges)"

    def _stopped_by(self) -> str | None:
        flags = self.allrows[:, -1]
        if self.job.signum:
            import signal

            return f"signal {signal.Signals(self.job.signum).name}"
        if (flags < 0).any():
            r = int(np.flatnonzero(flags < 0)[0])
            why = STOPS[int(flags[r])]
            if why == STOPS[-5]:
                return f"{why} (rank {r})"
            return why if why.endswith("(the monitor)") else f"{why} (rank {r}'s window)"
        return None

    def run(self) -> dict | None:
        complete, stopped_by = False, None
        self.job.in_frames = True
        try:
            for f in itertools.count() if self.n_frames is None else range(self.n_frames):
                self.frame(f)
                flags = self.allrows[:, -1]
                if flags.any():  # a rank was interrupted or its window closed: all stop after this frame
                    if (flags > 0).any():
                        self.job.signum = self.job.signum or int(flags.max())
                    break
            complete = self.done == self.n_frames
            if not complete:
                stopped_by = self._stopped_by()
        except BaseException as exc:
            stopped_by = f"{exc.__class__.__name__}: {exc}"
            raise
        finally:
            if self.rank == 0:
                summary = self.record.close(complete, stopped_by)
        # every rank learns whether rank 0's outputs were all written (a bounded agreement)
        failed = agree(self.comm, str(self.record.failed) if self.rank == 0 and self.record.failed else None,
                       self.cfg.timeout, "the end of the run")
        if failed and self.rank == 0:
            self.record.print_table(summary, self._title(complete, stopped_by))
        if failed:
            raise WriteFailed(failed)
        if self.rank != 0:
            return None
        self.record.print_table(summary, self._title(complete, stopped_by))
        return summary

    def _title(self, complete: bool, stopped_by: str | None) -> str:
        cfg, scene = self.cfg, self.scene
        planned = "" if self.n_frames is None else f" of {self.n_frames}"
        state = "" if complete else f" (stopped after {self.done}{planned} frames: {stopped_by})"
        W, H = self.canvas.size
        return (f"multigpu walkthrough: {scene.name}, {scene.n_triangles} triangles in {scene.n_objects} objects, "
                f"{cfg.grid[0]}x{cfg.grid[1]} wall of {W}x{H}, {self._what()}{state}")


def _config_doc(cfg, scene, load_info, n_frames, placement, renderer_method) -> dict:
    """The run's configuration for summary.json; ``placement``: every rank's host, index on
    its host (``node_rank``) and EGL device."""
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
            "path": cfg.path or cfg.path_kind, "egl_device": placement[0]["egl_device"], "present": cfg.present,
            "ranks": placement, "hosts": len({p["host"] for p in placement}),
            "mullion": list(cfg.mullion), "canvas": list(cfg.canvas.size), "wall": cfg.wall, "record": cfg.record,
            "monitor": cfg.monitor is not None,
            "lp_num_threads": os.environ.get("LP_NUM_THREADS"),
            "kernel": {"compiled": jit.available(),
                       "warm_seconds": round(load_info.get("kernel_seconds", 0.0), 3)}}


def _unshifted(camera: Camera, offset) -> Camera:
    """``camera`` in path-file coordinates (before ``--offset``)."""
    off = np.asarray(offset, dtype=np.float64)
    if not off.any():
        return camera
    return Camera(tuple(np.asarray(camera.position) - off), tuple(np.asarray(camera.target) - off), camera.up,
                  camera.fov, camera.near, camera.far)
