"""Each projector output's final picture, kept with the run's mosaics (a wall file's ``mpcdi``).

For every region of the MPCDI file (``warp/mpcdi.py``) the stitched canvas is sampled through
the region's warp and blended (``core/warpblend.py``: in linear light, beta's black lift
included; ``--blend off`` leaves the blend out) and coloured (the wall file's ``outputs``: a matrix
and a ``.cube`` LUT, ``warp/colour.py``), exactly what that projector is to show, and written to
``mosaic/outputs/NAME/frame_*.png`` beside the canvas it was made from. The buffer of the file
is the whole canvas (normalized: any resolution). The sampling is set up once for the canvas.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.core.warpblend import output, upsample
from multigpu.records.mosaic import save_png
from multigpu.warp import mpcdi
from multigpu.warp.make import content_coords


class OutputPictures:
    """The outputs of an MPCDI file, ready to be made from canvases; ``colors``: each output's colour
    by name (the wall file's ``outputs``: ``matrix``, ``lut``); ``blend`` False: no blend (``--blend
    off``: each projector's whole picture, for aligning by eye)."""

    def __init__(self, path: str, colors: dict | None = None, blend: bool = True):
        from multigpu.warp.colour import apply_lut, read_cube

        _, self.outputs = mpcdi.read(Path(path))
        self.coords = [content_coords(o, upsample(o.warp, o.size)) for o in self.outputs]
        self.blend = blend
        self.colors = []
        for o in self.outputs:  # a few outputs
            c = (colors or {}).get(o.name, {})
            lut = read_cube(Path(c["lut"])) if c.get("lut") else None
            self.colors.append((c.get("matrix"), None if lut is None else (lambda v, t=lut: apply_lut(v, t))))

    def pictures(self, canvas: np.ndarray) -> list[tuple[str, np.ndarray]]:
        """(name, (h, w, 3) uint8) of every output, from ``canvas`` (top row first)."""
        out = []
        for o, coords, (matrix, signal) in zip(self.outputs, self.coords, self.colors):
            alpha = np.ones(coords.shape[:2]) if o.alpha is None or not self.blend else o.alpha
            beta = 0.0 if o.beta is None or not self.blend else o.beta
            out.append((o.name, output(canvas, coords, alpha, beta, matrix=matrix, signal=signal)))
        return out

    def write(self, folder: Path, f: int, canvas: np.ndarray) -> None:
        """Frame ``f``'s pictures under ``folder/outputs/NAME/``."""
        from multigpu.errors import WriteFailed

        for name, img in self.pictures(canvas):
            where = folder / "outputs" / name
            try:
                where.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise WriteFailed.of(where, exc) from None
            save_png(img, where / f"frame_{f:05d}.png")
