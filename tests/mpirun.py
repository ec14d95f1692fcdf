"""Run multigpu under mpiexec from tests: always under a hard timeout, always cleaned up."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np

from multigpu.launcher.mpirun import JobTimeout, find_launcher, launcher_for, openmpi_on_path, run_multigpu

ROOT = Path(__file__).resolve().parents[1]
SMALL = ["--triangles", "20000", "--no-progress"]


def start_mpi(n: int, args: list[str], env: dict | None = None, launcher=None, hosts=None):
    """A job in its own process group (for signal tests); returns (proc, kill)."""
    import os
    import signal
    import subprocess

    launcher = launcher or find_launcher()
    job_env = launcher.environ({"LP_NUM_THREADS": "1", **(env or {})})
    proc = subprocess.Popen(launcher.command(n, args, hosts=hosts, env=job_env), cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True, env=job_env)
    return proc, lambda: os.killpg(proc.pid, signal.SIGKILL)


def run_mpi(n: int, args: list[str], timeout: float = 120, env: dict | None = None, launcher=None, hosts=None):
    """``mpiexec -n n python -m mpi4py -m multigpu ARGS`` (on ``hosts`` [(host, slots)] when
    given); the whole process group is killed on timeout."""
    try:
        return run_multigpu(n, args, timeout, env={"LP_NUM_THREADS": "1", **(env or {})}, cwd=ROOT,
                            launcher=launcher, hosts=hosts)
    except JobTimeout as exc:
        raise AssertionError(f"{exc}\n{exc.stderr[-2000:]}") from None


def start_launcher(args: list[str], env: dict) -> subprocess.Popen:
    """``python -m multigpu.launcher.mpirun ARGS`` as a user starts it (its own process group,
    output captured), ``env`` over this process's environment."""
    return subprocess.Popen([sys.executable, "-m", "multigpu.launcher.mpirun", *args], cwd=ROOT,
                            env={**os.environ, **env}, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def end_launcher(proc: subprocess.Popen, timeout: float = 120) -> tuple[str, str]:
    """Its output once it ends; its whole process group killed if it outlives ``timeout``."""
    try:
        return proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()


def read_png(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"))


def mpi_named(which: str):
    """The launcher of ``which`` MPI (``mpich``: the default mpiexec, which must be MPICH;
    ``openmpi``), or the test skipped with the reason it is not here."""
    import pytest

    if which == "mpich":
        got = find_launcher()
        if got.flavor == "mpich":
            return got
        wheel = Path(sys.executable).parent / "mpiexec"  # the mpich wheel's, beside a default Open MPI
        if wheel.exists() and launcher_for(str(wheel)).flavor == "mpich":
            return launcher_for(str(wheel))
        pytest.skip(f"the default mpiexec is {got.flavor} and no MPICH is installed (pip install mpich)")
    path = openmpi_on_path()
    if path is None:
        pytest.skip("no Open MPI mpiexec here (Debian: apt install openmpi-bin)")
    return launcher_for(path)
