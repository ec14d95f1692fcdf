"""Paul Bourke's warp meshes: the other reading of a warp, content-to-output.

A mesh file (text, "Mesh format for image warping", Bourke 2006) lists nodes on an ``nx`` x
``ny`` grid, each ``x y u v i``: where the node lands on the output (x across -aspect..aspect,
y up across -1..1), the content it shows there (u, v: 0..1, v up, a texture's coordinates) and a
brightness multiplier (``i``; below 0: the node is not drawn). The content is the mesh drawn as
a textured surface; ``read`` turns it into the output-to-content form the wall applies (the
MPCDI reading, ``mpcdi.Output``): every output pixel's content point, linear across each of the
mesh's triangles, NaN where no triangle covers the pixel, and the brightness as its alpha.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.errors import InputError
from multigpu.warp.mpcdi import Output


def read(path: Path, size: tuple[int, int], name: str | None = None) -> Output:
    """The mesh file ``path`` as an output of ``size`` (w, h) pixels (the whole buffer its
    content)."""
    path = Path(path)
    try:
        lines = [ln.split() for ln in path.read_text().splitlines() if ln.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the warp mesh ({exc})") from None
    try:
        kind, (nx, ny) = int(lines[0][0]), (int(v) for v in lines[1][:2])
        nodes = np.array([[float(v) for v in ln[:5]] for ln in lines[2:]], dtype=np.float64)
    except (IndexError, ValueError):
        raise InputError(f"{path}: not a warp mesh (a type, then nx ny, then x y u v i per node)") from None
    if kind not in (1, 2):
        raise InputError(f"{path}: mesh type {kind}: 2 (rectangular) or 1 (polar) is supported")
    if nx < 2 or ny < 2 or nodes.shape != (nx * ny, 5):
        raise InputError(f"{path}: {nx} x {ny} nodes promised, {len(nodes)} of 5 values found")
    if not np.isfinite(nodes).all():
        raise InputError(f"{path}: a node holds NaN or infinity")
    w, h = size
    aspect = w / h
    px = (nodes[:, 0] / aspect + 1) / 2 * w  # pixel coordinates, y down
    py = (1 - nodes[:, 1]) / 2 * h
    return Output(name or path.stem, (w, h), (0.0, 0.0, 1.0, 1.0),
                  *_raster(px, py, nodes[:, 2], 1 - nodes[:, 3], nodes[:, 4], nx, ny, (w, h)))


def _raster(px, py, u, v, bright, nx: int, ny: int, size) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's triangles drawn at every pixel centre of ``size``: ((h, w, 2) content, (h, w)
    brightness), linear across each triangle, NaN and 0 outside them all."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation

    node = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = node[:-1, :-1].ravel(), node[:-1, 1:].ravel(), node[1:, 1:].ravel(), node[1:, :-1].ravel()
    tris = np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])
    tris = tris[(bright[tris] >= 0).all(axis=1)]  # a node below 0 is not drawn
    w, h = size
    gx, gy = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    mesh = Triangulation(px, py, tris)
    at = [np.ma.filled(LinearTriInterpolator(mesh, f)(gx, gy).astype(np.float64), np.nan) for f in (u, v, bright)]
    warp = np.stack(at[:2], axis=-1)
    return warp, np.nan_to_num(np.clip(at[2], 0.0, 1.0), nan=0.0)
