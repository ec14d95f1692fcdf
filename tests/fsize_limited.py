"""Run ``python -m mpi4py ARGS`` with a file-size limit set after MPI started (its own shared
memory files need room): ``python tests/fsize_limited.py BYTES -m multigpu ...``. Writes past
the limit fail with EFBIG, as writes to a full disk fail with ENOSPC."""

import resource
import sys

from mpi4py import MPI  # noqa: F401  -- initialize MPI before the limit
from mpi4py.run import main

limit = int(sys.argv.pop(1))
resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
main()
