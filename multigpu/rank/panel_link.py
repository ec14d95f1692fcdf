"""Rank 0's side of the operator's page (``--panel``): the server started, and what the frame loop
hands it and takes from it once a frame.

It is a view for ``live.Live`` (``wants``/``thumbnail``: the shrunk wall, at most every
``server.PERIOD`` and only while a page is connected; ``poll``: a stop the page asked for),
the page's input for ``steer.Steering`` (``take``: the settings it changed, and the flying it did,
as a ``controls.Taken``), and where landed rows go (``landed``: the plots; the cameras of
``record``). Everything crosses to the server's thread through ``panel.state.PanelState``.
"""

from __future__ import annotations

import os
import secrets
import sys
import time

import numpy as np

from multigpu.core.navigate import Input
from multigpu.panel.protocol import Command
from multigpu.panel.server import PERIOD, PanelServer
from multigpu.panel.state import PanelState, plot_rows

#: where the launcher puts a token that outlives a restart of the wall (else each run makes its own)
TOKEN_ENV = "MULTIGPU_PANEL_TOKEN"
#: the setting fields of a Steering state the page may change, in their order there
SETTINGS = ("target_fps", "render_scale", "lod_error")


def legend(meta: dict, stops: int = 11) -> dict | None:
    """A simulation's colour bar for the page (``display.colorbar.legend_of``): the field, where it
    lives, the range, the map and its colours at ``stops`` even steps (#rrggbb), or None."""
    from multigpu.display.colorbar import legend_of

    got = legend_of(meta)
    if got is None:
        return None
    from multigpu.scene.simulation import lookup

    table = lookup(got["colormap"])
    picks = table[np.linspace(0, len(table) - 1, stops).round().astype(np.int64), :3]
    return {**got, "colors": ["#%02x%02x%02x" % tuple(int(v) for v in c) for c in picks]}


def header(cfg, title: str, balances, color_by: dict | None = None) -> dict:
    """The run's facts, as the page's table shows them (``color_by``: a simulation's colour bar,
    ``legend``, drawn beside the wall)."""
    W, H = cfg.canvas.size
    return {"title": title, **({"color_by": color_by} if color_by else {}), "scene": cfg.scene.model or cfg.scene.scene,
            "wall": f"{cfg.grid[0]}x{cfg.grid[1]} tiles of {cfg.tile[0]}x{cfg.tile[1]}",
            "wall_pixels": [W, H], "ranks": cfg.ranks, "decomposition": cfg.decomposition,
            "balance": cfg.balance, "strategies": list(balances), "latency": cfg.latency,
            "quality": {"target_fps": cfg.target_fps, "render_scale": cfg.render_scale, "lod_error": cfg.lod_error},
            "path": cfg.path or f"generated ({cfg.path_kind})", "present": cfg.present,
            "dark_tiles": list(cfg.dark)}


