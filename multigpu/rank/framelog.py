"""What a frame leaves behind, apart from the frame loop: the rank's timing row, the stop flag it
carries, rank 0's records of the landed rows, the mosaics, and the timeline.

The row is built by column name from the frame's timer (``row``: the columns are
``report.COLUMNS``; the phases that make each come from ``PHASE_COLUMNS``). The stop flag
(``stop_flag``) says why every rank stops after this frame: a signal, a window event, a write that
failed on rank 0. Rank 0 writes what every rank's rows say once they have landed (``record``:
the swap moments relative to the first, the recorded camera first, then the rows) and the mosaics
every rank gathers (``show``); a write that fails is kept (``write``) and stops the run after the
next frame, nothing more written after it. ``--timeline`` keeps the last frames' phase spans.
"""

from __future__ import annotations

import json
from collections import deque

import numpy as np

from multigpu.core import wire
from multigpu.core.stereo import make_stereo
from multigpu.errors import WriteFailed
from multigpu.rank.composite import decoded
from multigpu.rank.exchange import allgather_text, wait_all
from multigpu.records.mosaic import stitch
from multigpu.records.recovery import restarts
from multigpu.records.report import COLUMNS
from multigpu.records.stops import STOP_FLAG, STOPS

#: the phases a frame's balancing is timed in, in order (their sum is the Load Balancing
#: column): learning from the last frame's measured times, projecting the object bounds,
#: choosing the frame's quality (render scale, levels of detail), planning the partition
BALANCE_PHASES = ("learn", "pose", "project", "choose", "plan")
#: the phases of the Rendering column: the parts culled, the draw calls, the pixels read back
RENDER_PHASES = ("animate", "cull", "render", "readback")
#: the mosaic gather's messages (the frame exchange's are ``composite.TAG``)
MOSAIC_TAG = 10
#: the frames ``--timeline`` keeps: the run's last ones
TIMELINE_FRAMES = 8


