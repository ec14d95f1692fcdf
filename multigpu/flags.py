"""The flags of the scene and walkthrough commands, and the validated configuration built
from them (``walk_config``): argparse in, dataclasses out, no MPI (testable in one process)."""

from __future__ import annotations

import argparse
import re

from multigpu.errors import InputError


def defaults(cls) -> dict:
    """A configuration dataclass's field defaults: the one place every default lives."""
    import dataclasses

    return {f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}


def scene_args(p: argparse.ArgumentParser) -> None:
    from multigpu.scene.models import BUILTIN, SceneSpec

    d = defaults(SceneSpec)
    g = p.add_argument_group("scene")
    g.add_argument("--scene", default=d["scene"], metavar="|".join(BUILTIN), help="a built-in scene")
    g.add_argument("--model", metavar="FILE", help="model file (OBJ, PLY, STL, OFF, glTF/GLB) instead of --scene")
    g.add_argument("--split", default=d["split"], metavar="auto|components|grid:N",
                   help="objects of a model: scene-graph nodes (else connected components), connected components, "
                        "or an N^3 grid of cells (any file)")
    g.add_argument("--merge-below", type=int, default=d["merge_below"], metavar="N",
                   help="merge components under this many triangles")
    g.add_argument("--triangles", type=int, default=d["triangles"], metavar="N",
                   help="built-in scene size in triangles")
    g.add_argument("--copies", type=int, default=d["copies"], metavar="N",
                   help="built-in scenes side by side (the paper used 6..20 plants)")
    g.add_argument("--seed", type=int, default=d["seed"], metavar="N", help="built-in scenes: the random seed")
    g.add_argument("--cluster", default="auto", metavar="auto|N|0",
                   help="cut objects above N triangles into spatial clusters of at most N (auto: when an object is "
                        "too big to balance on the wall; 0: keep objects as modelled)")
    g.add_argument("--up", default=d["up"], metavar="x|y|z|-x|-y|-z",
                   help="up axis of the model (default: the format's convention, see scene info)")


def _cluster(text: str) -> int | None:
    if str(text).strip() == "auto":
        return None
    try:
        return int(text)
    except ValueError:
        raise InputError(f"--cluster must be 'auto' or a number of triangles (0: never), got '{text}'") from None


def _ranks(a) -> int:
    from multigpu.config import parse_pair

    rows, cols = parse_pair(getattr(a, "grid", None) or "2x2", "--grid")
    return rows * cols


def spec(a, **override):
    from multigpu.scene.models import SceneSpec

    fields = dict(scene=a.scene, model=a.model, split=a.split, merge_below=a.merge_below, triangles=a.triangles,
                  copies=a.copies, seed=a.seed, cluster=_cluster(a.cluster), up=a.up, ranks=_ranks(a))
    return SceneSpec(**{**fields, **override})


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Help with every flag's default shown (where it has one and its text does not already say
    it) and the epilog's examples kept as written."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        shown = "%(default)" in text or "default" in text.lower()
        empty = action.default is None or action.default is False or action.default is argparse.SUPPRESS
        if not shown and action.option_strings and not empty:
            text += " (default: %(default)s)"
        return text


def _one_of(names) -> str:
    """The values a flag takes, as its metavar (checked with the configuration, not by argparse:
    a bad value is a one-line error naming the flag)."""
    return "|".join(names)


#: the walkthrough's examples, printed after its flags
EXAMPLES = """examples:
  launch/walkthrough                                 the plant on a 2x2 wall of 256x256 tiles, 4 ranks
  launch/walkthrough --grid 3x3 --tile 512x512 --balance strips --out out/strips
  launch/walkthrough --model models/pump.glb --split components --path-kind orbit
  launch/walkthrough --wall wall.json --present window --path interactive --record flight.json
  launch/walkthrough --path flight.json --out out/replay     replay a flight bit for bit
  launch/walkthrough --hosts a:2,b:2                 4 ranks on two PCs (remote shell: ssh or $MULTIGPU_RSH)
  mpiexec -n 4 python -m mpi4py -m multigpu walkthrough --grid 2x2   under your own mpiexec

Outputs in --out: timings.csv (a row per frame and rank), summary.json, mosaic/ (docs/USAGE.md)."""


#: the walkthrough parser's settings (the CLI's subcommand and docs/USAGE.md's synopsis alike)
WALKTHROUGH = {"description": "Render a camera path on a display wall: one MPI rank per tile, the work\n"
                              "balanced every frame, every rank composing and showing its own tile.",
               "formatter_class": HelpFormatter, "epilog": EXAMPLES}


