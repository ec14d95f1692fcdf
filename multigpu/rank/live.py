"""A window run's live side: input each frame, overlays on the tiles, the operator's monitor.

Around the frame loop of ``--present window``: the input phase (``steer.Steering``: rank 0's
keys and mouse, one broadcast), what a tile shows besides the picture (the partition tinted
and outlined when P is on; the statistics panel on rank 0's tile, top left of the wall, when I
is on), and ``--monitor``: every rank sends its tile shrunk ``scale`` times to rank 0, which
shows the whole wall with the partition over it in one more window. The monitor never holds up
the wall: the shrunk tiles go as non-blocking messages on a communicator of their own, and rank
0 shows frame f when frame f+1 is shown (by then they have arrived), so no rank waits for
another one's swap. The composed tile itself is never changed: mosaics, video and replays see
the picture only.
"""

from __future__ import annotations

import math
import time

import numpy as np

from multigpu.config import INTERACTIVE
from multigpu.core.navigate import Navigator
from multigpu.core.work import Work
from multigpu.display.hud import overlay, paste, stats_panel
from multigpu.rank.exchange import wait_all
from multigpu.rank.steer import Control, Steering
from multigpu.records.mosaic import stitch
from multigpu.records.report import COLUMNS

#: the monitor shows the wall shrunk by a whole factor to fit in this many pixels
MONITOR_FIT = (640, 480)


def monitor_scale(size) -> int:
    """The whole factor the monitor shrinks a ``size`` (W, H) wall by."""
    return max(1, math.ceil(max(size[0] / MONITOR_FIT[0], size[1] / MONITOR_FIT[1])))


