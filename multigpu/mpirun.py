"""Start ``multigpu`` under ``mpiexec`` from Python, always bounded and always cleaned up.

Used by the experiments and by the tests: the job runs in its own process group, which is
killed whole (launcher and every rank) when it outlives its timeout.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

from .errors import InputError


class JobTimeout(RuntimeError):
    """The job outlived its timeout and was killed; ``stdout``/``stderr`` hold what it wrote."""

    def __init__(self, message: str, stdout: str, stderr: str):
        super().__init__(message)
        self.stdout, self.stderr = stdout, stderr


def mpiexec() -> str:
    """The ``mpiexec`` beside this interpreter (the mpich wheel's), else the one on PATH."""
    here = Path(sys.executable).parent
    found = shutil.which("mpiexec", path=f"{here}{os.pathsep}{os.environ.get('PATH', '')}")
    if not found:
        raise InputError("mpiexec not found: install MPI (pip install mpich) or put mpiexec on PATH")
    return found


def run_multigpu(n: int, args: list[str], timeout: float, env: dict | None = None, cwd=None,
                 merge_stderr: bool = False) -> subprocess.CompletedProcess:
    """``mpiexec -n n python -m mpi4py -m multigpu ARGS`` with ``LP_NUM_THREADS=1`` unless set."""
    cmd = [mpiexec(), "-n", str(n), sys.executable, "-m", "mpi4py", "-m", "multigpu", *args]
    full_env = {**os.environ, "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS", "1"), **(env or {})}
    proc = subprocess.Popen(cmd, cwd=cwd, env=full_env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT if merge_stderr else subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        raise JobTimeout(f"mpiexec timed out after {timeout} s: {' '.join(cmd)}", out or "", err or "") from None
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err or "")
