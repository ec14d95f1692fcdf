"""multigpu: screen-partitioning load balancing for tiled multi-display walls (Dong & Peng 2019).

The pure core (``tree``, ``balance``, ``regions``, ``bounds``, ``camera``) imports neither MPI
nor GL; ``render``, ``exchange`` and ``walkthrough`` sit at the edges.
"""

__version__ = "0.1.0"
