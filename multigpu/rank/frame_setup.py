"""What the frame loop is built from, made before it: the planner, the exchange backend, the
bounds' projection, window input, rank 0's run record and the clear colour.

Here are the collective MPI calls (the shared segments are agreed on by every rank) and the one GL
render that learns the clear colour; ``Frames`` is then built from these parts alone, so its
constructor does no work and takes a stand-in communicator (tests/threadcomm.py). ``release``
lets the parts go when the run ends, however it ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multigpu.config import INTERACTIVE, WalkConfig
from multigpu.core import wire
from multigpu.core.camera import unshifted
from multigpu.core.inflight import slots
from multigpu.planner import Planner
from multigpu.rank.backends import Exchange, Projection
from multigpu.rank.composite import Messages
from multigpu.rank.projection import make_projection
from multigpu.rank.shared import SharedPieces
from multigpu.records.outdir import OutputDir
from multigpu.records.record import RunRecord, config_doc


def planned_frames(cfg: WalkConfig, path) -> int | None:
    """The frames the run shows: the path's, or ``--frames`` of a flight (None: until stopped)."""
    return cfg.frames if cfg.path == INTERACTIVE else len(path)


@dataclass(slots=True)
class FrameSetup:
    """The frame loop's parts. ``record`` and ``live`` are None where there is none (``record``:
    rank 0 only; ``live``: window and panel runs only); ``doc`` is the run's configuration as
    summary.json has it."""

    planner: Planner
    exchange: Exchange
    projection: Projection | None  # None only while ``build`` makes it
    background: np.ndarray  # the clear colour (3,) uint8: a depth-composed tile starts from it
    doc: dict
    record: RunRecord | None = None
    live: object = None  # parallel.live.Live
    head: object = None  # rank.head_link.HeadLink: the tracked head (--head-tracker)
    spool: object = None  # rank 0 of a stream's run: its reader (``rank/spool.py``)
    first: object = None  # a stream's first step as rank 0 sent it (this PC cannot read its file), else None
    projector: object = None  # a projector wall's output of this rank (``rank/outputs.py``)

    def release(self, collective: bool) -> None:
        """Let the shared segments and the live state go; ``collective``: every rank finished the
        run and does so together (on a failure the job ends anyway, and a collective step would
        wait on ranks that are gone or still in the frame loop)."""
        for part in (self.exchange, self.live, self.projection, self.head):
            if part is not None:
                part.close(collective)
        if self.spool is not None:
            self.spool.close()
        if self.projector is not None:
            self.projector.release()
        self.exchange = self.live = self.projection = self.head = self.spool = self.projector = None


def clear_colour(renderer, n_objects: int) -> np.ndarray:
    """The renderer's background: one pixel drawn with nothing in it."""
    return renderer.render(np.eye(4), np.eye(4), np.array([0.0, 0.0, 1.0]), (0, 0, 1, 1),
                           np.zeros(n_objects, dtype=bool))[0, 0]


def make_exchange(cfg: WalkConfig, comm, planner: Planner, hosts: list[str]) -> tuple[Exchange, str | None]:
    """The exchange backend: a node-shared segment where asked for and possible, else messages
    (and why not the segment), its messages compressed on the links ``--compress`` chooses
    (``hosts``: every rank's). Every rank the same (collective)."""
    shared, why = None, None
    if cfg.exchange != "messages":  # room for every decomposition the operator may switch to
        composed = cfg.canvas if planner.stereo is None else planner.stereo.composed  # where tiles are composed
        shared, why = SharedPieces.make(comm, composed.size, planner.depth, cfg.timeout, cfg.exchange == "shared",
                                        slots=slots(cfg.latency), layers=planner.layers)
    exchange = shared or Messages(comm, cfg.timeout, sync=cfg.latency == 0)
    exchange.links = wire.links(cfg.compress, hosts, comm.Get_rank())
    return exchange, why


def _live(cfg: WalkConfig, comm, scene, path, planner: Planner, presenter, monitor, panel):
    """A window run's input and statistics, or a panel's: rank 0's windows take the keyboard and
    mouse, its page (``--panel``) the operator's actions."""
    from multigpu.rank.live import Live

    controls = start = None
    if comm.Get_rank() == 0:
        if presenter.mode == "window":
            from multigpu.display import take_input

            controls = take_input(presenter, *([monitor.window] if monitor is not None else []))
        if cfg.path == INTERACTIVE:
            start = unshifted(path.camera(0), cfg.offset)
    from multigpu.core.motion import SceneClock
    from multigpu.scene.moves import moves

    steered = moves(scene, cfg.scene) or "series" in scene.meta  # the operator may steer its time
    clock = SceneClock(cfg.scene.anim_speed) if steered else None
    return Live(cfg, comm, scene, planner.balances, planner.using, controls, monitor, start, panel, clock)


def build(cfg: WalkConfig, comm, scene, path, renderer, presenter, out: OutputDir | None, load_info: dict,
          placement: list[dict], monitor=None, panel=None, tracker=None) -> FrameSetup:
    """Every part of the frame loop for this rank (collective: every rank calls it)."""
    rank = comm.Get_rank()
    planner = Planner(cfg, scene, rank)  # MPI-free: projection, strategy, decomposition
    hosts = [p["host"] for p in placement]
    exchange, why = make_exchange(cfg, comm, planner, hosts)
    setup = FrameSetup(planner, exchange, None, np.zeros(3, dtype=np.uint8), {})
    try:  # from here on, whatever fails lets go of what was made (the exchange's segments first)
        setup.projection, projection_why = make_projection(cfg, comm, planner, scene.n_objects)
        n_frames = planned_frames(cfg, path)
        doc = setup.doc = config_doc(cfg, scene, load_info, n_frames, placement, renderer.method)
        doc["exchange"] = exchange.name
        doc["compress"] = wire.describe(cfg.compress, hosts)
        if cfg.compress_moving and not doc["compress"].startswith("none"):  # bits drop on compressed links only
            doc["compress"] += f", {cfg.compress_moving} colour bits dropped while moving"
        elif cfg.compress_moving:
            doc["compress"] += " (--compress-moving has no compressed link to drop bits on: every frame exact)"
        if why:
            doc["exchange_why"] = f"messages: no shared segment ({why})"
        doc["projection"] = setup.projection.name
        if projection_why:
            doc["projection_why"] = projection_why
        setup.background = clear_colour(renderer, scene.n_objects)
        if cfg.head_tracker is not None:  # every rank takes rank 0's pose (``tracker``: its socket)
            from multigpu.rank.head_link import HeadLink

            setup.head = HeadLink(comm, tracker, planner.viewer, cfg.timeout)
        if presenter.mode == "window" or cfg.panel is not None:
            setup.live = _live(cfg, comm, scene, path, planner, presenter, monitor, panel)
        if rank == 0:
            setup.record = RunRecord(out, comm.Get_size(), n_frames, doc, planner.report, cfg.video, cfg.progress,
                                     cfg.overlay, cfg.record, cfg.resume_at)
            setup.record.legend(scene.meta)  # a simulation's colour bar, on the annotated mosaics
        if cfg.mpcdi is not None:  # a projector wall: this rank's outputs, their picture made every frame
            from multigpu.rank.outputs import Projector

            K = cfg.ranks  # a stereo projector wall's ranks K.. drive the right eyes' projectors (``--eyes own``)
            setup.projector = Projector(renderer.ctx, cfg.mpcdi if rank < K else cfg.mpcdi_right, rank % K, cfg.grid,
                                        cfg.tile, cfg.output_colors, cfg.blend == "on")
    except BaseException:
        setup.release(collective=False)
        raise
    return setup
