"""Shared test setup: a per-session scene cache, so MPI tests build each scene once."""

import os
import signal
import tempfile
import threading

import pytest

os.environ.setdefault("MULTIGPU_CACHE", tempfile.mkdtemp(prefix="multigpu-cache-"))
os.environ.setdefault("LP_NUM_THREADS", "1")


def _interrupt(signum, frame):
    raise KeyboardInterrupt(f"stopped by signal {signal.Signals(signum).name}")


def pytest_configure(config):
    """A SIGTERM (CI's ``timeout``, a user's ``kill``) ends the run as Ctrl-C does: the running
    test's ``with`` blocks, ``finally`` clauses and fixtures tear down, so the mpiexec jobs, X
    servers and namespaces it started are killed by id, not left running (Python's default
    SIGTERM ends the process with no cleanup at all). A handler someone else set is kept."""
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _interrupt)


def pytest_sessionstart(session):
    """Compile the frame kernel once, here (numba caches it beside the module), so the MPI
    ranks of the tests load it instead of compiling it side by side inside their timeouts."""
    from multigpu import kernels

    kernels.warm()


@pytest.fixture
def egl():
    """A headless GL context, or the test skipped with the reason EGL is missing."""
    from multigpu.gpu.render import EglUnavailable, create_context

    try:
        return create_context()
    except EglUnavailable as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="module")
def ctx():
    """A headless GL context shared by a module's tests, or the tests skipped (EGL missing)."""
    from multigpu.gpu.render import EglUnavailable, create_context

    try:
        return create_context()[0]
    except EglUnavailable as exc:
        pytest.skip(str(exc))
