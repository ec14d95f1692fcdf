"""A scanned-style model: one big closed surface, the kind a 3D scanner or photogrammetry
delivers (a statue, a fossil, a machine part): millions of small, even triangles in a single
mesh with no parts of its own. Balancing such a model needs it cut into pieces first
(``--split grid:N``), which makes a scene of few large objects, each a patch of the surface.

``scan_mesh`` builds it deterministically: a sphere of even triangles of the requested size,
stretched into an upright figure (1 x 2 x 0.9, +Y up as PLY scans are, metres) and displaced along its
normals by a few octaves of smooth random waves, so patches differ in depth and silhouette as a
scan's do. ``write_scan`` saves it as binary PLY (what scanners export); ``multigpu scene scan
OUT.ply`` is the command.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: the figure's half extents before displacement (x, y, z), metres; +Y up, as PLY scans are
SHAPE = (0.5, 1.0, 0.45)
MIN_TRIANGLES = 12


def scan_mesh(triangles: int = 1_000_000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) float64, faces (F, 3) int64, outward winding) of a closed surface of
    about ``triangles`` even triangles (a cube's 6 faces as n x n grids pushed onto the
    sphere: 12 n^2 triangles, the nearest n)."""
    if triangles < MIN_TRIANGLES:
        raise ValueError(f"a scan needs at least {MIN_TRIANGLES} triangles, got {triangles}")
    n = max(1, int(round(np.sqrt(triangles / 12.0))))
    ijk, faces = _cube_grid(n)
    t = np.tan((ijk / n * 2.0 - 1.0) * (np.pi / 4))  # equal-angle cube map: near-even triangles
    unit = t / np.linalg.norm(t, axis=1, keepdims=True)
    a, b, c = unit[faces[:, 0]], unit[faces[:, 1]], unit[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) < 0
    faces[inward] = faces[inward][:, ::-1]  # every triangle wound outward
    verts = unit * np.array(SHAPE) * (1.0 + _relief(unit, seed))[:, None]
    verts[:, 1] += SHAPE[1]  # standing on y = 0
    return verts, faces


def _cube_grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Integer lattice points (V, 3) of a cube's surface (0..n on each axis) and its 12 n^2
    triangles; an edge shared by two faces is one set of vertices (exact integer keys)."""
    g = np.arange(n + 1)
    u, v = np.meshgrid(g, g, indexing="ij")
    u, v = u.ravel(), v.ravel()
    quads = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()  # lower-left corner per quad
    tri = np.concatenate([np.stack([quads, quads + n + 1, quads + n + 2], 1),
                          np.stack([quads, quads + n + 2, quads + 1], 1)])
    points, faces = [], []
    for axis in range(3):  # the cube's 6 faces, not vertices
        for side in (0, n):
            p = np.empty((len(u), 3), dtype=np.int64)
            p[:, axis] = side
            p[:, (axis + 1) % 3], p[:, (axis + 2) % 3] = u, v
            faces.append(tri + sum(len(q) for q in points))
            points.append(p)
    keys, inverse = np.unique(np.concatenate(points), axis=0, return_inverse=True)
    return keys.astype(np.float64), inverse.reshape(-1)[np.concatenate(faces)].astype(np.int64)


def _relief(unit: np.ndarray, seed: int) -> np.ndarray:
    """Relative displacement of each direction: octaves of random plane waves (smooth, bounded
    by 0.25), like the folds and bumps of a scanned surface."""
    rng = np.random.default_rng(seed)
    out = np.zeros(len(unit))
    for octave in range(5):  # octaves, not vertices
        freq, amp = 2.0 * 2.2 ** octave, 0.11 / 1.9 ** octave
        dirs = rng.normal(size=(4, 3))
        phase = rng.uniform(0, 2 * np.pi, 4)
        out += amp * np.sin(unit @ dirs.T * freq + phase).mean(axis=1)
    return out


def write_scan(path: Path, triangles: int = 1_000_000, seed: int = 0) -> Path:
    """Write the scan as binary little-endian PLY (float32 vertices, int32 faces)."""
    verts, faces = scan_mesh(triangles, seed)
    path = Path(path)
    header = (f"ply\nformat binary_little_endian 1.0\ncomment multigpu scan_mesh triangles={triangles} seed={seed}\n"
              f"element vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    rec = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", 3)])
    rec["n"], rec["v"] = 3, faces
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as f:  # written whole, then renamed: never read half-written
        f.write(header)
        f.write(verts.astype("<f4").tobytes())
        f.write(rec.tobytes())
    tmp.replace(path)
    return path
