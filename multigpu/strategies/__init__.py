"""Balancing strategies: one file each behind one contract (``base.Strategy``), one registry.

The registry is the single list the CLI's ``--balance`` help, the configuration's validation
and the tests that loop over every strategy read (as IceT's ``select.c`` and its tests do).
"""

from __future__ import annotations

from multigpu.strategies.adaptive import Adaptive
from multigpu.strategies.auto import Auto
from multigpu.strategies.base import Configured, Strategy, rank_pixels
from multigpu.strategies.cost import CostModel
from multigpu.strategies.cross import CrossSegment
from multigpu.strategies.none import NoBalance
from multigpu.strategies.shares import Shares
from multigpu.strategies.static import Static
from multigpu.strategies.strips import Strips
from multigpu.strategies.time import TimeFeedback

REGISTRY: dict[str, type] = {cls.name: cls for cls in (Strips, CostModel, TimeFeedback, Adaptive, CrossSegment,
                                                      Shares, Auto, NoBalance, Static)}


def describe() -> str:
    """Every strategy as ``name: summary`` (its one plain line), for --help."""
    return "; ".join(f"{name}: {cls.summary}" for name, cls in REGISTRY.items())


def make_strategy(name: str, grid, size, strips: int) -> Strategy:
    if name not in REGISTRY:
        raise ValueError(f"unknown balancing strategy '{name}' (known: {', '.join(REGISTRY)})")
    return REGISTRY[name](tuple(grid), tuple(size), strips)


__all__ = ["REGISTRY", "Strategy", "Configured", "make_strategy", "describe", "rank_pixels",
           "Strips", "CostModel", "TimeFeedback", "Adaptive", "CrossSegment", "Shares", "Auto", "NoBalance",
           "Static"]
