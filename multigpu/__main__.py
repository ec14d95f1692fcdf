"""``python -m multigpu`` (under mpiexec: ``python -m mpi4py -m multigpu walkthrough ...``)."""

import sys

from multigpu.cli import main

sys.exit(main())
