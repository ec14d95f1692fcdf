"""A fill-bound scene: few huge overlapping panels beside a compact triangle-heavy cluster.

The paper's balancer counts triangles, which is right for the plant (many small objects) and
wrong here: ``panels`` large thin boxes stand one behind the other over the west half of the
ground (a few dozen triangles in all, but each covers a large part of the screen, so the
depth complexity there reaches ``panels``), while the east half holds a dense cluster of
small high-poly spheres carrying almost every triangle and few pixels. Balancing triangles
gives the panel side one big region whose rank then fills millions of fragments.
"""

from __future__ import annotations

import numpy as np

from multigpu.scene.layout import Scene, assemble
from multigpu.scene.plant import box, instance, uv_sphere, z_rotation


def generate_fill(triangles: int, panels: int = 24, seed: int = 0) -> Scene:
    """``panels`` screen-filling panels (x < 50) and about ``triangles`` triangles of spheres
    (x > 60) on a 100 x 100 ground, z up."""
    if triangles < 1000:
        raise ValueError(f"fill scene triangles must be >= 1000, got {triangles}")
    if panels < 1:
        raise ValueError(f"fill scene panels must be >= 1, got {panels}")
    rng = np.random.default_rng(seed)
    x = np.linspace(4, 46, panels)
    scale = np.c_[np.full(panels, 0.3), np.full(panels, 90.0), np.full(panels, 40.0)]
    offset = np.c_[x, np.full(panels, 50.0), np.full(panels, 20.0)]
    shade = np.linspace(0.35, 0.85, panels)
    walls = instance(box(), scale, z_rotation(np.zeros(panels)), offset, np.c_[shade, shade * 0.6, 0.3 + 0 * shade])
    seg = 24
    sph = uv_sphere(seg, seg // 2)
    per = seg * (seg // 2) * 2
    n = max(1, int(triangles // per))
    centers = np.c_[rng.uniform(66, 94, n), rng.uniform(30, 70, n), rng.uniform(2, 18, n)]
    radius = rng.uniform(0.6, 1.4, n)
    balls = instance(sph, np.repeat(radius[:, None], 3, 1), z_rotation(rng.uniform(0, np.pi, n)), centers,
                     rng.uniform(0.3, 0.9, (n, 3)))
    meta = {"generator": "fill", "triangles": int(triangles), "panels": int(panels), "seed": int(seed), "up": [0, 0, 1]}
    return assemble([walls, balls], f"fill-{triangles}-p{panels}-s{seed}", meta)
