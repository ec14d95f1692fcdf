"""A projector wall's outputs on the ranks (the wall file's ``mpcdi``): each rank drives the
outputs whose regions make its tile (``warp/layout.py``: one, or a block of them where the wall
has fewer ranks than regions), turning the tile it composes into the pictures its projectors show,
every frame, on its GPU (``gpu/outputs.py``): warped, blended in linear light (``--blend off``:
not) and coloured (the wall file's ``outputs``). The window shows the rank's picture (its outputs
side by side, as an X screen spanning its projectors does); rank 0 keeps every output's, gathered
beside the mosaics (``framelog.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


class Projector:
    """Rank ``rank``'s outputs of the MPCDI file ``path`` on ``ctx``, on a wall of ``grid`` ranks
    composing tiles of ``tile`` (w, h): ``colors`` the wall file's colour of each output by name,
    ``blend`` False for ``--blend off``."""

    def __init__(self, ctx, path: str, rank: int, grid: tuple[int, int], tile: tuple[int, int], colors: dict,
                 blend: bool):
        from multigpu.core.warpblend import upsample
        from multigpu.gpu.outputs import OutputPass
        from multigpu.warp import mpcdi
        from multigpu.warp.colour import read_cube
        from multigpu.warp.layout import layout, outputs_by_tile, picture_size

        buffer, outs = mpcdi.read(Path(path))
        lay = layout(path, buffer, outs, grid)
        by_name = {o.name: o for o in outs}
        everyone = outputs_by_tile(path, grid)
        self.outputs = [o for o in everyone if o.tile == rank]
        self.size = picture_size(everyone, rank)
        self.passes = []
        for p in self.outputs:
            o, color = by_name[p.name], colors.get(p.name, {})
            lut = read_cube(Path(color["lut"])) if color.get("lut") else None
            self.passes.append(OutputPass(ctx, o.size, tile, upsample(o.warp, o.size), o.alpha if blend else None,
                                          o.beta if blend else None, matrix=color.get("matrix"), lut=lut,
                                          rect=(*p.offset, *lay.region)))
        self.picture: np.ndarray | None = None  # the last frame's, row 0 at the bottom
        w, h = self.size
        self._picture = None if len(self.passes) == 1 else np.zeros((h, w, 3), dtype=np.uint8)

    def run(self, tile: np.ndarray) -> np.ndarray:
        """The rank's picture of the composed ``tile`` (both row 0 at the bottom): each output's
        at its place."""
        if self._picture is None:
            self.picture = self.passes[0].run(tile)
            return self.picture
        H = self._picture.shape[0]
        for p, gpu in zip(self.outputs, self.passes):
            (x, y), (w, h) = p.at, p.size
            self._picture[H - y - h:H - y, x:x + w] = gpu.run(tile)
        self.picture = self._picture
        return self.picture

    def release(self) -> None:
        for gpu in self.passes:
            gpu.release()