def walkthrough_parser(prog: str = "multigpu walkthrough") -> argparse.ArgumentParser:
    """The walkthrough's parser on its own: what ``multigpu walkthrough --help`` prints."""
    p = argparse.ArgumentParser(prog=prog, **WALKTHROUGH)
    scene_args(p)
    walkthrough_args(p)
    return p


def walkthrough_args(w: argparse.ArgumentParser) -> None:
    """The walkthrough's own flags in groups; defaults from ``WalkConfig``, choices from the
    registries (the scene's flags come from ``scene_args``)."""
    from multigpu.config import DEFAULT_FRAMES, WalkConfig
    from multigpu.decompositions import PATTERNS, RANGES
    from multigpu.decompositions import REGISTRY as DECOMPOSITIONS
    from multigpu.gpu.render import METHODS
    from multigpu.strategies import REGISTRY, describe

    d = defaults(WalkConfig)
    pair = lambda v: f"{v[0]}x{v[1]}"
    c = w.add_argument_group("camera path")
    c.add_argument("--path", metavar="FILE", help="camera path JSON file, or 'interactive': fly by hand from rank 0's "
                                                   "window, starting where --path-kind starts (needs --present window; "
                                                   "H prints the keys) (default: a generated path)")
    c.add_argument("--path-kind", default=d["path_kind"], metavar=_one_of(list(DEFAULT_FRAMES)),
                   help="the generated path when no --path is given")
    c.add_argument("--frames", type=int, metavar="N",
                   help="frames to render (default: the whole path; generated: "
                        + ", ".join(f"{k} {v}" for k, v in DEFAULT_FRAMES.items()) + ")")
    c.add_argument("--offset", default="0,0,0", metavar="X,Y,Z",
                   help="move scene and path by these world units (e.g. 1e8,0,0: far from the origin)")
    g = w.add_argument_group("wall and display")
    g.add_argument("--grid", metavar="ROWSxCOLS",
                   help=f"display wall; ranks = rows*cols (default: {pair(WalkConfig.grid)})")
    g.add_argument("--tile", metavar="WxH", help=f"pixels per display tile (default: {pair(WalkConfig.tile)})")
    g.add_argument("--mullion", metavar="MXxMY",
                   help="pixels hidden behind the bezels between tiles: the camera spans them, nobody renders "
                        f"them (default: {pair(WalkConfig.mullion)})")
    g.add_argument("--wall", metavar="FILE", help="wall file (JSON): grid, tile, mullions, each rank's X display and "
                                                  "window position; flags override it (docs/USAGE.md: On a real wall)")
    g.add_argument("--present", default=d["present"], metavar=_one_of(["headless", "window"]),
                   help="window: every rank shows its composed tile in a borderless window on its X display, all "
                        "tiles swapped in step")
    g.add_argument("--monitor", nargs="?", const="beside", metavar="X,Y",
                   help="an operator view on rank 0's display: the whole wall shrunk, the partition over it, live "
                        "(at X,Y; without a value: the wall file's monitor position, else right of the wall)")
    g.add_argument("--device", type=int, metavar="I",
                   help="EGL device index (default: local rank modulo device count)")
    g.add_argument("--subfrustum", default=d["subfrustum"], metavar=_one_of(list(METHODS)),
                   help="how a rank renders its region (docs/ACCURACY.md)")
    b = w.add_argument_group("balancing")
    b.add_argument("--balance", default=d["balance"], metavar=_one_of(list(REGISTRY)),
                   help=f"the balancing strategy. {describe()}")
    b.add_argument("--decomposition", default=d["decomposition"], metavar=_one_of(list(DECOMPOSITIONS)),
                   help="how a frame is divided: screen = the paper's screen partition (balanced by --balance); "
                        "db = sort-last database decomposition, depth-composited; bins = static bin patterns, "
                        "no balancer; hybrid = the screen partition (--balance) for most objects, the wide ones "
                        "drawn once and depth-composited")
    b.add_argument("--strips", type=int, default=d["strips"], metavar="N", help="strips per split axis (>= 2)")
    b.add_argument("--bounds", default=d["bounds"], metavar=_one_of(["box", "sphere"]),
                   help="object bounds: box (8 corners) or sphere")
    b.add_argument("--bin-size", type=int, default=d["bin_size"], metavar="PX", help="bins: pixels per bin side")
    b.add_argument("--bin-pattern", default=d["bin_pattern"], metavar=_one_of(list(PATTERNS)),
                   help="bins: which rank owns a bin")
    b.add_argument("--db-ranges", default=d["db_ranges"], metavar=_one_of(list(RANGES)),
                   help="db: object ranges rebalanced over the visible objects every frame, or fixed by all triangles")
    b.add_argument("--partition", default=d["partition"], metavar=_one_of(["redundant", "broadcast"]),
                   help="who computes the partition: every rank, or rank 0 and a broadcast")
    b.add_argument("--projection", default=d["projection"], metavar=_one_of(["each", "shared"]),
                   help="who projects the object bounds: every rank every object, or the ranks of a machine a slice "
                        "each into one shared array (pays from ~50k objects)")
    b.add_argument("--latency", type=int, default=d["latency"], metavar="N",
                   help="frames in flight: a rank plans and draws the next frames while a frame's pixels travel and "
                        "show (0: each frame shown before the next starts; input reaches the screen N frames later; "
                        "default: 1 headless, 0 with --present window)")
    b.add_argument("--exchange", default=d["exchange"], metavar=_one_of(["auto", "shared", "messages"]),
                   help="frame exchange: auto = a shared-memory segment per machine where it can be made, messages "
                        "between machines; shared = the same, an error where it cannot; messages = point to point")
    q = w.add_argument_group("speed for accuracy")
    q.add_argument("--target-fps", type=float, default=d["target_fps"], metavar="F",
                   help="hold this frame rate while the camera moves: each frame a render scale and a level-of-detail "
                        "bound from the last frames' times; a frame whose camera stopped is full quality "
                        "(default: none, every frame full quality)")
    q.add_argument("--render-scale", type=float, default=d["render_scale"], metavar="S",
                   help="full quality's share of each side's pixels, 0.25..1 (nearest-neighbour upscaled to the tiles)")
    q.add_argument("--lod-error", type=float, default=d["lod_error"], metavar="PX",
                   help="full quality's level-of-detail bound: each object at its coarsest level whose error stays "
                        "within PX pixels on the wall (0: as modelled)")
    _output_args(w, d)