class FrameLog:
    """One rank's log of its frames; ``record`` (rank 0's ``RunRecord``, else None) is where
    rows, mosaics and the timeline go."""

    def __init__(self, cfg, comm, job, record, col: dict, n_frames: int | None, window: bool,
                 links: dict | None = None):
        self.cfg, self.comm, self.job, self.record, self.col = cfg, comm, job, record, col
        self.links = links or {}  # the codec of each rank whose messages with this one travel compressed
        self.rank, self.K = comm.Get_rank(), comm.Get_size()
        self.n_frames, self.window = n_frames, window
        self.canvas = cfg.canvas
        self.tiles = self.canvas.tiles()
        # a stereo wall gathers composed tiles (both eyes; with a rank for each eye, each eye's)
        self.stereo = make_stereo(cfg.stereo, self.canvas, cfg.eyes == "own")
        tw, th = cfg.tile if self.stereo is None else self.stereo.composed.tile
        self.gathered = np.zeros((self.K, th, tw, 3), dtype=np.uint8) if self.rank == 0 else None
        self.outputs = None  # a projector wall's outputs by tile (``Projected``): rank 0 keeps their pictures
        if cfg.mpcdi is not None and self.rank == 0:
            from multigpu.warp.layout import eye_outputs, picture_size

            self.outputs = eye_outputs(cfg.mpcdi, cfg.grid, cfg.mpcdi_right)
            self.picture_sizes = [picture_size(self.outputs, k) for k in range(self.K)]
        self.shown_at = None  # when this rank's last frame was shown (perf_counter): the frame period
        self._beat_cpu = job.thread_cpu
        self.timeline = deque(maxlen=TIMELINE_FRAMES) if cfg.timeline else None  # (frame, phase spans)

    def paused(self, seconds: float) -> None:
        """The run stood paused ``seconds``: the next frame's period leaves them out."""
        if self.shown_at is not None:
            self.shown_at += seconds

    def row(self, x, sent, swapped: float) -> dict:
        """This rank's row of frame ``x`` (``flight.InFlight``) by column name."""
        t, work = x.t, x.work
        box = work.bounds(self.rank)
        now = t.end
        period = t.total_ms if self.shown_at is None else (now - self.shown_at) * 1e3
        self.shown_at = now
        if self.timeline is not None:
            self.timeline.append((x.f, t.spans))
        return {"frame": x.f, "rank": self.rank, "triangles": x.drawn, "planned_triangles": work.loads[self.rank],
                "x0": box[0], "y0": box[1], "x1": box[2], "y1": box[3],
                "load_balancing_ms": t.ms(*BALANCE_PHASES), "rendering_ms": t.ms(*RENDER_PHASES),
                "synchronization_ms": t.ms("sync"), "frame_exchange_ms": t.ms("exchange"),
                "display_ms": t.ms("display", "swap_wait"), "frame_ms": period, "latency_ms": t.total_ms,
                "load_balancing_cpu_ms": t.cpu_ms(*BALANCE_PHASES), "rendering_cpu_ms": t.cpu_ms(*RENDER_PHASES),
                "culling_cpu_ms": t.cpu_ms("cull"),
                "learning_cpu_ms": t.cpu_ms("learn"), "projection_cpu_ms": t.cpu_ms("project"),
                "posing_cpu_ms": t.cpu_ms("pose"), "animating_cpu_ms": t.cpu_ms("animate"),
                "planning_cpu_ms": t.cpu_ms("plan"),
                "frame_exchange_cpu_ms": t.cpu_ms("exchange"), "display_cpu_ms": t.cpu_ms("display"),
                "bytes_sent": sent.bytes, "objects": x.objects, "pieces": len(work.rects[self.rank]),
                "depth_bytes": sent.depth, "load_cv": work.load_cv, "present_ms": t.ms("display"),
                "swap_wait_ms": t.ms("swap_wait"), "swap_ms": swapped if self.window else 0.0,
                "input_ms": t.ms("input"), "heartbeat_cpu_ms": self._heartbeat_cpu(),
                "render_scale": x.quality.scale, "lod_error_px": x.quality.lod_px,
                "choosing_cpu_ms": t.cpu_ms("choose"), "balance": x.balance,
                "load_balancing_waited_ms": t.waited_ms(*BALANCE_PHASES),  # the span of load_balancing_ms
                "rendering_waited_ms": t.waited_ms(*RENDER_PHASES), "synchronization_waited_ms": t.waited_ms("sync"),
                "frame_exchange_waited_ms": t.waited_ms("exchange"),
                "display_waited_ms": t.waited_ms("display", "swap_wait"), "restarts": restarts(),
                "wire_bytes": sent.wire, "compress_cpu_ms": sent.compress_ms, "decompress_cpu_ms": sent.decompress_ms,
                "lossy_bits": sent.bits}

    def _heartbeat_cpu(self) -> float:
        """CPU ms of this rank's heartbeat thread since the last frame's row."""
        spent, self._beat_cpu = (self.job.thread_cpu - self._beat_cpu) * 1e3, self.job.thread_cpu
        return spent

    def stop_flag(self, window_event: int) -> float:
        """The stop flag this rank's row carries: a signal it got, a window event (its
        ``STOP_FLAG``), a write that failed on rank 0; 0: go on."""
        failed = self.record is not None and self.record.failed is not None
        return float(self.job.signum or window_event or (STOP_FLAG[STOPS[-5]] if failed else 0))

    def landed(self, f: int, every: np.ndarray, recorded) -> np.ndarray | None:
        """Rank 0: every rank's landed row of frame ``f`` into the records (rows first: the
        summary always matches the CSV; the camera before them: the path file never lags); the
        rows as recorded (the swap skew on each), None on other ranks."""
        if self.rank != 0:
            return None
        rows = every[:, :len(COLUMNS)].copy()
        if self.window:  # swap moments after the frame's first swap; the skew on every row
            at = rows[:, self.col["swap_ms"]].copy()
            rows[:, self.col["swap_ms"]] = (at - at.min()) * 1e3
            rows[:, self.col["swap_skew_ms"]] = (at.max() - at.min()) * 1e3
        if recorded is not None:
            self.record.camera(*recorded)
        self.write(self.record.rows, f, rows)
        return rows

    def show(self, f: int, work, back: np.ndarray, picture: np.ndarray | None = None) -> None:
        """Mosaic PNGs and video frames: every rank joins the gather on the same frames (and
        that of its projector output's ``picture``, on a projector wall)."""
        cfg = self.cfg
        last = self.n_frames is not None and f == self.n_frames - 1
        mosaic_due = bool(cfg.mosaic_every) and (f % cfg.mosaic_every == 0 or last)
        if not (mosaic_due or cfg.video):
            return
        self._gather(f, back)
        pictures = None if picture is None or not mosaic_due else self._pictures(picture)
        if self.rank != 0:
            return
        st = self.stereo
        if st is None:
            self.write(self.record.image, f, stitch(self.gathered, self.tiles, self.canvas.size, self.canvas.dark),
                       work.rects, mosaic_due, None, pictures)
            return
        # the wall as its displays show it, and each eye's own mosaic (the partition over the left eye's)
        ew, K = st.eye_tile[0], self.canvas.grid[0] * self.canvas.grid[1]
        if st.own:  # a rank for each eye of each tile: the left eyes' tiles, then the right eyes'
            eyes = [stitch(self.gathered[e * K:(e + 1) * K], st.eye.tiles(), st.eye.size, self.canvas.dark)
                    for e in range(2)]  # eyes
        else:
            eyes = [stitch(self.gathered[:, :, e * ew:(e + 1) * ew], st.eye.tiles(), st.eye.size, self.canvas.dark)
                    for e in range(2)]  # eyes
        # a passive wall's outputs: the left eyes' beside the right eyes', as one X screen spanning both shows them
        wall = (np.concatenate(eyes, axis=1) if st.outputs == 2 else
                stitch(np.stack([st.pack(g) for g in self.gathered]), self.tiles, self.canvas.size, self.canvas.dark))
        self.write(self.record.image, f, wall, work.rects, mosaic_due, eyes, pictures)

    def _gather(self, f: int, back: np.ndarray) -> None:
        """Every rank's composed tile into rank 0's ``gathered``: one message each, compressed from
        ranks on other PCs as the frame's pieces are (``core/wire.py``); a tile that does not
        decode ends the job (``CorruptPiece``)."""
        if self.rank != 0:
            msg = wire.encode(back.reshape(-1).copy(), self.links[0]) if 0 in self.links else back
            wait_all([self.comm.Isend(msg, dest=0, tag=MOSAIC_TAG)], self.cfg.timeout, "mosaic gather")
            return
        self.gathered[0] = back
        boxes = {k: np.empty(wire.bound(back.nbytes), np.uint8) if k in self.links else self.gathered[k]
                 for k in range(1, self.K)}
        statuses: list = []
        wait_all([self.comm.Irecv(b, source=k, tag=MOSAIC_TAG) for k, b in boxes.items()], self.cfg.timeout,
                 "mosaic gather", statuses=statuses)
        for k in self.links:  # boxes hold ranks 1.. in order: rank k's status is statuses[k - 1]
            packed, _, _ = decoded(boxes[k], back.nbytes, f"rank 0: frame {f}: the tile of rank {k}",
                                   statuses[k - 1].Get_count())
            self.gathered[k].reshape(-1)[:] = packed

    def _pictures(self, picture: np.ndarray) -> list | None:
        """Every projector output's picture at rank 0, (name, image top row first) by tile: each
        rank's picture (its outputs side by side) one message (raw: mosaic frames only)."""
        if self.rank != 0:
            wait_all([self.comm.Isend(np.ascontiguousarray(picture), dest=0, tag=MOSAIC_TAG + 1)], self.cfg.timeout,
                     "mosaic gather")
            return None
        boxes = [np.empty((h, w, 3), dtype=np.uint8) for w, h in self.picture_sizes[1:]]
        wait_all([self.comm.Irecv(b, source=k, tag=MOSAIC_TAG + 1) for k, b in enumerate(boxes, 1)], self.cfg.timeout,
                 "mosaic gather")
        tops = [img[::-1] for img in (picture, *boxes)]
        return [(o.name, tops[o.tile][o.at[1]:o.at[1] + o.size[1], o.at[0]:o.at[0] + o.size[0]]) for o in self.outputs]

    def close(self, complete: bool, stopped_by: str | None, loop: tuple[float, int], head, panel,
              served: float) -> dict:
        """Rank 0: the run's record closed, its summary (``records.record.RunRecord.close``) with
        rank 0's costs per frame of the loop (``loop``: its CPU seconds, all threads, and frames):
        the whole process, the tracked ``head``'s poses and their motion to photon, the ``panel``'s
        server thread on its own clock (``served``: its CPU seconds before the loop)."""
        frames = max(loop[1], 1)
        self.record.extra["rank0_process_cpu_ms"] = loop[0] * 1e3 / frames
        if head is not None:
            self.record.extra.update(head.report())
        if panel is not None:
            self.record.extra["panel_server_cpu_ms"] = (panel.server.cpu_s() - served) * 1e3 / frames
        return self.record.close(complete, stopped_by)

    def write(self, write, *args) -> None:
        """Rank 0's outputs: the first write that fails is kept (``record.failed``) and stops every
        rank after the next frame (its row's stop flag); nothing more is written after it, so
        what is on disk stays whole and the summary matches the CSV."""
        if self.record.failed is None:
            try:
                write(*args)
            except WriteFailed as exc:
                self.record.failed = exc

    def write_timeline(self, latency: int) -> None:
        """``timeline.json`` (``--timeline``): every rank's phase spans of the last frames."""
        if self.timeline is None:
            return
        mine = json.dumps([[f, [[n, a, b] for n, a, b in spans]] for f, spans in self.timeline])
        every = allgather_text(self.comm, mine, self.cfg.timeout, "timeline", nbytes=1 << 18)
        if self.rank == 0:
            self.write(self.record.timeline, [json.loads(e) if e else [] for e in every], latency)