def monitor_size(size, tiles: np.ndarray, tile_size) -> tuple[int, int]:
    """The monitor's pixels: every shrunk tile at its shrunk place."""
    s = monitor_scale(size)
    w, h = -(-tile_size[0] // s), -(-tile_size[1] // s)
    return int((tiles[:, 0] // s).max() + w), int((tiles[:, 1] // s).max() + h)


class Live:
    """The live side of one rank's window run. ``monitor`` and ``controls`` exist on rank 0
    only; ``start`` (rank 0, ``--path interactive``) is where the hand-flown camera begins."""

    def __init__(self, cfg, comm, scene, balances: list[str], balance: int, controls=None, monitor=None,
                 start=None, panel=None, clock=None):
        self.comm, self.cfg = comm, cfg
        self.rank, self.K = comm.Get_rank(), comm.Get_size()
        self.balances = balances
        navigator = None
        if start is not None:  # flown in path-file coordinates (before --offset): see steer.py
            off = np.asarray(cfg.offset, dtype=np.float64)
            lo, hi = scene.bounds
            navigator = Navigator(lo - off, hi - off, start)
        self.steering = Steering(comm, cfg.timeout, balances, balance, controls, navigator, cfg.offset,
                                 interactive=cfg.path == INTERACTIVE, panel=panel,
                                 quality=(cfg.target_fps, cfg.render_scale, cfg.lod_error), clock=clock)
        self.monitor, self.panel = monitor, panel
        self.tiles = cfg.canvas.tiles()
        # the shrunk wall travels to rank 0 for the monitor's window and the panel's thumbnail
        self.scale = monitor_scale(cfg.canvas.size) if cfg.monitor is not None or cfg.panel is not None else 0
        if self.scale:
            s = self.scale
            tw, th = cfg.tile
            self.small = np.zeros((-(-th // s), -(-tw // s), 3), dtype=np.uint8)
            self.small_tiles = np.zeros((self.K, *self.small.shape), dtype=np.uint8) if self.rank == 0 else None
            h, w = self.small.shape[:2]
            self.small_rects = np.stack([self.tiles[:, 0] // s, self.tiles[:, 1] // s,
                                         self.tiles[:, 0] // s + w, self.tiles[:, 1] // s + h], axis=1)
            self.monitor_size = monitor_size(cfg.canvas.size, self.tiles, cfg.tile)
            self.mcomm = comm.Dup()  # the monitor's messages never meet the frame exchange's
            self.pending: list = []  # this rank's requests of the last frame's tiles
            self.last_rects = None  # rank 0: the partition of the frame in flight
        self.fps, self.last = 0.0, None
        self.col = {c: i for i, c in enumerate(COLUMNS)}

    def control(self, frame: int = 0) -> Control:
        """The input phase: frame ``frame``'s camera and settings, the same on every rank."""
        control = self.steering.last_control = self.steering.next(frame)
        return control

    def steer(self, t, in_flight, log, planner, fidelity, frame: int = 0) -> Control:
        """The input phase of a frame (every rank the same camera and settings from here on): a
        pause left out of every time (this frame's ``t``, the frames ``in_flight``, the ``log``'s
        period), and the page's or the keys' strategy, quality and head applied to the
        ``planner`` and ``fidelity`` at this frame on every rank."""
        with t.phase("input"):
            control = self.control(frame)
        if control.paused_s:  # the page paused the run: no frame's time holds the pause
            t.paused(control.paused_s, "input")
            for x in in_flight:
                x.t.paused(control.paused_s)
            log.paused(control.paused_s)
        if control.balance != planner.using:
            planner.use(control.balance)
        if control.quality != fidelity.settings():
            fidelity.set(*control.quality)
        planner.head_offset = control.head  # the keys' move of the viewer's head
        return control

    def recorded(self):
        """Rank 0: the hand-flown camera of this frame in path-file coordinates (or None)."""
        return self.steering.recorded

    def _panel(self, control: Control, rows: np.ndarray) -> np.ndarray:
        get = lambda c: rows[:, self.col[c]]
        phases = np.stack([get("load_balancing_cpu_ms"), get("rendering_cpu_ms"), get("frame_exchange_cpu_ms")], 1)
        mode = ("orbit" if control.orbiting else "walk") if self.cfg.path == INTERACTIVE else "path"
        scale, lod = float(get("render_scale")[0]), float(get("lod_error_px")[0])
        quality = f"  x{scale:.2f} {lod:.1f}px" if 0 < scale < 1.0 or lod > 0 else ""  # render scale, LOD bound
        return stats_panel(self.fps, self.balances[control.balance], phases, get("triangles"), mode,
                           width=min(220, self.cfg.tile[0]), quality=quality, restarts=int(get("restarts")[0]))

    def tile(self, back: np.ndarray, work: Work, control: Control, rows: np.ndarray) -> np.ndarray:
        """What this rank's window shows: the composed tile, with the overlays that are on.
        ``rows`` are the last frame's gathered timing rows."""
        if self.rank == 0:
            now = time.perf_counter()
            if self.last is not None:  # frames per second, smoothed over the last few frames
                rate = 1.0 / max(now - self.last, 1e-6)
                self.fps = 0.8 * self.fps + 0.2 * rate if self.fps else rate
            self.last = now
        shown = back
        if control.partition:
            x0, y0 = int(self.tiles[self.rank][0]), int(self.tiles[self.rank][1])
            shown = overlay(back[::-1], work.rects, origin=(x0, y0))[::-1]
        if control.stats and self.rank == 0:
            shown = paste(shown, self._panel(control, rows))
        return shown

    def show_monitor(self, back: np.ndarray, work: Work, control: Control, rows: np.ndarray) -> str | None:
        """``--monitor``: every rank's shrunk tile to rank 0, which shows the wall with the
        partition over it; ``--panel``: the same, on the frames the page wants a thumbnail (the
        one before: the last gather's); rank 0 returns why the monitor or the page wants the run
        to stop, or None."""
        if not self.scale:
            return None
        thumb = control.thumb  # a page looks at rank 0's: a few frames a second, agreed by every rank
        if self.cfg.monitor is None and not thumb:
            return self.panel.poll() if self.panel is not None else None
        s = self.scale
        wait_all(self.pending, self.cfg.timeout, "monitor tiles")  # the last gather's: long arrived
        if self.rank != 0:
            np.copyto(self.small, back[::s, ::s])
            self.pending = [self.mcomm.Isend(self.small, dest=0, tag=1)]
            return None
        if self.last_rects is not None and (self.monitor is not None or thumb):  # the last frame, whole
            img = stitch(self.small_tiles, self.small_rects, self.monitor_size, self.cfg.canvas.dark)
            if thumb and self.panel is not None:
                self.panel.thumbnail(img, self.last_rects, s)
            if self.monitor is not None:
                shown = overlay(img, self.last_rects, scale=s)[::-1]
                if control.stats:
                    shown = paste(shown, self._panel(control, rows))
                self.monitor.present(shown)
        np.copyto(self.small_tiles[0], back[::s, ::s])
        self.pending = [self.mcomm.Irecv(self.small_tiles[k], source=k, tag=1) for k in range(1, self.K)]
        self.last_rects = work.rects
        why = self.monitor.poll() if self.monitor is not None else None
        if why:
            return f"{why} (the monitor)"
        return self.panel.poll() if self.panel is not None else None

    def landed(self, f: int, rows: np.ndarray, recorded, fidelity) -> None:
        """Rank 0: a frame's rows, every rank's as recorded, to the page (plots, status, a recording)."""
        if self.panel is not None:
            self.panel.landed(f, rows, self.col, recorded)
            self.panel.status(self.steering.last_control, self.balances, fidelity)

    def close(self, finished: bool) -> None:
        """Complete the monitor's last messages after a run every rank finished (nothing is
        left unreceived at the end); after a failure the job ends anyway."""
        if self.scale:
            if finished:  # (freeing is collective: not after a failure)
                wait_all(self.pending, self.cfg.timeout, "monitor tiles")
                self.mcomm.Free()
            self.pending = []
            self.scale = 0