def _output_args(w: argparse.ArgumentParser, d: dict) -> None:
    """The walkthrough's outputs, run control and the launcher's hosts flags."""
    from multigpu.scene.looks import COLOR_VIEWS

    o = w.add_argument_group("outputs")
    o.add_argument("--out", default=d["out"], metavar="DIR",
                   help="output directory: timings.csv, summary.json, mosaic/")
    o.add_argument("--mosaic-every", type=int, default=d["mosaic_every"], metavar="N",
                   help="write the full wall as a PNG every N frames (0: never)")
    o.add_argument("--no-overlay", action="store_true", help="no partition overlay beside each mosaic")
    o.add_argument("--colors", choices=COLOR_VIEWS, default=d["colors"], metavar="model|objects",
                   help="model: the model's own colours (its materials and vertex colours; one grey where the file "
                        "has none); objects: a colour per object, to see what the balancer moves between ranks")
    o.add_argument("--video", action="store_true", help="write mosaic.mp4 of every frame (needs imageio-ffmpeg)")
    o.add_argument("--timeline", action="store_true",
                   help="write timeline.json: every rank's phases, start to end, over the run's last frames "
                        "(multigpu bench timeline plots it)")
    o.add_argument("--record", metavar="FILE", help="write every frame's camera to FILE, in the format --path reads "
                                                    "(replaying it renders the same images)")
    r = w.add_argument_group("run control")
    r.add_argument("--timeout", type=float, default=d["timeout"], metavar="S",
                   help="seconds a rank waits for the others within a frame")
    r.add_argument("--liveness", type=float, default=d["liveness"], metavar="S",
                   help="seconds without a heartbeat before a rank counts as stopped and the job ends (0: off)")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.add_argument("--recover", type=int, metavar="N",
                   help="restart the job after a failure (a rank or host that dies or freezes), resuming at the "
                        "first frame not shown, at most N times in 10 minutes; the launcher's (default: 3 with "
                        "--present window, 0 headless)")
    r.add_argument("--dark-tiles", metavar="K,...", default="",
                   help="tiles whose PC is gone: shown black, the rest of the wall shared among every rank (the "
                        "launcher's restart without a host that does not answer)")
    r.add_argument("--resume-at", type=int, default=0, metavar="F",
                   help="start at frame F of the camera path, continuing the run already in --out (the "
                        "launcher's restart after a failure)")
    h = w.add_argument_group("hosts (the launcher's: launch/walkthrough, python -m multigpu.parallel.mpirun)")
    h.add_argument("--hosts", metavar="H:N,...", help="place the ranks on these hosts in order, N each (e.g. a:2,b:2)")
    h.add_argument("--hostfile", metavar="FILE", help="hosts one per line: HOST, HOST:N or HOST slots=N")


