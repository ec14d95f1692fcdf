"""The subcommands beside ``walkthrough``, declared as data: each one's words, its arguments and
the function it runs. ``cli.build_parser`` adds them all in one loop, so a flag's declaration lives
here once (``--out``, ``--frames``, ``--quick``: one helper each) and the walkthrough's flags come
from the declared options (``options.py``). No argparse here beyond its constants."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

from multigpu.scene.paths import GENERATORS


@dataclass(frozen=True)
class Arg:
    """One argument: argparse's names and keywords."""

    names: tuple[str, ...]
    kw: dict


def arg(*names: str, **kw) -> Arg:
    return Arg(names, kw)


def out(default: str | None, help: str) -> Arg:
    """``--out``: where a command writes (required where ``default`` is None)."""
    return arg("--out", help=help, **({"required": True} if default is None else {"default": default}))


def frames(help: str = argparse.SUPPRESS, default: int | None = None) -> Arg:
    """``--frames N``."""
    return arg("--frames", type=int, default=default, help=help)


def quick(help: str) -> Arg:
    """``--quick``: small sizes, the same code."""
    return arg("--quick", action="store_true", help=help)


def path_kind(help: str = "generated path: walkthrough | orbit | still") -> Arg:
    """``--path-kind``: the generated camera path (the walkthrough's choices)."""
    return arg("--path-kind", default="walkthrough", choices=tuple(GENERATORS), help=help)


@dataclass(frozen=True)
class Command:
    """A subcommand: its words (``("scene", "info")``), help, arguments, whether it takes the
    scene's flags, and what it runs (``"module:function"``, imported when it runs)."""

    words: tuple[str, ...]
    help: str
    run: str
    args: tuple[Arg, ...] = ()
    scene: bool = False
    group_help: dict = field(default_factory=dict)  # the help of the group its first word opens


