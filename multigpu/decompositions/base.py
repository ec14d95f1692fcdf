"""The decomposition contract: what every rank draws each frame and where its pixels go.

A decomposition builds itself from the configuration (``from_config``: a new one is one file
and one line in the registry), turns a frame's object rects into ``core.work.Work`` (``plan``), learns from
the measured per-rank render times if it wants to (``observe``), and says what it did
(``report``). Pure: no MPI, no GL; every rank runs its own copy on the same inputs.
"""

from __future__ import annotations

from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from multigpu.core.work import Work


@runtime_checkable
class Decomposition(Protocol):
    name: ClassVar[str]
    balanced: ClassVar[bool]  # whether ``--balance``'s strategy divides the frame (summary, title)
    depth: ClassVar[bool]  # pieces carry depth and are composited by the nearest fragment
    layers: ClassVar[int]  # how many times a rank's pieces may cover the display (the exchange's room)
    needs_coverage: bool  # whether ``plan`` wants per-object silhouette coverage

    @classmethod
    def from_config(cls, cfg, scene, balance: str, rank: int | None = None) -> "Decomposition":
        """Built from a ``WalkConfig`` (the registry's one way in: ``make_decomposition``)."""

    def plan(self, frame: int, rects: np.ndarray, tris: np.ndarray, coverage: np.ndarray | None = None) -> Work:
        """This frame's work from (N, 4) normalized object rects and (N,) triangle counts."""

    def observe(self, frame: int, work: Work, times: np.ndarray) -> None:
        """Frame ``frame``'s measured (K,) per-rank render times in ms."""

    def report(self) -> dict:
        """What it did, for summary.json."""
