"""Balancing strategies behind one small interface, registered in one place.

A strategy has two hooks, like Equalizer's equalizers: ``plan`` before the frame (rects and
weights in, a ``Partition`` out) and ``observe`` after it (the measured per-rank render times,
for strategies that learn from them). Strategies are pure: no MPI, no GL.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .balance import Partition, partition, partition_tiles


@dataclass
class Strategy:
    grid: tuple[int, int]
    size: tuple[int, int]
    strips: int = 2048

    """Common configuration; subclasses add ``plan(rects, tris) -> Partition``."""

    name = "base"

    def observe(self, partition: Partition, render_ms: np.ndarray) -> None:
        """Take the frame's measured per-rank render times (ms). Default: ignore them."""


class Strips(Strategy):
    """Dong & Peng's GPU-tree strip balancer on triangle counts."""

    name = "strips"

    def plan(self, rects, tris):
        return partition(rects, tris, self.grid, self.size, self.strips)


class NoBalance(Strategy):
    """The paper's baseline: each rank renders exactly its own display tile."""

    name = "none"

    def plan(self, rects, tris):
        return partition_tiles(rects, tris, self.grid, self.size)


REGISTRY: dict[str, type[Strategy]] = {cls.name: cls for cls in (Strips, NoBalance)}


def make_strategy(name: str, grid, size, strips: int) -> Strategy:
    if name not in REGISTRY:
        raise ValueError(f"unknown balancing strategy '{name}' (known: {', '.join(REGISTRY)})")
    return REGISTRY[name](tuple(grid), tuple(size), strips)