COMMANDS: tuple[Command, ...] = (
    Command(("scene", "info"), "print objects, triangles, bounds, memory and load time", "multigpu.tools:scene_info",
            (arg("source", nargs="?", default="plant", help="built-in scene name or model file"),
             arg("--grid", default="2x2", help="the wall the scene is prepared for (automatic clustering)"),
             arg("--no-cache", action="store_true")), scene=True, group_help={"scene": "scene tools"}),
    Command(("scene", "scan"), "write a scanned-style model: one closed surface of even triangles (binary PLY); "
            "load it cut into parts with --model OUT --split grid:8", "multigpu.tools:scene_scan",
            (arg("out", help="PLY file to write"),
             arg("--triangles", type=int, default=1_000_000, help="about this many (default %(default)s)"),
             arg("--seed", type=int, default=0))),
    Command(("path", "make"), "write a camera path file", "multigpu.tools:path_make",
            (arg("kind", choices=tuple(GENERATORS), help="walkthrough | orbit"), frames("frames of the path"),
             arg("--fov", type=float, default=60.0), out(None, "path file to write (JSON)")), scene=True,
            group_help={"path": "camera path tools"}),
    Command(("wall", "check"), "validate a wall file and print its layout", "multigpu.tools:wall_check",
            (arg("file", help="wall file (JSON: grid, tile, mullion, displays)"),
             arg("--grid-only", action="store_true", help="print only ROWSxCOLS (for launch scripts)"),
             arg("--hosts-only", action="store_true", help="print only the hosts as H:N,... (for launch scripts)"),
             arg("--offline", action="store_true",
                 help="check the file alone: no host name look-up, no X screen asked (a wall written elsewhere)")),
            group_help={"wall": "wall file tools"}),
    Command(("wall", "test"), "show the calibration pattern on the wall (under mpiexec: launch/wall-test FILE)",
            "multigpu.tools:wall_test",
            (arg("file", help="wall file (JSON)"), frames("stop after N frames (default: at Escape)"),
             arg("--blend", default="on", choices=("on", "off"), help="a projector wall's outputs blended in their "
                 "overlaps, or not (each projector's whole picture, for aligning by eye; default on)"))),
    Command(("warp", "make"), "write an MPCDI file (2D media) for a described projector rig: projectors side by "
            "side on a flat or cylindrical screen, their warps and blends", "multigpu.tools:warp_make",
            (arg("out", help="MPCDI file to write (.mpcdi)"),
             arg("--screen", default="flat", choices=("flat", "cylinder"), help="flat | cylinder (default flat)"),
             arg("--projectors", type=int, default=3, help="projectors side by side (default 3)"),
             arg("--overlap", type=float, default=0.18, help="neighbours overlap by this share of an image's "
                                                             "width (default 0.18)"),
             arg("--size", default="1920x1080", help="each projector's pixels WxH (default 1920x1080)"),
             arg("--canvas", default=None, help="the wall's canvas WxH: the screen takes its shape and the file's "
                                                "buffer its size (default: the projectors' own density)")),
            group_help={"warp": "projector warp and blend tools"}),
    Command(("warp", "check"), "read an MPCDI file (2D media) and print its regions, warps and blend maps",
            "multigpu.tools:warp_check", (arg("file", help="MPCDI file (.mpcdi)"),)),
    Command(("monitor-view",), "the operator's view on a PC of its own (started by the launcher from the wall "
            "file's monitor.host)", "multigpu.tools:monitor_view",
            (arg("--display", help="X display (default $DISPLAY)"),
             arg("--position", default="0x0", help="window position XxY on that display (default 0x0)"),
             arg("--port", type=int, default=0, help="TCP port to listen on (default: any, printed)"),
             arg("--listen", default="127.0.0.1", help="address to listen on (default 127.0.0.1; the launcher gives "
                                                       "the wall file's monitor address or host; a connection must "
                                                       "bring the token the launcher writes on standard input)"))),
    Command(("view",), "serve the operator's page over a finished run's outputs: its plots, summary and mosaics",
            "multigpu.tools:view",
            (arg("out", help="the run's output directory (summary.json, timings.csv, mosaic/)"),
             arg("--panel", default="127.0.0.1:0", help="[ADDRESS:]PORT to serve on (default 127.0.0.1, any port; "
                                                        "the URL with its token is printed)"))),
    Command(("tree",), "print the GPU tree of a ROWSxCOLS wall", "multigpu.tools:tree", (arg("grid"),)),
    Command(("depth",), "depth complexity and overdraw of one frame (images + stats)", "multigpu.tools:depth",
            (path_kind(), frames("frames of the generated path"),
             arg("--frame", type=int, default=0, help="which frame of the path"),
             arg("--size", default="1024x1024", help="display WxH in pixels"),
             out("out/depth", "output directory")), scene=True),
    Command(("experiment",), "the paper's evaluation: tables, plots, Markdown", "multigpu.cli:_experiment",
            (arg("name", help="{experiments}"), quick("tiny sizes: the same code in a few minutes"),
             out("out/experiments", "output directory"),
             arg("--results", default=None, help="results page written by 'all' (default OUT/RESULTS.md)"),
             arg("--rounds", type=int, default=None, help="alternated rounds of payoff, speedup and partition "
                                                          "(default 3, 3 and 2; 1 with --quick)"))),
    Command(("accuracy",), "measure every speed-for-accuracy trade (tables for docs/ACCURACY.md)",
            "multigpu.cli:_accuracy",
            (quick("tiny sizes: the same code in under a minute"), out("out/accuracy", "directory for the CSV tables"),
             arg("--page", default=None, help="Markdown page to write (default OUT/ACCURACY.md)"))),
    Command(("bench",), "benchmarks: print speed and memory figures", "multigpu.cli:_bench",
            (arg("what", help="{benches}"), quick("small sizes, a few seconds"),
             arg("--worker", action="store_true", help=argparse.SUPPRESS),  # floor: the MPI side
             frames(), path_kind(argparse.SUPPRESS),
             arg("--ranks", default="4", help="floor, peer: the rank counts to measure, e.g. 4,9,16 or 1,4 "
                                              "(default 4)"),
             arg("--rounds", type=int, default=2, help="peer, latency: alternated rounds (default 2)"),
             arg("--tile", type=int, default=256, help="floor: the side of the region every rank renders, pixels "
                                                       "(default 256)"),
             arg("--display", type=int, default=None, help="floor: the side of the display that region is the "
                                                           "centre of, pixels (default twice the tile)"),
             out("out/peer", "peer, latency, simplify, timeline: where the runs and the results go (default "
                             "out/peer, out/latency, out/simplify, out/timeline)")),
            scene=True),  # bench floor's worker: the scene it renders
)
