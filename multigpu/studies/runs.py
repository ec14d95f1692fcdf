"""What the experiments share: their settings, the walkthrough jobs they launch (each under a
hard timeout, through ``launcher.mpirun``: ``walk``, ``job`` and, for a job watched while it runs,
``start``; no study starts a job another way), reading a run's timings back, the paper's figures
quoted for comparison, and the matplotlib setup.

Figures and what they are (see records/report.py): component columns are wall-clock means per
rank; "emulated" figures use each rank's process CPU time and take the slowest rank per frame,
the frame time the run would have with one core (GPU) per rank. Ranks outnumber cores here, so
speedups and efficiencies are computed from emulated figures only.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multigpu.errors import InputError
from multigpu.launcher.mpirun import JobTimeout, run_multigpu
from multigpu.records.report import COLUMNS, read_timings


def study_env() -> dict:
    """The environment every study job runs with: one llvmpipe raster thread per rank at any
    rank count (unless ``LP_NUM_THREADS`` is set), so 1-rank and K-rank CPU times compare like
    with like. A plain walkthrough lets each rank choose (``gpu.render.raster_threads``)."""
    return {"LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS", "1")}


# Dong & Peng 2019, Section 7 (quoted for comparison, not measured here)
PAPER = {
    "balance_speedup": 20.95 / 15.95,  # Fig. 7: mean FPS with / without balancing
    "gpus_frame_ms_1": 52.36,  # Table 1: one GPU, 6 power plants
    "gpus_frame_ms_4": 31.89,  # Table 1: four GPUs
    "balancer_share_max": 0.13,  # Fig. 8: balancer at most 13 % of the frame
    "triangles": 254_000_000,
}


@dataclass
class Settings:
    """Sizes of one experiment run; ``quick`` shrinks everything for smoke tests."""

    quick: bool = False
    triangles: int = 100_000  # one plant (the CLI's default scene)
    frames: int = 240  # camera path frames per run (the path is resampled, not cut)
    copies: tuple[int, ...] = (1, 2, 3, 4)
    resolutions: tuple[int, ...] = (512, 1024, 2048, 4096)
    res_frames: int = 40
    strip_frames: int = 120
    timeout: int = 900  # seconds per mpiexec job
    strategies: tuple[str, ...] = field(default_factory=tuple)
    rounds: int | None = None  # alternated rounds of the experiments that repeat runs (None: each one's own)

    def repeat(self, default: int) -> int:
        """Alternated rounds for an experiment whose own number is ``default`` (1 when quick)."""
        return self.rounds or (1 if self.quick else default)

    @classmethod
    def make(cls, quick: bool, rounds: int | None = None) -> "Settings":
        from multigpu.strategies import REGISTRY

        if rounds is not None and rounds < 1:
            raise InputError.of("rounds", f"must be at least 1, got {rounds}")
        s = cls(quick=quick, strategies=tuple(REGISTRY), rounds=rounds)
        if quick:  # a smoke run: every experiment's path through the pipeline, at a fraction of its runs
            from multigpu.config import WalkConfig

            keep = {"strips", "cost", WalkConfig().balance, "none"}  # the paper's, the tables', the default, the base
            s.strategies = tuple(n for n in REGISTRY if n in keep)
            s.triangles, s.frames, s.copies = 20_000, 12, (1,)
            s.resolutions, s.res_frames, s.strip_frames, s.timeout = (128, 256), 6, 8, 240
        return s


@dataclass
class Run:
    """One finished walkthrough job: its summary and its per-(frame, rank) timing rows."""

    summary: dict
    rows: np.ndarray  # (F, K, C) complete frames only
    out: Path

    def col(self, name: str) -> np.ndarray:
        return self.rows[:, :, COLUMNS.index(name)]

    @property
    def emulated(self) -> np.ndarray:
        """Per frame, the emulated parallel frame (the slowest rank's CPU time over the phases)."""
        cpu = ("load_balancing_cpu_ms", "rendering_cpu_ms", "frame_exchange_cpu_ms", "display_cpu_ms")
        return sum(self.col(c) for c in cpu).max(axis=1)

    @property
    def render_max_cpu(self) -> np.ndarray:
        """Per frame, the slowest rank's rendering CPU time (the emulated render component)."""
        return self.col("rendering_cpu_ms").max(axis=1)


def walk(out: Path, grid: tuple[int, int], tile: tuple[int, int] | None, args: list[str], timeout: float,
         env: dict | None = None, launcher=None, as_run: bool = False,
         hosts: list[tuple[str, int]] | None = None, ranks: int | None = None) -> Run:
    """Run ``multigpu walkthrough`` on ``rows*cols`` ranks into ``out``, in the studies'
    environment (``study_env``; ``as_run``: the walkthrough's own, each rank choosing its raster
    threads as a user's run does, for studies of what a user's wall time is; ``env`` over either)
    under ``launcher`` (None: the one found), on ``hosts`` [(host, ranks)] where given (simulated
    hosts: ``simhosts.py``); kill it on timeout; ``tile`` None: the wall file in ``args`` gives the
    grid and tile; ``ranks``: the job's, where not a rank a tile (``--eyes own``). Every study's
    walkthrough job goes through here."""
    import json

    k = ranks or grid[0] * grid[1]
    out.mkdir(parents=True, exist_ok=True)
    shape = [] if tile is None else ["--grid", f"{grid[0]}x{grid[1]}", "--tile", f"{tile[0]}x{tile[1]}"]
    args = ["walkthrough", *shape, "--out", str(out), "--no-progress", *args]
    try:
        done = job(k, args, timeout, env={**({} if as_run else study_env()), **(env or {})}, launcher=launcher,
                   merge_stderr=True, hosts=hosts)
    except JobTimeout:
        raise RuntimeError(f"experiment job timed out after {timeout} s: multigpu {' '.join(args)}") from None
    log = done.stdout
    (out / "log.txt").write_text(log)
    if done.returncode != 0:
        tail = "\n".join(log.strip().splitlines()[-5:])
        raise RuntimeError(f"experiment job failed (exit {done.returncode}): multigpu {' '.join(args)}\n{tail}")
    summary = json.loads((out / "summary.json").read_text())
    rows = read_timings(out / "timings.csv")
    rows = rows[np.lexsort((rows[:, 1], rows[:, 0]))]
    frames = rows.shape[0] // k
    return Run(summary, rows[: frames * k].reshape(frames, k, len(COLUMNS)), out)


def job(ranks: int, args: list[str], timeout: float, env: dict | None = None, launcher=None,
        merge_stderr: bool = False, hosts: list[tuple[str, int]] | None = None) -> subprocess.CompletedProcess:
    """A multigpu job of ``ranks`` ranks (``args``: its command line after ``multigpu``) under the
    MPI's mpiexec (on ``hosts`` where given), waited for and killed whole after ``timeout`` s."""
    return run_multigpu(ranks, args, timeout, env=env, launcher=launcher, merge_stderr=merge_stderr, hosts=hosts)


def alternated(arms, rounds: int, one) -> dict:
    """``one(arm, folder)`` for every arm in every round, the order rotating each round (a shared
    machine's drift falls alike on every arm), each run in a folder of its own that goes
    afterwards: each arm's results, round by round."""
    import tempfile

    got: dict = {a: [] for a in arms}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            k = r % len(arms)
            for arm in (*arms[k:], *arms[:k]):
                got[arm].append(one(arm, Path(tmp) / f"{arm}-{r}"))
    return got


def medians(results: list[dict]) -> dict:
    """Each figure's median over the rounds' results."""
    return {k: float(np.median([x[k] for x in results])) for k in results[0]}


def start(ranks: int, args: list[str], env: dict | None = None, as_users: bool = False,
          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) -> subprocess.Popen:
    """A multigpu job started in a session of its own, returned at once, for a study that watches
    it run (memory, a long run, recovery): under the MPI's mpiexec, or (``as_users``) as users
    start it, through ``python -m multigpu.launcher.mpirun`` (which supervises and recovers).
    ``env`` goes over this process's environment; ``end`` stops what is left of it."""
    from multigpu.launcher.mpirun import find_launcher

    if as_users:
        cmd, job_env = [sys.executable, "-m", "multigpu.launcher.mpirun", "-n", str(ranks), *args], {
            **os.environ, **(env or {})}
    else:
        launcher = find_launcher()
        job_env = launcher.environ(env)
        cmd = launcher.command(ranks, args, env=job_env)
    return subprocess.Popen(cmd, env=job_env, stdout=stdout, stderr=stderr, text=True, start_new_session=True)


def end(proc: subprocess.Popen) -> None:
    """Stop what is left of a job ``start`` made (its whole session)."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(30)


def _scene_args(s: Settings, copies: int = 1) -> list[str]:
    """``copies`` plants side by side, each of ``s.triangles`` (so the scene grows with copies)."""
    return ["--triangles", str(s.triangles * copies), "--copies", str(copies)]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _breakdown(run: Run) -> dict:
    s = run.summary
    w = s["wall"]
    return {
        "lb_ms": w["load_balancing_ms"], "render_ms": w["rendering_ms"], "sync_ms": w["synchronization_ms"],
        "exchange_ms": w["frame_exchange_ms"], "display_ms": w["display_ms"], "frame_ms": s["frame_ms"],
        "fps": s["fps"], "lb_cpu_ms": s["cpu"]["load_balancing_cpu_ms"],
        "render_cpu_max_ms": s["render_cpu_max_ms"], "exchange_cpu_ms": s["cpu"]["frame_exchange_cpu_ms"],
        "emulated_ms": s["emulated_frame_ms"], "emulated_fps": s["emulated_fps"],
        "imb_tris": s["imbalance_triangles"], "imb_render": s["imbalance_render_cpu"],
        "bytes_per_frame": s["bytes_sent_per_frame"],
    }


BREAKDOWN_COLS = [("lb_ms", "LB", ".2f"), ("render_ms", "Render", ".2f"), ("sync_ms", "Sync", ".2f"),
                  ("exchange_ms", "Exchange", ".2f"), ("display_ms", "Display", ".2f"),
                  ("frame_ms", "Frame (wall)", ".2f"), ("fps", "FPS (wall)", ".1f"),
                  ("emulated_ms", "Frame (emulated)", ".2f"), ("emulated_fps", "FPS (emulated)", ".1f")]


# --------------------------------------------------------------------------- experiments
