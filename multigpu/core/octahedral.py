"""Unit normals as 32-bit octahedral codes, 16 bits a coordinate (the GL vertices' normals,
``gpu/buffers.py``; the vertex shader decodes them): a third of the bytes of three floats, within
1e-4 of the normal's direction, which the lighting cannot show in 8-bit colour. A zero normal
reads as +z, and so does one with a coordinate that is not finite (numpy's cast of a NaN to an
integer differs between its scalar and vector loops: such a normal had no code of its own).

``encode_reference`` is the numpy reference; ``octahedral_kernel._encode`` the same arithmetic
compiled (one pass, no temporaries: a 96x96 plate's 35 k vertices packed in ~0.3 ms against ~1.7, every
rank's share of a live step swapped in), chosen once here (``encode``).
"""

from __future__ import annotations

import numpy as np

from multigpu.core import jit


def encode(normals: np.ndarray, compiled: bool | None = None) -> np.ndarray:
    """(V,) uint32 codes of (V, 3) normals; ``compiled``: the kernel (None: where numba is
    installed) or the reference, the same bits either way (tests/test_octahedral_kernel.py)."""
    if not jit.use(compiled):
        return encode_reference(normals)
    from multigpu.core.octahedral_kernel import _encode

    n = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
    out = np.empty(len(n), dtype=np.uint32)
    _encode(n, out)
    return out


def pack(vertices: np.ndarray, compiled: bool | None = None) -> np.ndarray:
    """(V, 4) uint32 of (V, 6) float32 vertices (position, normal): the position's three float32
    bits as they are, the normal's code (``encode``); compiled, one pass (the GL vertex layout,
    ``gpu/buffers.pack_vertices``)."""
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    out = np.empty((v.shape[0], 4), dtype=np.uint32)
    if not jit.use(compiled):
        out[:, :3] = np.ascontiguousarray(v[:, :3]).view(np.uint32)
        out[:, 3] = encode_reference(v[:, 3:6])
        return out
    from multigpu.core.octahedral_kernel import _pack

    _pack(v, v.view(np.uint32), out)
    return out


def encode_reference(normals: np.ndarray) -> np.ndarray:
    """The numpy reference of ``encode``."""
    n = np.array(normals, dtype=np.float64)
    n[~np.isfinite(n).all(axis=1)] = 0.0
    s = np.abs(n).sum(axis=1, keepdims=True)
    n = n / np.where(s > 0, s, 1.0)
    n[s[:, 0] == 0, 2] = 1.0
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sx, sy = np.where(x >= 0, 1.0, -1.0), np.where(y >= 0, 1.0, -1.0)
    fold = z < 0
    x, y = np.where(fold, (1 - np.abs(y)) * sx, x), np.where(fold, (1 - np.abs(x)) * sy, y)
    u = np.rint((x * 0.5 + 0.5) * 65535).astype(np.uint32)
    v = np.rint((y * 0.5 + 0.5) * 65535).astype(np.uint32)
    return u | (v << np.uint32(16))
