"""Choosing each object's level of detail for a frame: the coarsest whose error stays under a bound
in pixels where the object is seen.

A level's geometric error ``e`` (world units, ``scene/lod.py``) seen at distance ``d`` covers at
most ``e * focal / d`` pixels of the canvas, ``focal`` = canvas height / (2 tan(fov / 2)). The
distance taken is the nearest the object's bounding sphere comes to the eye (at least the near
plane), so the bound holds for every point of the object, wherever the screen cuts it. One
vectorised pass over the objects; every rank computes the same levels from the same camera.
Pure numpy.
"""

from __future__ import annotations

import math

import numpy as np

from multigpu.core import jit
from multigpu.core.camera import Camera


class LevelChooser:
    """The per-frame level choice for one scene (its spheres and level errors, prepared once)."""

    def __init__(self, scene, height: int):
        self.centers = np.ascontiguousarray(scene.centers, dtype=np.float64)
        self.radii = np.asarray(scene.radii, dtype=np.float64)
        self.height = int(height)
        have = scene.lod_error is not None
        self.error = np.ascontiguousarray(scene.lod_error if have else np.zeros((scene.n_objects, 1)), dtype=np.float64)
        count = scene.lod_count if have else scene.index_count[:, None]
        self.tris = np.ascontiguousarray(count, dtype=np.int64) // 3  # (N, L) triangles of each level
        self._rows = np.arange(scene.n_objects)
        # the objects with a coarser level: the only ones a frame chooses for (the city: two in five)
        self.which = np.flatnonzero(np.isfinite(self.error[:, 1])) if self.levels > 1 else np.zeros(0, np.int64)
        self._out = None  # the kernel's output arrays, reused every frame (valid until the next choice)
        self._entry = None  # the kernel's compiled entry point (``jit.entry``): no type dispatch per frame

    @property
    def levels(self) -> int:
        return int(self.error.shape[1])

    def pixels_per_unit(self, camera: Camera) -> np.ndarray:
        """(N,) how many canvas pixels one world unit at each object's nearest point covers at most."""
        focal = self.height / (2.0 * math.tan(math.radians(camera.fov) / 2.0))
        eye = np.asarray(camera.position, dtype=np.float64)
        d = np.sqrt(((self.centers - eye) ** 2).sum(axis=1)) - self.radii
        return focal / np.maximum(d, max(float(camera.near), 1e-12))

    def choose(self, camera: Camera, bound_px: float, rects: np.ndarray | None = None, compiled: bool | None = None
               ) -> tuple[np.ndarray | None, np.ndarray]:
        """((N,) int8 levels, (N,) int64 triangles drawn at them); levels None where every object
        is at level 0 (a bound of 0, or a scene without levels): the draw path of a run without
        levels. ``rects``: the frame's (N, 4) object rects, NaN where unseen: an unseen object
        is drawn by no rank and keeps level 0 unchosen. ``compiled``: the one-pass kernel
        (``lod_kernel.py``) where numba is installed (None), or this numpy reference (False)."""
        if bound_px <= 0 or self.levels == 1:
            return None, self.tris[:, 0]
        seen = np.ones((len(self.radii), 1)) if rects is None else np.ascontiguousarray(rects[:, :1], dtype=np.float64)
        if jit.use(compiled):
            from multigpu.core.lod_kernel import _choose

            if self._out is None:  # the others stay at level 0 for good
                self._out = (np.zeros(len(self.radii), dtype=np.int8), self.tris[:, 0].copy())
            levels, drawn = self._out
            ex, ey, ez = (float(v) for v in camera.position)
            focal = self.height / (2.0 * math.tan(math.radians(camera.fov) / 2.0))
            args = (self.centers, self.radii, self.error, self.tris, seen, self.which, ex, ey, ez, focal,
                    max(float(camera.near), 1e-12), float(bound_px), levels, drawn)
            if self._entry is None:
                self._entry = jit.entry(_choose, args)
            coarse = self._entry(*args)
            return (levels, drawn) if coarse else (None, self.tris[:, 0])
        px = self.error * self.pixels_per_unit(camera)[:, None]  # (N, L) non-decreasing along each row
        levels = ((px <= bound_px).sum(axis=1) - 1).astype(np.int8)  # level 0's error is 0: always within
        levels[np.isnan(seen[:, 0])] = 0
        if not levels.any():
            return None, self.tris[:, 0]
        return levels, self.tris[self._rows, levels]
