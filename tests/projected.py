"""The numpy reference of a projector wall's output pictures (``core/warpblend.py``): each
output's tile cut from the stitched canvas, sampled through its warp, blended and coloured, as
the rank that drives it does on its GPU (``gpu/outputs.py``)."""

from pathlib import Path

import numpy as np

from multigpu.core.canvas import Canvas
from multigpu.core.warpblend import output, upsample
from multigpu.warp import mpcdi
from multigpu.warp.colour import apply_lut, read_cube
from multigpu.warp.layout import layout


def reference(canvas: np.ndarray, path, colors: dict | None = None, blend: bool = True) -> dict[str, np.ndarray]:
    """{name: (h, w, 3) uint8, top row first} of every output of the MPCDI file at ``path``, from
    the stitched ``canvas`` (top row first)."""
    buffer, outs = mpcdi.read(Path(path))
    lay = layout(path, buffer, outs)
    tiles = Canvas(lay.grid, lay.tile, lay.mullion).tiles()
    H = canvas.shape[0]
    out = {}
    for o, label in zip(outs, lay.labels):
        x0, y0, x1, y1 = tiles[label]
        c = (colors or {}).get(o.name, {})
        lut = read_cube(Path(c["lut"])) if c.get("lut") else None
        alpha = np.ones(o.size[::-1]) if o.alpha is None or not blend else o.alpha
        beta = 0.0 if o.beta is None or not blend else o.beta
        out[o.name] = output(canvas[H - y1:H - y0, x0:x1], upsample(o.warp, o.size), alpha, beta,
                             matrix=c.get("matrix"), signal=None if lut is None else (lambda v, t=lut: apply_lut(v, t)))
    return out
