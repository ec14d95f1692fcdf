"""The ``multigpu`` command line: one entry point, argparse subcommands.

    mpiexec -n K multigpu walkthrough [...]   the parallel renderer (MPI)
    multigpu scene info SCENE_OR_FILE          objects, triangles, bounds, memory, load time
    multigpu path make KIND --out FILE         write a camera path file
    multigpu tree RxC                          print the GPU tree and each rank's ParInfo
    multigpu bench balance|frame|passes|exchange|...  benchmarks (speed and memory figures)
    multigpu experiment NAME|all [--quick] [--rounds N]  the paper's evaluation: CSV, plots, Markdown
    multigpu accuracy [--quick]                speed-for-accuracy trades: CSV + ACCURACY.md

Bad input prints ``multigpu: error: ...`` (one line) and exits 2.
"""

from __future__ import annotations

import argparse
import sys

from multigpu import tools
from multigpu.core.memory import keep_heap
from multigpu.errors import InputError, WriteFailed
from multigpu.flags import WALKTHROUGH, scene_args, walk_config, walkthrough_args  # noqa: F401 (walk_config: tests)


class Parser(argparse.ArgumentParser):
    """argparse that speaks once per MPI job: only launcher rank 0 prints usage, help and
    errors (every rank parses the same argv and exits the same way)."""

    def error(self, message):
        """A bad flag in one line (``prog: error: ...``), exit 2: not the whole usage above it."""
        self.exit(2, f"{self.prog}: error: {message} (--help lists the flags)\n")

    def _print_message(self, message, file=None):
        from multigpu.rank.job import launcher_rank

        if launcher_rank() == 0:
            super()._print_message(message, file)


#: what ``multigpu --help`` opens with
DESCRIPTION = ("Render 3-D models on tiled display walls, one MPI rank per GPU and display tile, the "
               "rendering work balanced between the ranks every frame (Dong & Peng 2019). Start with "
               "'mpiexec -n 4 multigpu walkthrough' or launch/walkthrough; each command's --help has its flags.")


#: what ``multigpu --help`` ends with
EXAMPLES = """examples:
  launch/walkthrough --model models/pump.glb        4 ranks, a 2x2 wall, headless: out/
  launch/walkthrough --wall wall.json --present window --monitor --path interactive
"""


