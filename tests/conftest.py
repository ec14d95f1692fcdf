"""Shared test setup: a per-session scene cache, so MPI tests build each scene once."""

import os
import tempfile

os.environ.setdefault("MULTIGPU_CACHE", tempfile.mkdtemp(prefix="multigpu-cache-"))
os.environ.setdefault("LP_NUM_THREADS", "1")
