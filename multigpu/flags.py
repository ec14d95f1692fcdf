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
    g.add_argument("--scene", default=d["scene"], help=f"built-in scene: {' | '.join(BUILTIN)} (default: %(default)s)")
    g.add_argument("--model", help="model file (OBJ, PLY, STL, OFF, glTF/GLB) instead of --scene")
    g.add_argument("--split", default=d["split"],
                   help="objects of a model: auto (scene-graph nodes, else connected components) | components | "
                        "grid:N (applies to any file)")
    g.add_argument("--merge-below", type=int, default=d["merge_below"],
                   help="merge components under this many triangles (default %(default)s)")
    g.add_argument("--triangles", type=int, default=d["triangles"],
                   help="built-in scene size in triangles (default %(default)s)")
    g.add_argument("--copies", type=int, default=d["copies"], help="plants side by side (the paper used 6..20)")
    g.add_argument("--seed", type=int, default=d["seed"])
    g.add_argument("--cluster", default="auto",
                   help="cut objects above N triangles into spatial clusters of at most N: auto (when an object "
                        "is too big to balance on the wall) | N | 0 (keep objects as modelled)")
    g.add_argument("--up", default=d["up"], help="up axis of the model: x | y | z | -x | -y | -z "
                                                 "(default: the format's convention, see scene info)")


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


def walkthrough_args(w: argparse.ArgumentParser) -> None:
    """The walkthrough's own flags; defaults from ``WalkConfig``, choices from the registries."""
    from multigpu.config import DEFAULT_FRAMES, WalkConfig
    from multigpu.gpu.render import METHODS
    from multigpu.strategies import REGISTRY, describe

    d = defaults(WalkConfig)
    pair = lambda v: f"{v[0]}x{v[1]}"
    w.add_argument("--path", help="camera path JSON file (default: generated walkthrough), or 'interactive': fly "
                                  "by hand from rank 0's window, starting where --path-kind starts (needs --present "
                                  "window; keys in docs/USAGE.md, H prints them)")
    w.add_argument("--record", metavar="FILE", help="write every frame's camera to FILE, in the format --path reads "
                                                    "(replaying it renders the same images)")
    w.add_argument("--monitor", nargs="?", const="beside", metavar="X,Y",
                   help="an operator view on rank 0's display: the whole wall shrunk, the partition over it, live "
                        "(at X,Y; default: right of the wall)")
    w.add_argument("--path-kind", default=d["path_kind"], help=f"generated path: {' | '.join(DEFAULT_FRAMES)}")
    w.add_argument("--frames", type=int, help="frames to render (default: the whole path; generated: "
                                              + ", ".join(f"{k} {v}" for k, v in DEFAULT_FRAMES.items()) + ")")
    w.add_argument("--grid", help=f"display wall ROWSxCOLS (ranks = rows*cols; default {pair(WalkConfig.grid)})")
    w.add_argument("--tile", help=f"pixels per display tile WxH (default {pair(WalkConfig.tile)})")
    w.add_argument("--mullion", help="pixels hidden behind the bezels between tiles MXxMY: the camera spans them, "
                                     f"nobody renders them (default {pair(WalkConfig.mullion)})")
    w.add_argument("--wall", help="wall file (JSON): grid, tile, mullions, each rank's X display and window position; "
                                  "flags override it (docs/USAGE.md: On a real wall)")
    w.add_argument("--present", default=d["present"],
                   help="headless (default) | window: every rank shows its composed tile in a borderless window "
                        "on its X display, all tiles swapped in step")
    w.add_argument("--strips", type=int, default=d["strips"], help="strips per split axis (>= 2)")
    w.add_argument("--balance", default=d["balance"],
                   help=f"balancing strategy, one of {' | '.join(REGISTRY)} (default %(default)s). {describe()}")
    from multigpu.decompositions import PATTERNS, RANGES
    from multigpu.decompositions import REGISTRY as DECOMPOSITIONS

    w.add_argument("--decomposition", default=d["decomposition"],
                   help=f"how a frame is divided: {' | '.join(DECOMPOSITIONS)} (default %(default)s): screen = the "
                        "paper's screen partition (balanced by --balance); db = sort-last database decomposition, "
                        "depth-composited; bins = static bin patterns, no balancer")
    w.add_argument("--bin-size", type=int, default=d["bin_size"],
                   help="bins: pixels per bin side (default %(default)s)")
    w.add_argument("--bin-pattern", default=d["bin_pattern"],
                   help=f"bins: which rank owns a bin: {' | '.join(PATTERNS)} (default %(default)s)")
    w.add_argument("--db-ranges", default=d["db_ranges"],
                   help=f"db: {' | '.join(RANGES)}: object ranges rebalanced over the visible objects every frame, "
                        "or fixed by all triangles (default %(default)s)")
    w.add_argument("--bounds", default=d["bounds"], help="object bounds: box (8 corners) | sphere")
    w.add_argument("--out", default=d["out"], help="output directory (README: Outputs)")
    w.add_argument("--mosaic-every", type=int, default=d["mosaic_every"],
                   help="write the full wall every N frames (0: never)")
    w.add_argument("--no-overlay", action="store_true", help="do not write partition overlay images")
    w.add_argument("--video", action="store_true", help="write mosaic.mp4 of every frame (needs imageio-ffmpeg)")
    w.add_argument("--subfrustum", default=d["subfrustum"],
                   help=f"how a rank renders its region: {' | '.join(METHODS)} (docs/ACCURACY.md)")
    w.add_argument("--partition", default=d["partition"],
                   help="who computes the partition: redundant (every rank) | broadcast (rank 0, then MPI_Bcast)")
    w.add_argument("--exchange", default=d["exchange"],
                   help="frame exchange: auto (a shared-memory segment per machine where it can be made, messages "
                        "between machines) | shared (the same, but an error across machines) | messages "
                        "(point-to-point only)")
    w.add_argument("--projection", default=d["projection"],
                   help="who projects the object bounds each frame: each (every rank every object) | shared (the "
                        "ranks of a machine a slice each, into one shared-memory array, where it can be made; box "
                        "bounds, strategies without coverage; pays on scenes of 50k objects and more) "
                        "(default %(default)s)")
    w.add_argument("--offset", default="0,0,0", help="move scene and path by X,Y,Z world units (e.g. 1e8,0,0)")
    w.add_argument("--device", type=int, help="EGL device index (default: local rank modulo device count)")
    w.add_argument("--timeout", type=float, default=d["timeout"],
                   help="seconds a rank waits for the others within a frame (default %(default)s)")
    w.add_argument("--liveness", type=float, default=d["liveness"],
                   help="seconds without a heartbeat before a rank counts as stopped and the job ends "
                        "(default %(default)s; 0: off, timeouts only)")
    w.add_argument("--no-progress", action="store_true")


