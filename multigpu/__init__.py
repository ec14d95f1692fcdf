"""multigpu: screen-partitioning load balancing for tiled multi-display walls (Dong & Peng 2019).

The pure core (``tree``, ``balance``, ``regions``, ``bounds``, ``camera``) imports neither MPI
nor GL; ``render``, ``exchange`` and ``walkthrough`` sit at the edges.
"""

import time as _time

__version__ = "0.1.0"
#: when this process imported multigpu (epoch seconds): the start of a restarted job's own time
STARTED = _time.time()
