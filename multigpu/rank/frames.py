"""The frame loop of one rank: plan, render, sync, exchange, present, record, in named phases.

Built by ``walkthrough.run`` once setup has been agreed on every rank; every wait is bounded
(``--timeout``), a signal or a window event stops every rank after the same frame, and rank 0's
``RunRecord`` holds whole frames only.
"""

from __future__ import annotations

import itertools
from time import process_time

import numpy as np

from multigpu.config import INTERACTIVE, WalkConfig
from multigpu.core.camera import unshifted
from multigpu.core.inflight import read_lag, step
from multigpu.core.quality import Fidelity
from multigpu.core.resample import grown
from multigpu.core.work import transfers
from multigpu.display.colorbar import TileKey
from multigpu.errors import WriteFailed
from multigpu.rank.drawing import Drawing
from multigpu.rank.exchange import agree, broadcast_partition
from multigpu.rank.fault import FAULT_SPEC, fault
from multigpu.rank.flight import InFlight
from multigpu.rank.frame_setup import FrameSetup, planned_frames
from multigpu.rank.framelog import FrameLog
from multigpu.rank.moving import Moving
from multigpu.rank.rows import Rows
from multigpu.rank.series import replayed_step, series_stepping, swap_in
from multigpu.rank.showing import Showing
from multigpu.rank.timer import Timer
from multigpu.records.record import run_title
from multigpu.records.report import BALANCE_NAMES
from multigpu.records.stops import STOP_FLAG, STOPS, stopped_by_flags
from multigpu.scene.moves import motion_of