class PanelLink:
    """The page of one run, served from rank 0 (``open`` starts it and prints its URL)."""

    def __init__(self, state: PanelState, server: PanelServer, url: str, out_dir, interactive: bool,
                 viewer: bool = False, steps: int = 0):
        self.state, self.server, self.url = state, server, url
        self.steps, self.step = steps, (0, False)  # a series' steps, and the one shown (late or not)
        self.step_note: str | None = None  # a stream's state (``Stepping.note``: waited for, ended)
        self.out_dir, self.interactive, self.viewer = out_dir, interactive, viewer
        self.last_thumb = 0.0
        self.stop = False
        self.paused = False
        self.balance: str | None = None  # a strategy the page chose, not yet applied
        self.settings: dict = {}  # settings the page changed, not yet applied
        self._fly_clear()
        self.head = [0.0, 0.0, 0.0]  # metres the page moved the viewer's head since the last frame
        self.head_home = False
        self.scene: dict = {}  # a moving scene's time as the page set it: "pause" (bool), "time" (seconds)
        self.held: frozenset = frozenset()
        self.recording = None  # scene.pathfile.PathAppender while the page records
        self.recordings = 0
        self.cameras: list = []

    @classmethod
    def open(cls, cfg, title: str, balances, out_dir, events: list[str], color_by: dict | None = None,
             steps: int = 0) -> "PanelLink":
        """Start serving (raises OSError where the address cannot be listened on) and print the URL
        (``steps``: a series' steps, the page shows the one on the wall)."""
        address, port = cfg.panel
        token = os.environ.get(TOKEN_ENV) or secrets.token_urlsafe(24)
        state = PanelState(header(cfg, title, balances, color_by), tuple(balances), cfg.ranks, events)
        server = PanelServer(state, address, port, token)
        url = server.start()
        print(f"multigpu: the panel: {url}", flush=True)
        from multigpu.config import INTERACTIVE

        if steps:
            state.header["series_steps"] = steps
        return cls(state, server, url, out_dir, cfg.path == INTERACTIVE, cfg.viewer is not None, steps)

    # -- a view of the wall (live.Live)

    def wants(self) -> bool:
        """Whether a new thumbnail is due: a page is connected and the last one is ``PERIOD`` old."""
        return self.state.clients > 0 and time.perf_counter() - self.last_thumb >= PERIOD

    def thumbnail(self, img: np.ndarray, rects, shrink: int) -> None:
        self.last_thumb = time.perf_counter()
        self.state.set_thumb(img, rects, shrink)

    def poll(self) -> str | None:
        """Why the page wants the run to stop (``records.stops``), or None."""
        return "stop (the panel)" if self.stop else None

    # -- input (steer.Steering, rank 0)

    def _fly_clear(self) -> None:
        self.tapped: set = set()
        self.drag = [0.0, 0.0]
        self.speed = self.orbit = self.reset = 0

    def read(self) -> None:
        """The page's commands since the last frame, into what the next ``take`` hands over."""
        for cmd in self.state.take_commands():  # a handful a frame at most
            self._apply(cmd)

    def _apply(self, cmd: Command) -> None:
        do, args = cmd
        if do in ("pause", "resume", "stop"):
            self.paused = do == "pause"
            self.stop = self.stop or do == "stop"
            self.state.set_status(paused=self.paused, **({"state": "stopping"} if self.stop else {}))
        elif do == "balance":
            self.balance = args["name"]
        elif do in SETTINGS:
            self.settings[do] = args["value"]
        elif do == "keys":
            self.held = frozenset(args["held"])
            self.tapped |= self.held
        elif do == "drag":
            self.drag[0] += args["dx"]
            self.drag[1] += args["dy"]
        elif do == "speed":
            self.speed += args["steps"]
        elif do == "orbit":
            self.orbit += 1
        elif do == "reset":
            self.reset += 1
        elif do == "record":
            self._record(args["on"])
        elif do in ("scene_pause", "scene_play"):
            self.scene["pause"] = do == "scene_pause"
        elif do == "scene_time":
            self.scene["time"] = args["value"]
        elif do == "head_home":
            self.head, self.head_home = [0.0, 0.0, 0.0], True
        elif do == "head":
            for i, axis in enumerate(("dx", "dy", "dz")):
                self.head[i] += args[axis]

    def flight(self) -> Input:
        """The flying the page did since the last call (keys held or tapped, drags, speed, orbit,
        reset), as the navigator takes it."""
        got = Input(frozenset(self.held | self.tapped), (self.drag[0], self.drag[1]), False, self.speed,
                    self.orbit % 2 == 1, self.reset > 0)
        self._fly_clear()
        return got

    def head_moves(self) -> tuple[tuple, bool]:
        """The viewer's head as the page moved it since the last call: metres (room axes), and
        whether it went home first (as the window's K)."""
        got = (tuple(self.head), self.head_home)
        self.head, self.head_home = [0.0, 0.0, 0.0], False
        return got

    # -- records (rank 0's landed rows)

    def landed(self, f: int, rows: np.ndarray, col: dict, recorded) -> None:
        """Frame ``f``'s rows, every rank's as rank 0 records them (the swap skew on each): one plot
        row (``panel.state.names``); its camera while recording."""
        self.state.add_row(plot_rows(rows[None], col)[0])
        self.step = (int(rows[0, col["step"]]), bool(rows[0, col["step_late"]]))  # a series' step, if one plays
        if self.recording is not None and recorded is not None:
            cam, when, step = recorded
            self.cameras.append([*cam.position, *cam.target, *cam.up, cam.fov, cam.near, cam.far,
                                 float("nan") if when is None else when, float("nan") if step is None else step])
            if len(self.cameras) >= 100:
                self._flush()

    def status(self, control, balances, fidelity) -> None:
        """What the page shows of the run's state now."""
        self.state.set_status(paused=bool(self.paused), recording=self.recording is not None,
                              balance=balances[control.balance] if control is not None else None,
                              target_fps=fidelity.target_fps, render_scale=fidelity.scale,
                              lod_error=fidelity.lod_error, interactive=self.interactive,
                              viewer=self.viewer, scene_time=None if control is None else control.scene_time,
                              scene_paused=bool(control is not None and control.scene_paused),
                              **({"step": self.step[0], "step_late": self.step[1], "step_note": self.step_note}
                                 if self.steps else {}))

    def _record(self, on: bool) -> None:
        """Start (a new file in the run's outputs) or stop recording the cameras shown."""
        from multigpu.scene.pathfile import PathAppender

        if on and self.recording is None:
            self.recordings += 1
            path = self.out_dir / f"recorded-{self.recordings:02d}.json"
            while path.exists():  # a restarted run (--recover) keeps the recordings made before it
                self.recordings += 1
                path = self.out_dir / f"recorded-{self.recordings:02d}.json"
            self.recording = PathAppender(path)
            self.state.event(f"recording the camera to {path} (replay: --path {path})")
        elif not on and self.recording is not None:
            self._end_recording()

    def _flush(self) -> None:
        if self.cameras and self.recording is not None:
            try:
                self.recording.append(np.array(self.cameras, dtype=np.float64))
            except OSError as exc:
                print(f"multigpu: panel: the recording could not be written ({exc}); it stops", file=sys.stderr,
                      flush=True)
                self.state.event(f"the recording could not be written ({exc}); it stopped")
                self.recording = None
            self.cameras.clear()

    def _end_recording(self) -> None:
        self._flush()
        if self.recording is not None:
            frames = self.recording.frames
            self.recording.close()
            self.state.event(f"recorded {frames} frames")
            self.recording = None

    def finish(self, summary: dict | None) -> None:
        """The run ended: the summary to the page, the recording closed."""
        self._end_recording()
        if summary is not None:
            self.state.finish(summary)

    def close(self) -> None:
        """Stop serving, once a connected page had a moment to get the summary."""
        self._end_recording()
        self.server.close(linger=2.0 if self.state.summary is not None else 0.0)