def _version() -> str:
    """The installed package's version (the source tree's when not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("multigpu")
    except PackageNotFoundError:
        return "(not installed)"


def build_parser() -> argparse.ArgumentParser:
    import textwrap

    ap = Parser(prog="multigpu", description=textwrap.fill(DESCRIPTION, 79), epilog=EXAMPLES,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"multigpu {_version()}")
    sub = ap.add_subparsers(dest="cmd", required=True)

    w = sub.add_parser("walkthrough", help="render a camera path on a display wall (run under mpiexec)",
                       **WALKTHROUGH)
    scene_args(w)
    walkthrough_args(w)
    w.set_defaults(run=_walkthrough)
    _tool_parsers(sub)
    _study_parsers(sub)
    return ap


def _tool_parsers(sub) -> None:
    """The scene, path, wall, monitor-view, tree and depth subcommands."""
    s = sub.add_parser("scene", help="scene tools")
    ssub = s.add_subparsers(dest="scmd", required=True)
    si = ssub.add_parser("info", help="print objects, triangles, bounds, memory and load time")
    si.add_argument("source", nargs="?", default="plant", help="built-in scene name or model file")
    scene_args(si)
    si.add_argument("--grid", default="2x2", help="the wall the scene is prepared for (automatic clustering)")
    si.add_argument("--no-cache", action="store_true")
    si.set_defaults(run=tools.scene_info)
    sc = ssub.add_parser("scan", help="write a scanned-style model: one closed surface of even triangles (binary "
                                      "PLY); load it cut into parts with --model OUT --split grid:8")
    sc.add_argument("out", help="PLY file to write")
    sc.add_argument("--triangles", type=int, default=1_000_000, help="about this many (default %(default)s)")
    sc.add_argument("--seed", type=int, default=0)
    sc.set_defaults(run=tools.scene_scan)

    p = sub.add_parser("path", help="camera path tools")
    psub = p.add_subparsers(dest="pcmd", required=True)
    pm = psub.add_parser("make", help="write a camera path file")
    pm.add_argument("kind", help="walkthrough | orbit")
    scene_args(pm)
    pm.add_argument("--frames", type=int)
    pm.add_argument("--fov", type=float, default=60.0)
    pm.add_argument("--out", required=True, help="path file to write (JSON)")
    pm.set_defaults(run=tools.path_make)

    wl = sub.add_parser("wall", help="wall file tools")
    wsub = wl.add_subparsers(dest="wall_cmd", required=True)
    wc = wsub.add_parser("check", help="validate a wall file and print its layout")
    wc.add_argument("file", help="wall file (JSON: grid, tile, mullion, displays)")
    wc.add_argument("--grid-only", action="store_true", help="print only ROWSxCOLS (for launch scripts)")
    wc.add_argument("--hosts-only", action="store_true", help="print only the hosts as H:N,... (for launch scripts)")
    wc.add_argument("--offline", action="store_true",
                    help="check the file alone: no host name look-up, no X screen asked (a wall written elsewhere)")
    wc.set_defaults(run=tools.wall_check)
    wt = wsub.add_parser("test", help="show the calibration pattern on the wall (under mpiexec: launch/wall-test FILE)")
    wt.add_argument("file", help="wall file (JSON)")
    wt.add_argument("--frames", type=int, default=None, help="stop after N frames (default: at Escape)")
    wt.set_defaults(run=tools.wall_test)
    mv = sub.add_parser("monitor-view", help="the operator's view on a PC of its own (started by the launcher "
                                             "from the wall file's monitor.host)")
    mv.add_argument("--display", help="X display (default $DISPLAY)")
    mv.add_argument("--position", default="0x0", help="window position XxY on that display (default 0x0)")
    mv.add_argument("--port", type=int, default=0, help="TCP port to listen on (default: any, printed)")
    mv.add_argument("--listen", default="", help="address to listen on (default: every interface; a connection "
                                                 "must bring the token the launcher writes on standard input)")
    mv.set_defaults(run=tools.monitor_view)
    t = sub.add_parser("tree", help="print the GPU tree of a ROWSxCOLS wall")
    t.add_argument("grid")
    t.set_defaults(run=tools.tree)

    dp = sub.add_parser("depth", help="depth complexity and overdraw of one frame (images + stats)")
    scene_args(dp)
    dp.add_argument("--path-kind", default="walkthrough", help="generated path: walkthrough | orbit")
    dp.add_argument("--frames", type=int, default=None, help="frames of the generated path")
    dp.add_argument("--frame", type=int, default=0, help="which frame of the path")
    dp.add_argument("--size", default="1024x1024", help="display WxH in pixels")
    dp.add_argument("--out", default="out/depth", help="output directory")
    dp.set_defaults(run=tools.depth)


def _study_parsers(sub) -> None:
    """The experiment, accuracy and bench subcommands."""
    from multigpu.studies.registry import EXPERIMENTS, names_help

    e = sub.add_parser("experiment", help="the paper's evaluation: tables, plots, Markdown")
    e.add_argument("name", help=names_help(["all", *EXPERIMENTS]))
    e.add_argument("--quick", action="store_true", help="tiny sizes: the same code in a few minutes")
    e.add_argument("--out", default="out/experiments", help="output directory")
    e.add_argument("--results", default=None, help="results page written by 'all' (default OUT/RESULTS.md)")
    e.add_argument("--rounds", type=int, default=None,
                   help="alternated rounds of payoff, speedup and partition "
                        "(default 3, 3 and 2; 1 with --quick)")
    e.set_defaults(run=_experiment)
    ac = sub.add_parser("accuracy", help="measure every speed-for-accuracy trade (tables for docs/ACCURACY.md)")
    ac.add_argument("--quick", action="store_true", help="tiny sizes: the same code in under a minute")
    ac.add_argument("--out", default="out/accuracy", help="directory for the CSV tables")
    ac.add_argument("--page", default=None, help="Markdown page to write (default OUT/ACCURACY.md)")
    ac.set_defaults(run=_accuracy)
    _bench_args(sub.add_parser("bench", help="benchmarks: print speed and memory figures"))


def _bench_parser(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``bench`` subcommand's parser."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices["bench"]


def _bench_args(b: argparse.ArgumentParser) -> None:
    """The ``bench`` subcommand's arguments."""
    from multigpu.studies.registry import BENCHES

    b.add_argument("what", help="; ".join(f"{n}: {about}" for n, (_, about) in BENCHES.items()))
    b.add_argument("--quick", action="store_true", help="small sizes, a few seconds")
    b.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)  # floor: the MPI side
    b.add_argument("--frames", type=int, default=None, help=argparse.SUPPRESS)
    b.add_argument("--path-kind", default="walkthrough", help=argparse.SUPPRESS)
    b.add_argument("--ranks", default="4", help="floor, peer: the rank counts to measure, e.g. 4,9,16 or 1,4 "
                                                "(default 4)")
    b.add_argument("--rounds", type=int, default=2, help="peer, latency: alternated rounds (default 2)")
    b.add_argument("--tile", type=int, default=256, help="floor: the side of the region every rank renders, pixels "
                                                        "(default 256)")
    b.add_argument("--display", type=int, default=None, help="floor: the side of the display that region is the "
                                                             "centre of, pixels (default twice the tile)")
    b.add_argument("--out", default="out/peer", help="peer, latency, simplify, timeline: where the runs and the "
                                                     "results go (default out/peer, out/latency, out/simplify, "
                                                     "out/timeline)")
    scene_args(b)  # bench floor's worker: the scene it renders
    b.set_defaults(run=_bench)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if len(argv) == 3 and argv[0] == "bench" and argv[2] in ("-h", "--help"):  # that benchmark's own flags
        from multigpu.studies.bench import help_for
        from multigpu.studies.registry import BENCHES

        if argv[1] in BENCHES:
            print(help_for(argv[1], _bench_parser(build_parser())), end="")
            return 0
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # usage errors and --help: the same on every rank
        if "mpi4py.MPI" in sys.modules:  # under `python -m mpi4py`: exit together, no MPI_Abort
            from multigpu.rank.job import collective_exit

            collective_exit(exc.code if isinstance(exc.code, int) else 0)
        raise
    keep_heap()  # per-frame temporaries stay in the heap (see memory.py)
    try:
        return args.run(args)  # the subcommand's own function (``set_defaults`` in ``build_parser``)
    except InputError as exc:
        print(f"multigpu: error: {exc}", file=sys.stderr)
        return 2


