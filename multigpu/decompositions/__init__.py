"""How one frame's work is divided, one file each behind one contract, one registry.

* ``screen``: the paper's sort-first screen partition with sort-last region exchange, around
  any balancing strategy (``--balance``);
* ``db``: sort-last database decomposition, depth-composited onto the display tiles;
* ``bins``: static bin patterns (sort-middle emulation), no balancer.

Every decomposition writes the same timing columns and composes walls bit-identical to a
one-rank render. Pure: no MPI, no GL.
"""

from __future__ import annotations

from multigpu.core.bins import PATTERNS
from multigpu.decompositions.base import Decomposition
from multigpu.decompositions.bins import Bins
from multigpu.decompositions.db import RANGES, Database
from multigpu.decompositions.screen import Screen

REGISTRY: dict[str, type] = {cls.name: cls for cls in (Screen, Database, Bins)}


def make_decomposition(name: str, grid, size, strips: int, scene, balance: str = "strips",
                       bin_size: int = 64, bin_pattern: str = "diagonal", db_ranges: str = "visible",
                       rank: int | None = None) -> Decomposition:
    """The decomposition ``name`` for a scene on a ``grid`` wall of ``size`` pixels; ``rank``
    (when given) lets a decomposition compute only what that rank draws."""
    if name == "screen":
        from multigpu.strategies import make_strategy

        return Screen(make_strategy(balance, grid, size, strips))
    if name == "db":
        return Database(grid, size, scene.centers, scene.tris, db_ranges)
    if name == "bins":
        return Bins(grid, size, bin_size, bin_pattern, rank)
    raise ValueError(f"unknown decomposition '{name}' (known: {', '.join(REGISTRY)})")


__all__ = ["REGISTRY", "PATTERNS", "RANGES", "Decomposition", "Screen", "Database", "Bins", "make_decomposition"]