def walk_config(a):
    """The walkthrough's flags as a validated configuration (no MPI: testable in one process)."""
    from multigpu.config import WalkConfig, parse_pair, parse_vec3
    from multigpu.wall import Wall, bezel_mullion, check_ranks, load_wall

    for name in ("hosts", "hostfile"):
        if getattr(a, name, None) is not None:
            raise InputError(f"--{name} places the ranks when the job starts: give it to launch/walkthrough or "
                             "python -m multigpu.parallel.mpirun, or place them with your mpiexec's own flags")
    wall = load_wall(a.wall) if a.wall else Wall("")
    pick = lambda flag, text, parse, default: parse(text, flag) if text is not None else default
    grid = pick("--grid", a.grid, parse_pair, wall.grid or WalkConfig.grid)
    check_ranks(wall, grid[0] * grid[1])
    ranks = range(grid[0] * grid[1])
    tile = pick("--tile", a.tile, parse_pair, wall.tile or WalkConfig.tile)
    return WalkConfig(scene=spec(a), path=a.path, path_kind=a.path_kind, frames=a.frames,
                      grid=grid, tile=tile,
                      mullion=pick("--mullion", a.mullion, parse_mullion,
                                   wall.mullion or bezel_mullion(wall, tile) or WalkConfig.mullion),
                      present=a.present, wall=a.wall,
                      displays=tuple(wall.displays.get(r) for r in ranks) if wall.displays else (),
                      positions=tuple(wall.positions.get(r) for r in ranks) if wall.positions else (),
                      fullscreen=tuple(r in wall.fullscreen for r in ranks) if wall.fullscreen else (),
                      gpus=tuple(wall.gpus.get(r) for r in ranks) if wall.gpus else (),
                      strips=a.strips,
                      balance=a.balance, bounds=a.bounds, out=a.out, mosaic_every=a.mosaic_every,
                      overlay=not a.no_overlay, video=a.video, device=a.device, subfrustum=a.subfrustum,
                      partition=a.partition, exchange=a.exchange, latency=a.latency, projection=a.projection,
                      offset=parse_vec3(a.offset, "--offset"), timeout=a.timeout,
                      decomposition=a.decomposition, bin_size=a.bin_size, bin_pattern=a.bin_pattern,
                      db_ranges=a.db_ranges,
                      liveness=a.liveness, progress=not a.no_progress, record=a.record, timeline=a.timeline,
                      monitor=wall.monitor if a.monitor == "beside" and wall.monitor else _monitor(a.monitor),
                      target_fps=a.target_fps, render_scale=a.render_scale,
                      lod_error=a.lod_error, colors=a.colors, recover=a.recover, resume_at=a.resume_at,
                      dark=_labels(a.dark_tiles))


def dark_tiles(a) -> tuple[int, ...]:
    """``--dark-tiles`` as tile labels, () where unreadable (the configuration's check says so)."""
    try:
        return _labels(getattr(a, "dark_tiles", "") or "")
    except InputError:
        return ()


def _labels(text: str) -> tuple[int, ...]:
    """``--dark-tiles 2,3`` as tile labels."""
    try:
        return tuple(sorted({int(v) for v in text.split(",") if v.strip()}))
    except ValueError:
        raise InputError(f"--dark-tiles must be tile numbers separated by commas, got '{text}'") from None


def _monitor(text: str | None) -> tuple[int, int] | None:
    """``--monitor`` [X,Y] as a window place (None: no monitor)."""
    from multigpu.config import MONITOR_BESIDE

    if text is None:
        return None
    if text == "beside":
        return MONITOR_BESIDE
    x, y = str(text).split(",", 1) if "," in str(text) else (text, "")
    if not (x.strip().isdigit() and y.strip().isdigit()):
        raise InputError(f"--monitor must look like X,Y (pixels from the display's top-left corner), got '{text}'")
    return int(x), int(y)


def parse_mullion(text: str, flag: str = "--mullion") -> tuple[int, int]:
    """'MXxMY' (non-negative pixels) or a clear error naming ``flag``."""
    m = re.fullmatch(r"\s*(\d+)\s*x\s*(\d+)\s*", str(text))
    if not m:
        raise InputError(f"{flag} must look like MXxMY with pixels >= 0 (e.g. 40x40), got '{text}'")
    return int(m.group(1)), int(m.group(2))
