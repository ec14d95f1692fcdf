"""A bare warp and blend, as nDisplay takes them: a PFM warp grid beside its alpha (and beta) PNG.

The PFM is read as MPCDI's geometry warp (output-to-content, normalized: x right, y down across
the content, NaN where the output shows nothing; ``pfm.py``), the PNGs as MPCDI's maps (linear
after ``gamma_embedded`` is taken off; resampled, and said so, where their size is not the
output's). The output's content is the whole buffer.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.errors import InputError
from multigpu.warp import pfm
from multigpu.warp.mpcdi import REACH, Output


def read(warp: Path, size: tuple[int, int], alpha: Path | None = None, beta: Path | None = None,
         gamma_embedded: float = 1.0) -> Output:
    """An output of ``size`` (w, h) from the PFM ``warp`` and the ``alpha``/``beta`` PNGs."""
    from PIL import Image

    from multigpu.core.warpblend import map_values, resample

    warp = Path(warp)
    try:
        grid = pfm.read(warp.read_bytes(), str(warp))
    except OSError as exc:
        raise InputError(f"{warp}: cannot read the warp ({exc.strerror or exc})") from None
    if grid.shape[2] != 3 or min(grid.shape[:2]) < 2:
        raise InputError(f"{warp}: a warp is a PF (three channels) of at least 2 x 2 samples, got "
                         f"{grid.shape[1]} x {grid.shape[0]} x {grid.shape[2]}")
    coords = grid[..., :2].astype(np.float64)
    finite = coords[np.isfinite(coords)]
    if finite.min() < -REACH or finite.max() > 1 + REACH:
        raise InputError(f"{warp}: maps outside the content (coordinates {finite.min():.3g} .. {finite.max():.3g}, "
                         "not 0..1)")
    out = Output(warp.stem, tuple(size), (0.0, 0.0, 1.0, 1.0), coords)
    for which, path in (("alpha", alpha), ("beta", beta)):
        if path is None:
            continue
        try:
            img = np.asarray(Image.open(path))
        except (OSError, ValueError) as exc:
            raise InputError(f"{path}: not an image Pillow reads ({exc})") from None
        depth = 16 if img.dtype == np.uint16 or img.max(initial=0) > 255 else 8
        values = map_values(img[..., :3] if img.ndim == 3 else img, depth, gamma_embedded)
        if values.shape[:2] != (size[1], size[0]):
            out.notes.append(f"{Path(path).name} of {values.shape[1]} x {values.shape[0]} resampled to the "
                             f"output's {size[0]} x {size[1]}")
            values = resample(values, size)
        setattr(out, which, values)
    return out
