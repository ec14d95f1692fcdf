"""Shared test setup: a per-session scene cache, so MPI tests build each scene once."""

import os
import tempfile

import pytest

os.environ.setdefault("MULTIGPU_CACHE", tempfile.mkdtemp(prefix="multigpu-cache-"))
os.environ.setdefault("LP_NUM_THREADS", "1")


def pytest_sessionstart(session):
    """Compile the frame kernel once, here (numba caches it beside the module), so the MPI
    ranks of the tests load it instead of compiling it side by side inside their timeouts."""
    from multigpu.core import kernel

    kernel.warm()


@pytest.fixture
def egl():
    """A headless GL context, or the test skipped with the reason EGL is missing."""
    from multigpu.gpu.render import EglUnavailable, create_context

    try:
        return create_context()
    except EglUnavailable as exc:
        pytest.skip(str(exc))
