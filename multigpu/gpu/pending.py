"""A submitted frame's pixels, read when they are needed (``render.RegionRenderer.submit``)."""

from __future__ import annotations

import numpy as np


class Pending:
    """A submitted frame's pieces: already read (``done``), or drawn into ``fbo`` at ``drawn``
    (x, y, w, h) and read on ``read`` (waiting for the GL to finish drawing them)."""

    def __init__(self, done: list | None, fbo=None, drawn: list | None = None, depth: bool = False):
        self.done, self.fbo, self.drawn, self.depth = done, fbo, drawn, depth

    def read(self) -> list:
        """Every piece as ``(rgb, depth or None)``, row 0 at the bottom (as ``render``)."""
        if self.done is None:
            out = []
            for x, y, w, h in self.drawn:  # pieces, not objects
                rgb = np.empty((h, w, 3), dtype=np.uint8)
                self.fbo.read_into(rgb, viewport=(x, y, w, h), components=3, alignment=1)
                z = None
                if self.depth:
                    z = np.empty((h, w), dtype=np.float32)
                    self.fbo.read_into(z, viewport=(x, y, w, h), components=1, attachment=-1, dtype="f4", alignment=1)
                out.append((rgb, z))
            self.done, self.fbo = out, None
        return self.done


def _disjoint(rects: list) -> bool:
    """Whether no two of the ``[x0, y0, x1, y1)`` rects overlap (pieces, a handful a rank)."""
    r = np.asarray(rects, dtype=np.int64).reshape(-1, 4)
    if len(r) < 2:
        return True
    apart = ((r[:, None, 2] <= r[None, :, 0]) | (r[None, :, 2] <= r[:, None, 0]) |
             (r[:, None, 3] <= r[None, :, 1]) | (r[None, :, 3] <= r[:, None, 1]))
    np.fill_diagonal(apart, True)
    return bool(apart.all())
