"""The projector a configuration names: object bounds as boxes (8 corners, ``bounds``) or as
spheres (``spheres``), prepared once per scene for per-frame projection."""

from __future__ import annotations

import numpy as np

from multigpu.core.bounds import BoxProjector
from multigpu.core.spheres import SphereProjector


def make_projector(scene, kind: str = "box", dtype=np.float32) -> BoxProjector | SphereProjector:
    """A scene's bounds prepared once for per-frame projection: ``box`` (8 corners) or ``sphere``."""
    if kind == "sphere":
        return SphereProjector(scene.centers, scene.radii)
    if kind == "box":
        return BoxProjector(scene.bmin, scene.bmax, dtype)
    raise ValueError(f"bounds must be 'box' or 'sphere', got '{kind}'")
