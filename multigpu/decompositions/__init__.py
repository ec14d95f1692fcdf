"""How one frame's work is divided, one file each behind one contract, one registry.

* ``screen``: the paper's sort-first screen partition with sort-last region exchange, around
  any balancing strategy (``--balance``);
* ``db``: sort-last database decomposition, depth-composited onto the display tiles;
* ``bins``: static bin patterns (sort-middle emulation), no balancer;
* ``hybrid``: the screen partition for most objects, the wide ones drawn once, depth-composited.

Every decomposition writes the same timing columns and composes walls bit-identical to a
one-rank render. Pure: no MPI, no GL.
"""

from __future__ import annotations

from multigpu.core.bins import PATTERNS
from multigpu.decompositions.base import Decomposition
from multigpu.decompositions.bins import Bins
from multigpu.decompositions.db import RANGES, Database
from multigpu.decompositions.hybrid import Hybrid
from multigpu.decompositions.screen import Screen

REGISTRY: dict[str, type] = {cls.name: cls for cls in (Screen, Database, Bins, Hybrid)}


def make_decomposition(cfg, scene, balance: str | None = None, rank: int | None = None) -> Decomposition:
    """The decomposition ``cfg.decomposition`` built from the configuration (a ``WalkConfig``:
    grid, visible size, strips and the decomposition's own settings) for ``scene``, balancing
    with ``balance`` (default ``cfg.balance``) where it balances; ``rank`` (when given) lets a
    decomposition compute only what that rank draws."""
    if cfg.decomposition not in REGISTRY:
        raise ValueError(f"unknown decomposition '{cfg.decomposition}' (known: {', '.join(REGISTRY)})")
    return REGISTRY[cfg.decomposition].from_config(cfg, scene, balance or cfg.balance, rank)


__all__ = ["REGISTRY", "PATTERNS", "RANGES", "Decomposition", "Screen", "Database", "Bins", "Hybrid",
           "make_decomposition"]