class Frames:
    """The frame loop in named phases: balance, render, sync, exchange, display, record. Built
    from its parts (``frame_setup.build``), it does no work until ``run``."""

    def __init__(self, cfg: WalkConfig, comm, job, scene, path, renderer, presenter, setup: FrameSetup):
        self.cfg, self.comm, self.job = cfg, comm, job
        self.scene, self.path, self.renderer, self.presenter = scene, path, renderer, presenter
        self.rank, self.K = comm.Get_rank(), comm.Get_size()
        self.planner, self.exchange, self.projection = setup.planner, setup.exchange, setup.projection
        # where ranks plan and render (one eye's canvas on a stereo wall) and where tiles are composed
        self.stereo, self.canvas = self.planner.stereo, self.planner.canvas
        composed = self.canvas if self.stereo is None else self.stereo.composed
        self.tiles = composed.tiles()
        tw, th = composed.tile
        self.live, self.record, self.background = setup.live, setup.record, setup.background
        if self.live is not None:  # a paused run still hears Ctrl-C and SIGTERM
            self.live.steering.stopping = lambda: job is not None and job.signum is not None
        self.head = setup.head  # the tracked head (--head-tracker), or None
        # speed for accuracy: each frame's render scale and levels of detail (core/quality.py)
        self.fidelity = Fidelity(scene, self.canvas.size[1], cfg.target_fps, cfg.render_scale, cfg.lod_error,
                                 lag=cfg.latency + 1)  # a frame's time is learnt about latency + 1 frames later
        self.balance_ids = [BALANCE_NAMES.index(b) for b in self.planner.balances]  # the CSV's balance column
        self.relay = self._relay if cfg.partition == "broadcast" and self.K > 1 else None  # screen only (door)
        self.back = np.zeros((th, tw, 3), dtype=np.uint8)  # composed tile
        self.key = TileKey.of(scene.meta, self.tiles[self.rank]) if cfg.scene.color_bar else None  # --color-bar
        self.zback = np.ones((th, tw), dtype=np.float32) if self.planner.depth else None
        self.latency, ahead = cfg.latency, read_lag(cfg.latency) > 0
        self.draw = Drawing(scene, renderer, self.planner, self.canvas, self.stereo, self.rank, ahead)
        motion = motion_of(scene, cfg.scene)  # a scene that moves: posed every frame (``rank/moving.py``)
        self.moving = None if motion is None else Moving(scene, motion, cfg.scene.anim_speed, self.planner,
                                                         self.projection, self.draw.culler, self.fidelity.chooser,
                                                         renderer, spheres=self.fidelity.chooser.levels > 1)
        self.stepping = series_stepping(scene, cfg.scene, self.rank, cfg.timeout, setup.spool, comm, setup.first)
        # rows land a step later in flight (no rank waits there); windows, in step at the swap lock, gather at once
        self.rows = Rows(comm, cfg.timeout, later=cfg.latency > 0 and presenter.mode != "window")
        self.col = self.rows.col
        self.interactive = cfg.path == INTERACTIVE
        self.n_frames = planned_frames(cfg, path)  # None: until the user stops it
        self.done = cfg.resume_at  # frames of the path shown (a resumed run's start after them)
        self.learn: list = []  # (frame, times) of landed rows: observed at the next submit
        self.stopping, self.stop_flags = False, None  # a landed row's stop flags, kept from the first
        self.window = presenter.mode == "window"
        self.showing = Showing(comm, presenter, self.stereo, self.live, self.window, cfg.timeout, setup.projector)
        self.flight: dict[int, InFlight] = {}  # the frames between their stages (``loop``)
        self.log = FrameLog(cfg, comm, job, self.record, self.col, self.n_frames, self.window,
                            self.exchange.links)

    def _relay(self, partition):
        """``--partition broadcast``: rank 0 computes the partition, every rank receives it."""
        part = partition() if self.rank == 0 else None
        return broadcast_partition(self.comm, part, self.K, self.scene.n_objects, self.cfg.timeout)

    # -- phases of one frame

    def submit(self, f: int) -> "InFlight":
        """A frame's first stage: input, balancing in three named phases (``BALANCE_PHASES``:
        learning from the landed rows' times, projecting the bounds, planning the partition) and
        the draw calls (``core/inflight.py``)."""
        t = Timer()
        self.rows.push()
        control = None if self.live is None else self.live.steer(  # a window run's input phase
            t, self.flight.values(), self.log, self.planner, self.fidelity, f)
        camera = control.camera if control is not None and control.camera is not None else self.path.camera(f)
        with t.phase("learn"):
            if FAULT_SPEC:
                fault(self.rank, f)
            for landed in self.learn:  # the times of frames that landed, to what planned them
                self.planner.observe(*landed)
            self.learn.clear()
        head_at = 0.0
        if self.head is not None:  # the newest pose, every rank the same from this frame
            with t.phase("input"):
                self.planner.pose, head_at = self.head.pose()
        when, step = None, ()
        if self.moving is not None:  # the bodies where they are at the frame's scene time (the operator's, if steered)
            steered = control is not None and control.scene_time is not None
            when = control.scene_time if steered else self.moving.time_of(f, self.path)
            self.moving.pose(t, when)
        if self.stepping is not None and self.stepping.live:  # a stream: rank 0's newest step, to every rank now
            with t.phase("sync"):
                self.stepping.hear()
        if self.stepping is not None:  # the series' step the frame's scene time wants, where every rank holds it
            steered = control is not None and control.scene_time is not None
            when = control.scene_time if steered else self.stepping.time_of(f, self.path)
            with t.phase("animate"):  # the scene's own work: a step swapped in
                swap = self.stepping.frame(when, replayed_step(self.path, f))
                if swap is not None:
                    self.scene = swap_in(self, *swap)
            step = (self.stepping.shown, self.stepping.want != self.stepping.shown)
            if self.rank == 0:
                self.stepping.say_note(None if self.live is None else self.live.panel)
        view, proj, light, rects = self.projection.project(f, camera, t)  # the bounds' rects (project, sync)
        with t.phase("choose"):  # the frame's quality: every rank the same from the same camera and rows
            quality, levels, tris = self.fidelity.frame(f, camera, rects, self.moving is not None or
                                                        self.stepping is not None)
        with t.phase("plan"):
            work = self.planner.work(f, rects, self.relay, None if levels is None else tris.copy())
            # the planner's arrays may be its own again by the time the frame is shown (frames in flight)
            work = work._replace(rects=tuple(r.copy() for r in work.rects))
            if work.depth and quality.scale != 1.0:  # sort-last pieces reach the pixels their scaled samples show
                front = work.front or (0,) * work.ranks  # a hybrid's regions stay
                work = work._replace(rects=tuple(grown(r, self.canvas.size, quality.scale, f)
                                                 for r, f in zip(work.rects, front)))
        eyes = None if self.planner.viewer is None else self.planner.views
        pending = self.draw.frame(t, work, eyes, (view, proj, light), rects, quality.scale, levels)
        with t.phase("exchange"):
            composed, picks = (work, None) if self.stereo is None else self.stereo.compose(work)
            plan = transfers(composed, self.tiles)
        recorded = None
        if (self.cfg.record or self.cfg.panel) and self.rank == 0:  # the frame's camera, in path-file coordinates
            live = self.live.recorded() if self.live is not None and self.interactive else None
            kept = live if live is not None else unshifted(camera, self.cfg.offset)
            recorded = (kept, when, step[0] if step else None)  # and a series' step shown (its replay's)
        return InFlight(f, t, control, work, plan, pending, self.draw.drawn, work.objects(self.rank),
                        self.balance_ids[self.planner.using], recorded, quality, composed, picks, head_at, step)

    def send(self, x: "InFlight") -> None:
        """A frame's second stage: its pixels read back (``readback``: waiting for the GL) and,
        with frames in flight, its parts on their way to their tiles' ranks."""
        with x.t.phase("readback"):
            x.rendered = x.pending.read() if x.picks is None else [p and p.read() for p in x.pending]
            x.pending = None
        with x.t.phase("exchange"):  # parts for peers out: into the shared segment, or as messages
            self.exchange.bits = self.cfg.compress_moving if x.quality.moving else 0  # lossy only while moving
            rects, rendered = x.composed.rects, x.rendered
            if x.picks is not None:  # each eye's pieces as the parts where they are composed (views)
                rendered = self.stereo.parts(x.picks[self.rank], rects[self.rank], rendered)
            x.started = self.exchange.start(x.f, self.rank, rects, rendered, x.plan, x.work.depth)

    def deliver(self, x: "InFlight") -> None:
        """A frame's last stage: the peers' parts (the ``sync`` wait), the tile composed and
        presented, the row posted (landing now, or a step later with frames in flight)."""
        t, work, depth = x.t, x.work, x.work.depth
        for landed in self.rows.land():  # the last frame's row first: kept even if a peer fails in this one
            self.landed(*landed)
        with t.phase("sync"):
            self.exchange.wait(x.started)
            if FAULT_SPEC:
                fault(self.rank, "compose")
        with t.phase("exchange"):
            if depth:
                self.back[:] = self.background
                self.zback[:] = 1.0
            sent = self.exchange.finish(x.started, self.tiles[self.rank], self.back, self.zback if depth else None)
        if self.key is not None:  # the colour bar's part on this tile, as the wall shows it
            self.key.stamp(self.back)
        x.rendered = x.started = None
        swapped, stop = self.showing.present(t, self.back, work, x.control, self.rows.allrows)
        if self.head is not None:
            self.head.shown(x.head_at)
        # a signal, a window event or a failed write seen here stops every rank after the same frame
        if self.stepping is not None and self.stepping.ended():  # --at-end stop: every rank after this frame
            stop = stop or STOP_FLAG[STOPS[-7]]
        values = self.log.row(x, sent, swapped)
        if self.stepping is not None:  # the step shown, the one held ready (every rank agrees on it once landed)
            values.update(self.stepping.row(*x.step))
        # the mosaic before the row: a frame whose row lands (the frames a restart resumes after) has its
        # mosaic; a peer lost in the gather leaves the row unposted and the frame to the restarted job
        self.log.show(x.f, work, self.back, self.showing.picture)
        for landed in self.rows.post(x.f, values, self.log.stop_flag(stop), x.recorded):
            self.landed(*landed)

    def landed(self, f: int, every: np.ndarray, recorded) -> None:
        """Every rank's row of frame ``f``: to the balancer's learning, and rank 0's records."""
        self.learn.append((f, every[:, self.col["rendering_cpu_ms"]].copy()))
        if self.stepping is not None:
            self.stepping.landed(every[:, self.col["step_ready"]])
        self.fidelity.landed(f, float(every[:, self.col["frame_ms"]].mean()))  # a frame-rate target learns
        rows = self.log.landed(f, every, recorded if self.cfg.record else None)  # rank 0's records
        if self.live is not None and rows is not None:  # the page's plots (and its recording)
            self.live.landed(f, rows, recorded, self.fidelity)
        self.done = f + 1
        if every[:, -1].any():
            self.stopping = True

    def loop(self) -> None:
        """Every frame through its three stages (``core/inflight.py``). A stop flag in a landed
        row (a rank interrupted, a window closed, a write failed) ends the run on every rank
        after the same frame: the last one submitted, once it is shown."""
        flight = self.flight
        last = None if self.n_frames is None else self.n_frames - 1
        for k in itertools.count(self.cfg.resume_at):
            stages = step(k, last, self.latency, self.cfg.resume_at)
            if stages is None:
                return
            submit, send, deliver = stages
            if submit is not None:
                flight[submit] = self.submit(submit)
            if send is not None:
                self.send(flight[send])
            if deliver is not None:
                self.deliver(flight.pop(deliver))
            if self.stopping and self.stop_flags is None:
                self.stop_flags = flags = self.rows.allrows[:, -1].copy()
                if (flags > 0).any():
                    self.job.signum = self.job.signum or int(flags.max())
                last = k if last is None else min(last, k)

    def _keep_shown(self) -> None:
        """On a failure with frames in flight: the row of the last frame every rank showed, where
        every rank posted it (a moment at most; a peer that never did leaves it out)."""
        try:
            for landed in self.rows.land(min(self.cfg.timeout, 2.0)):
                self.landed(*landed)
        except Exception:  # the failure itself is what the run reports
            self.rows.posted = None

    def run(self) -> dict | None:
        complete, stopped_by = False, None
        self.job.in_frames = True
        panel = self.live.panel if self.live is not None else None
        began, shown, served = process_time(), self.done, panel.server.cpu_s() if panel is not None else 0.0
        try:
            self.loop()
            for landed in self.rows.land():  # frames in flight: the last frame's row
                self.landed(*landed)
            complete = self.done == self.n_frames and self.stop_flags is None
            if not complete:
                stopped_by = stopped_by_flags(self.job.signum, self.stop_flags, self.K)
            # every rank's spans (collective: here, where every rank is); before the ranks agree on
            # rank 0's writes below, so a timeline that cannot be written is the run's failure
            self.log.write_timeline(self.latency)
        except BaseException as exc:
            stopped_by = f"{exc.__class__.__name__}: {exc}"
            self._keep_shown()
            raise
        finally:
            if self.stepping is not None:
                self.stepping.close()
            if self.rank == 0:
                summary = self.log.close(complete, stopped_by, (process_time() - began, self.done - shown),
                                         self.head, panel, served)
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
        planned = "" if self.n_frames is None else f" of {self.n_frames}"
        state = "" if complete else f" (stopped after {self.done}{planned} frames: {stopped_by})"
        return run_title(self.cfg, self.scene) + state
