"""Connected components of a mesh's vertices, compiled (``scene.labels.component_labels``):
union-find over the faces' edges, one parent per vertex and nothing per edge, where scipy's
sparse graph builds edge lists of ~30 bytes a face. Each component's root is its lowest vertex,
so the components rank as scipy numbers them (tests/test_scene_paths.py compares the two)."""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all


def _find(parent, v):
    root = v
    while parent[root] != root:
        root = parent[root]
    while parent[v] != root:  # path compression
        parent[v], v = root, parent[v]
    return root


def _union(parent, a, b):
    ra, rb = _find(parent, a), _find(parent, b)
    if ra < rb:
        parent[rb] = ra
    elif rb < ra:
        parent[ra] = rb


def _roots(canon, faces, n):
    parent = np.arange(n).astype(canon.dtype)
    for f in range(faces.shape[0]):
        a, b, c = canon[faces[f, 0]], canon[faces[f, 1]], canon[faces[f, 2]]
        _union(parent, a, b)
        _union(parent, b, c)
    for v in range(n):
        parent[v] = _find(parent, v)
    return parent


compile_all(globals(), ("_find", "_union", "_roots"))


def vertex_roots(canon: np.ndarray, faces: np.ndarray, n: int) -> np.ndarray:
    """(n,) the lowest vertex of each vertex's component, over the edges of ``faces`` ((T, 3)
    indices into ``canon``, which maps them to the ``n`` distinct vertices)."""
    return _roots(canon, faces, n)