def walk_config(a):
    """The walkthrough's flags as a validated configuration (no MPI: testable in one process)."""
    from multigpu.config import WalkConfig, parse_pair, parse_vec3
    from multigpu.wall import Wall, check_ranks, load_wall

    wall = load_wall(a.wall) if a.wall else Wall("")
    pick = lambda flag, text, parse, default: parse(text, flag) if text is not None else default
    grid = pick("--grid", a.grid, parse_pair, wall.grid or WalkConfig.grid)
    check_ranks(wall, grid[0] * grid[1])
    ranks = range(grid[0] * grid[1])
    return WalkConfig(scene=spec(a), path=a.path, path_kind=a.path_kind, frames=a.frames,
                      grid=grid, tile=pick("--tile", a.tile, parse_pair, wall.tile or WalkConfig.tile),
                      mullion=pick("--mullion", a.mullion, parse_mullion, wall.mullion or WalkConfig.mullion),
                      present=a.present, wall=a.wall,
                      displays=tuple(wall.displays.get(r) for r in ranks) if wall.displays else (),
                      positions=tuple(wall.positions.get(r) for r in ranks) if wall.positions else (),
                      strips=a.strips,
                      balance=a.balance, bounds=a.bounds, out=a.out, mosaic_every=a.mosaic_every,
                      overlay=not a.no_overlay, video=a.video, device=a.device, subfrustum=a.subfrustum,
                      partition=a.partition, exchange=a.exchange, projection=a.projection,
                      offset=parse_vec3(a.offset, "--offset"), timeout=a.timeout,
                      decomposition=a.decomposition, bin_size=a.bin_size, bin_pattern=a.bin_pattern,
                      db_ranges=a.db_ranges,
                      liveness=a.liveness, progress=not a.no_progress, record=a.record,
                      monitor=_monitor(a.monitor))


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
