"""The one merge of rendered parts into a display tile, shared by every exchange backend.

A colour-only part (screen, bins) is copied: such parts tile the display exactly. A depth part
(sort-last) replaces the tile's fragments only where it is strictly nearer; parts arrive in
ascending sender order and ranks own ascending ranges of the draw order, so a depth tie keeps
the lower rank's fragment, as a one-rank GL_LESS render keeps the first drawn. A hybrid's screen
regions hold the objects drawn before its wide ones (``core.drawlist.draw_order``), so their
parts win ties (``ties``: nearer or equal) whatever order they arrive in. Pure numpy.
"""

from __future__ import annotations

import numpy as np


def merge_part(color: np.ndarray, depth: np.ndarray | None, tile_origin, rect, rgb: np.ndarray,
               z: np.ndarray | None, ties: bool = False) -> None:
    """Put part ``rect`` (canvas pixels ``[x0, y0, x1, y1)``) with pixels ``rgb`` (h, w, 3) and,
    sort-last, ``z`` (h, w) into the tile ``color`` (th, tw, 3) / ``depth`` (th, tw) whose
    lower-left canvas pixel is ``tile_origin``; ``ties``: the part wins depth ties."""
    x0, y0, x1, y1 = rect
    tx0, ty0 = int(tile_origin[0]), int(tile_origin[1])
    dst = np.s_[y0 - ty0:y1 - ty0, x0 - tx0:x1 - tx0]
    if depth is None:
        color[dst] = rgb
        return
    tile_z = depth[dst]
    nearer = z <= tile_z if ties else z < tile_z
    np.copyto(color[dst], rgb, where=nearer[..., None])  # 4x a boolean index's speed (ad hoc, 384x384)
    np.minimum(tile_z, z, out=tile_z)  # the nearer depth either way