def _experiment(a) -> int:
    from multigpu.studies import experiments

    return experiments.run(a.name, a.out, quick=a.quick, results=a.results, rounds=a.rounds)


def _accuracy(a) -> int:
    from multigpu.studies import accuracy

    return accuracy.run(a.out, a.page, quick=a.quick)


def _bench(a) -> int:
    from multigpu.studies import bench

    return bench.run_args(a)


def _walkthrough(a) -> int:
    from mpi4py import MPI

    from multigpu.flags import dark_tiles
    from multigpu.rank.job import Interrupted, Job, collective_exit, teardown_barrier
    from multigpu.rank.tiles import tile_comm

    try:
        comm = tile_comm(MPI.COMM_WORLD, getattr(a, "wall", None), dark_tiles(a))
    except InputError as exc:  # agreed on every rank (a wall file one host cannot read): one line, all exit 2
        if MPI.COMM_WORLD.Get_rank() == 0:
            print(f"multigpu: error: {exc}", file=sys.stderr, flush=True)
        collective_exit(2)
    job = Job(comm, liveness=a.liveness if a.liveness is not None and a.liveness >= 0 else 30.0)
    job.catch_signals()  # SIGINT/SIGTERM: raise during setup, stop after the frame during frames
    try:
        cfg = walk_config(a)
        from multigpu.rank.walkthrough import run

        with job:
            run(cfg, comm, job)
    except (InputError, WriteFailed) as exc:  # agreed on every rank: one line, all exit 2
        job.close()
        if comm.Get_rank() == 0:
            print(f"multigpu: error: {exc}", file=sys.stderr, flush=True)
        collective_exit(2)
    except BaseException as exc:  # noqa: BLE001 -- every other way a run can end early
        job.close()
        _end_failed_job(comm, job, exc)
    job.close()
    if job.signum is not None:  # every rank stopped after the same frame: exit 128 + signal, together
        teardown_barrier(comm)
        collective_exit(Interrupted(job.signum).code)
    return 0


def _end_failed_job(comm, job, exc: BaseException) -> None:
    """End the whole job after a failure, with one message and rank 0's outputs saved.

    A rank's own failure is printed by that rank and announced to the others (``Job``), so they
    stop waiting at once. Rank 0 has already written timings.csv and summary.json for every
    whole frame (the frame loop's ``finally``) when it gets here, and aborts the job. Other
    ranks that only saw the consequence (a failed, stalled or silent peer) stay quiet and give
    rank 0 ``FAILURE_GRACE`` seconds to save and end the job, unless rank 0 is the silent one.
    """
    import time

    from multigpu.rank.exchange import PeerTimeout
    from multigpu.rank.job import ABORT_PAUSE, FAILURE_GRACE, Interrupted, PeerFailed, PeerStalled

    rank = comm.Get_rank()
    consequence = isinstance(exc, (PeerTimeout, PeerFailed))
    if isinstance(exc, Interrupted):
        code, text = exc.code, f"multigpu: {exc}; ending the job"
    elif isinstance(exc, KeyboardInterrupt):
        code, text = 130, "multigpu: interrupted; ending the job"
    elif isinstance(exc, PeerStalled):
        code, text = 1, f"multigpu: {exc}"
    else:
        code, text = 1, f"multigpu: rank {rank}: {exc.__class__.__name__}: {exc}"
    if not consequence:
        if rank == 0 or not isinstance(exc, (Interrupted, KeyboardInterrupt)):
            print(text, file=sys.stderr, flush=True)
        job.announce_failure(f"{exc.__class__.__name__}: {exc}")
    if rank != 0:
        deadline = time.monotonic() + FAILURE_GRACE
        while time.monotonic() < deadline and not job.silent(0):
            time.sleep(0.05)  # rank 0 saves the frames done, then ends the job
        if consequence and not isinstance(exc, PeerFailed):
            live = [r for r in range(comm.Get_size()) if not job.silent(r)]
            if not live or rank == min(live):
                print(text, file=sys.stderr, flush=True)
    elif consequence and not isinstance(exc, PeerFailed):
        print(text, file=sys.stderr, flush=True)
    time.sleep(ABORT_PAUSE)  # the launcher forwards what we printed before MPI_Abort tears it down
    comm.Abort(code)


if __name__ == "__main__":
    sys.exit(main())
