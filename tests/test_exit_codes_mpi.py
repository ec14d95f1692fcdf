"""Exit codes through every launcher: ``launch/walkthrough``, ``python -m
multigpu.launcher.mpirun`` and raw ``mpiexec``, for MPICH and Open MPI. A bad flag gives 2, a
failing rank 1, SIGINT (Ctrl-C) 130 and SIGTERM 143, and summary.json says what happened.
Raw Open MPI ``mpiexec`` cannot carry a signal's code (it forwards Ctrl-C as SIGTERM and
returns 1 itself; docs/USAGE.md says so): our two launchers return the documented codes with
either MPI. Every job runs in its own process group under a hard timeout, killed by id.

Not every entry meets every event (``CASES``): the launchers differ in how they carry a code out
(a bad flag, a failing rank, the two signals), not in how a rank finds a corrupt piece, which
the script's entry covers: 19 jobs, not 36."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from mpirun import ROOT, SMALL

from multigpu.config import WalkConfig
from multigpu.launcher.mpirun import find_launcher, launcher_for, openmpi_on_path

pytestmark = pytest.mark.mpi
EVENTS = {"bad flag": 2, "failing rank": 1, "corrupt piece": 2, "corrupt raw piece": 2, "SIGINT": 130, "SIGTERM": 143}


@pytest.fixture(scope="module")
def launcher(request):
    if request.param == "default":
        return find_launcher()
    path = openmpi_on_path()
    if path is None:
        pytest.skip("no Open MPI mpiexec here (Debian: apt install openmpi-bin)")
    got = launcher_for(path)
    if os.path.realpath(got.path) == os.path.realpath(find_launcher().path):
        pytest.skip("the default mpiexec is Open MPI already")
    return got


def command(entry: str, launcher, args: list[str]) -> list[str]:
    if entry == "script":
        return [str(ROOT / "launch" / "walkthrough"), *args]
    if entry == "module":
        return [sys.executable, "-m", "multigpu.launcher.mpirun", "-n", "2", "walkthrough", *args]
    return launcher.command(2, ["walkthrough", *args])


def expected(entry: str, launcher, event: str) -> int:
    if entry == "raw" and launcher.flavor == "openmpi" and event.startswith("SIG"):
        return 1  # Open MPI's mpiexec returns 1 after forwarding the signal
    return EVENTS[event]


#: the (entry, event) pairs each launcher runs: every event through the script, the codes a launcher
#: carries through the module and raw mpiexec (the module wraps the script's launcher: signals only);
#: a corrupt piece is a rank's finding, not a launcher's: Open MPI runs one of the two. Open MPI's
#: module entry is the script's launcher run from Python (the default MPI's cases cover that path),
#: and its raw mpiexec's codes are its own: a failing rank, and one signal (it returns 1 for both)
PAIRS = [*(("script", e) for e in EVENTS), ("module", "SIGINT"), ("module", "SIGTERM"),
         *(("raw", e) for e in ("bad flag", "failing rank", "SIGINT", "SIGTERM"))]
OPENMPI = [p for p in PAIRS if p[0] == "script" and p[1] != "corrupt raw piece"] + [("raw", "failing rank"),
                                                                                     ("raw", "SIGTERM")]
CASES = [("default", *p) for p in PAIRS] + [("openmpi", *p) for p in OPENMPI]


@pytest.mark.parametrize(("launcher", "entry", "event"), CASES, indirect=["launcher"])
def test_exit_code(tmp_path, launcher, entry, event):
    out = tmp_path / "o"
    args = [*SMALL, "--grid", "1x2", "--tile", "64x48", "--mosaic-every", "0", "--out", str(out)]
    args += {"bad flag": ["--balance", "nope", "--frames", "5"], "failing rank": ["--frames", "100000"],
             "corrupt piece": ["--frames", "100000", "--decomposition", "db", "--exchange", "messages",
                               "--compress", "zstd"],
             # 16x16 tiles: pieces under 4 kB travel raw on a compressed link, and the fault cuts them short
             "corrupt raw piece": ["--frames", "100000", "--decomposition", "db", "--exchange", "messages",
                                   "--compress", "zstd", "--tile", "16x16"]}.get(event, ["--frames", "100000"])
    fault = {"failing rank": "1:8", "corrupt piece": "1:8:corrupt", "corrupt raw piece": "1:8:corrupt"}
    env = launcher.environ({"LP_NUM_THREADS": "1", "MULTIGPU_MPIEXEC": launcher.path,
                            **({"MULTIGPU_FAULT": fault[event]} if event in fault else {})})
    proc = subprocess.Popen(command(entry, launcher, args), cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        if event.startswith("SIG"):
            csv, t = out / "timings.csv", time.monotonic()
            while not (csv.exists() and csv.read_text().count("\n") > 1 + 2 * 10):
                assert proc.poll() is None and time.monotonic() - t < 120, proc.communicate()[1][-3000:]
                time.sleep(0.2)
            os.killpg(proc.pid, getattr(signal, event))  # as a terminal does: the whole foreground group
        _, err = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == expected(entry, launcher, event), (proc.returncode, err[-3000:])
    if event == "bad flag":
        assert err.count("--balance must be one of") == 1 and not out.exists(), err[-2000:]
        return
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and s["frames"] == s["frames_written"] > 0
    if event == "failing rank":
        # the frames every rank showed before rank 1 failed starting frame 8 (with frames in flight, fewer)
        shown = 8 - WalkConfig().latency
        assert s["frames"] == shown and "injected fault at frame 8" in s["stopped_by"], s["stopped_by"]
        assert err.count("injected fault at frame 8") == 1, err[-2000:]
    elif event.startswith("corrupt"):  # rank 0 finds frame 8's pieces from rank 1 spoilt: one line, frames before kept
        lines = [ln for ln in err.splitlines() if "frame 8: the pieces from rank 1" in ln]
        assert len(lines) == 1 and lines[0].startswith("multigpu: error: rank 0: frame 8: the pieces from rank 1: "), \
            err[-2000:]
        # every frame before it whole (frame 7's row lands as frame 8 is delivered, before its pieces are read)
        assert s["frames"] == 8 and "CorruptPiece" in s["stopped_by"], s["stopped_by"]
    else:
        seen = "SIGTERM" if launcher.flavor == "openmpi" else event  # Open MPI forwards Ctrl-C as SIGTERM
        assert s["stopped_by"] == f"signal {seen}", s["stopped_by"]
