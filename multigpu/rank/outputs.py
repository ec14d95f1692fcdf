"""A projector wall's outputs on the ranks (the wall file's ``mpcdi``): each rank drives the
output whose region is its tile (``warp/layout.py``), turning the tile it composes into the
picture its projector shows, every frame, on its GPU (``gpu/outputs.py``): warped, blended in
linear light (``--blend off``: not) and coloured (the wall file's ``outputs``). The window shows
that picture; rank 0 keeps every output's, gathered beside the mosaics (``framelog.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


class Projector:
    """Rank ``rank``'s output of the MPCDI file ``path`` on ``ctx``, from tiles of ``tile`` (w, h):
    ``colors`` the wall file's colour of each output by name, ``blend`` False for ``--blend off``."""

    def __init__(self, ctx, path: str, rank: int, tile: tuple[int, int], colors: dict, blend: bool):
        from multigpu.core.warpblend import upsample
        from multigpu.gpu.outputs import OutputPass
        from multigpu.warp import mpcdi
        from multigpu.warp.colour import read_cube
        from multigpu.warp.layout import Projected, layout

        buffer, outs = mpcdi.read(Path(path))
        o = outs[layout(path, buffer, outs).labels.index(rank)]
        self.output = Projected(o.name, o.size)
        color = colors.get(o.name, {})
        lut = read_cube(Path(color["lut"])) if color.get("lut") else None
        self.gpu = OutputPass(ctx, o.size, tile, upsample(o.warp, o.size), o.alpha if blend else None,
                              o.beta if blend else None, matrix=color.get("matrix"), lut=lut)
        self.picture: np.ndarray | None = None  # the last frame's, row 0 at the bottom

    def run(self, tile: np.ndarray) -> np.ndarray:
        """The output's picture of the composed ``tile`` (both row 0 at the bottom)."""
        self.picture = self.gpu.run(tile)
        return self.picture

    def release(self) -> None:
        self.gpu.release()
