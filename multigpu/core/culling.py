"""Sub-object culling: of the objects a region needs, only the parts whose bounds reach it.

The balancer hands a rank whole objects (every object whose rect touches its region), and an
object of thousands of triangles that a region only grazes would be drawn whole. A scene whose
objects are cut into parts (``scene/parts.py``) keeps each part's bounding box: once a frame the
parts of cut objects are projected (the compiled box projection, conservative as the objects'),
and for each region a part is drawn only where its pixel span touches the region, by the same
rule that gives the objects' masks (``regions.pixel_spans`` and ``overlaps``). A part culled
this way has no pixel in the region, so the region's pixels are the same as drawing the whole
object (tests/test_culling.py against a per-triangle reference, and the composites against one
rank). Parts of objects kept whole follow their object. Pure numpy and the compiled projector.
"""

from __future__ import annotations

import numpy as np

from multigpu.core import jit
from multigpu.core.bounds import BoxProjector
from multigpu.core.culling_kernel import _seen
from multigpu.core.regions import overlaps, pixel_spans


class PartCuller:
    """The parts of a scene's cut objects, projected once a frame and tested per region."""

    def __init__(self, scene, compiled: bool | None = None):
        n = np.diff(scene.part_start)
        self.compiled = jit.use(compiled)  # the per-region test compiled (one pass) or numpy's
        self.cut = np.flatnonzero(np.repeat(n > 1, n))  # the part rows of objects cut into parts
        self.project = BoxProjector(scene.part_bmin[self.cut], scene.part_bmax[self.cut], compiled=compiled)
        self.out = np.ones(int(scene.part_start[-1]), dtype=bool)  # parts of objects kept whole stay True
        self.rects = np.zeros((0, 4))
        self.size = (1, 1)

    def place(self, center: np.ndarray, half: np.ndarray) -> None:
        """Every part's moved box: (3, P) centres and half extents (``core.motion.Posed``)."""
        self.project.place(center[:, self.cut], half[:, self.cut])

    def frame(self, view: np.ndarray, proj: np.ndarray, size: tuple[int, int]) -> None:
        """Project the cut objects' parts for this frame's camera on a ``size`` canvas."""
        self.rects, self.size = self.project(view, proj), (int(size[0]), int(size[1]))

    def seen(self, region) -> np.ndarray:
        """(P,) bool in scene part order: the parts that may have a pixel in ``region`` (the
        parts of objects kept whole: all; their object's mask decides). One array, rewritten
        by the next call: use it before asking for another region."""
        x0, y0, x1, y1 = (int(v) for v in region)
        if self.compiled:
            _seen(np.ascontiguousarray(self.rects.T), float(self.size[0]), float(self.size[1]), x0, y0, x1, y1,
                  self.cut, self.out)
            return self.out
        spans, onscreen = pixel_spans(self.rects, self.size)
        self.out[self.cut] = onscreen & overlaps(spans, (x0, y0, x1, y1))
        return self.out
