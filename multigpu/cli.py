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

from multigpu import exits
from multigpu.core.memory import keep_heap
from multigpu.errors import InputError, WriteFailed
from multigpu.flags import WALKTHROUGH, scene_args, walk_config, walkthrough_args  # noqa: F401 (walk_config: tests)


class Parser(argparse.ArgumentParser):
    """argparse that speaks once per MPI job: only launcher rank 0 prints usage, help and
    errors (every rank parses the same argv and exits the same way)."""

    def error(self, message):
        """A bad flag in one line (``prog: error: ...``), exit 2: not the whole usage above it."""
        self.exit(exits.BAD_INPUT, f"{self.prog}: error: {message} (--help lists the flags)\n")

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
    _commands(sub)
    return ap


def _commands(sub) -> None:
    """Every subcommand of ``commands.COMMANDS``, its arguments added in one loop."""
    from multigpu.commands import COMMANDS
    from multigpu.studies.registry import BENCHES, EXPERIMENTS, names_help

    words = {"experiments": names_help(["all", *EXPERIMENTS]),
             "benches": "; ".join(f"{n}: {about}" for n, (_, about) in BENCHES.items())}
    groups: dict[str, object] = {}
    for c in COMMANDS:
        where = sub
        if len(c.words) == 2:
            if c.words[0] not in groups:
                g = sub.add_parser(c.words[0], help=c.group_help.get(c.words[0]))
                groups[c.words[0]] = g.add_subparsers(dest=f"{c.words[0]}_cmd", required=True)
            where = groups[c.words[0]]
        p = where.add_parser(c.words[-1], help=c.help)
        for a in c.args:
            kw = {**a.kw, "help": a.kw["help"].format(**words)} if a.kw.get("help", "").startswith("{") else a.kw
            p.add_argument(*a.names, **kw)
        if c.scene:
            scene_args(p)
        p.set_defaults(run=_runner(c.run))


def _runner(target: str):
    """The function ``module:function`` names, imported when the command runs."""
    def run(a) -> int:
        import importlib

        module, name = target.split(":")
        return getattr(importlib.import_module(module), name)(a)

    return run


def _bench_parser(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``bench`` subcommand's parser."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices["bench"]


def main(argv: list[str] | None = None) -> int:
    from multigpu.flags import joined_negatives

    argv = joined_negatives(sys.argv[1:] if argv is None else list(argv))
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
        return exits.BAD_INPUT
    except BrokenPipeError:  # its reader went away (``| head``): the rest is not wanted, and no traceback
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


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

    from multigpu.config import DEFAULT_LIVENESS
    from multigpu.flags import dark_tiles
    from multigpu.rank.job import Interrupted, Job, collective_exit, teardown_barrier
    from multigpu.rank.tiles import tile_comm

    try:
        comm = tile_comm(MPI.COMM_WORLD, getattr(a, "wall", None), dark_tiles(a))
    except InputError as exc:  # agreed on every rank (a wall file one host cannot read): one line, all exit 2
        if MPI.COMM_WORLD.Get_rank() == 0:
            print(f"multigpu: error: {exc}", file=sys.stderr, flush=True)
        collective_exit(exits.BAD_INPUT)
    from multigpu.rank import standby

    ready = None
    try:
        go_file = standby.standing_by()
        if go_file:  # started ahead of a restart (--standby): set up, then idle until the launcher says go
            standby.warm()
            ready = standby.prepared(a, comm)
            got = standby.wait_for_go(comm, go_file)
            if got.get("quit"):
                return 0
            standby.go(a, got)
    except InputError as exc:  # the same on every rank (the same setting, the same bytes): one line, all exit 2
        if comm.Get_rank() == 0:
            print(f"multigpu: error: {exc}", file=sys.stderr, flush=True)
        collective_exit(exits.BAD_INPUT)
    job = Job(comm, liveness=a.liveness if a.liveness is not None and a.liveness >= 0 else DEFAULT_LIVENESS)
    job.catch_signals()  # SIGINT/SIGTERM: raise during setup, stop after the frame during frames
    try:
        cfg = walk_config(a)
        from multigpu.rank.walkthrough import run

        with job:
            run(cfg, comm, job, ready)
    except (InputError, WriteFailed) as exc:  # agreed on every rank: one line, all exit 2
        job.close()
        if comm.Get_rank() == 0:
            print(f"multigpu: error: {exc}", file=sys.stderr, flush=True)
        collective_exit(exits.BAD_INPUT)
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

    from multigpu.rank.composite import CorruptPiece
    from multigpu.rank.exchange import PeerTimeout
    from multigpu.rank.job import ABORT_PAUSE, FAILURE_GRACE, Interrupted, PeerFailed, PeerStalled

    rank = comm.Get_rank()
    consequence = isinstance(exc, (PeerTimeout, PeerFailed))
    corrupt = isinstance(exc, PeerFailed) and exc.kind == CorruptPiece.__name__
    if isinstance(exc, CorruptPiece) or corrupt:  # pixels that arrived wrong: bad data, exit 2
        code, text = exits.BAD_INPUT, f"multigpu: error: {exc}"
    elif isinstance(exc, Interrupted):
        code, text = exc.code, f"multigpu: {exc}; ending the job"
    elif isinstance(exc, KeyboardInterrupt):
        code, text = exits.INTERRUPTED, "multigpu: interrupted; ending the job"
    elif isinstance(exc, PeerStalled):
        code, text = exits.FAILED, f"multigpu: {exc}"
    else:
        code, text = exits.FAILED, f"multigpu: rank {rank}: {exc.__class__.__name__}: {exc}"
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
