"""The test run itself: a SIGTERM ends it as Ctrl-C does, with the running test cleaned up."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def test_a_sigterm_ends_the_run_and_the_running_test_cleans_up(tmp_path):
    """A child pytest with this suite's conftest, stopped by SIGTERM in the middle of a test:
    the test's ``finally`` runs (where the MPI, X and namespace tests kill what they started)
    and the run exits non-zero. With Python's default SIGTERM the child dies with no cleanup."""
    started, cleaned = tmp_path / "started", tmp_path / "cleaned"
    (tmp_path / "test_child.py").write_text(
        "import pathlib, time\n\n\n"
        "def test_waits():\n"
        "    try:\n"
        f"        pathlib.Path({str(started)!r}).write_text('1')\n"
        "        time.sleep(120)\n"
        "    finally:\n"
        f"        pathlib.Path({str(cleaned)!r}).write_text('1')\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])}
    child = subprocess.Popen([sys.executable, "-m", "pytest", "-q", "-p", "conftest", "-p", "no:cacheprovider",
                              "test_child.py"], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not started.exists() and child.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert started.exists(), child.communicate(timeout=30)[0].decode()
        child.send_signal(signal.SIGTERM)
        out = child.communicate(timeout=60)[0].decode()
    finally:
        if child.poll() is None:
            os.killpg(child.pid, signal.SIGKILL)
            child.wait()
    assert cleaned.exists(), out
    assert child.returncode != 0, out
