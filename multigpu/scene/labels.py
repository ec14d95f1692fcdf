"""Which object each face of a model belongs to (``--split``).

``components``: faces sharing vertices (by position: STL and split-normal OBJ duplicate
vertices) form one object, and parts under ``--merge-below`` faces are merged by the grid cell
of their centre; ``grid:N``: faces by the cell of an N^3 grid over the model their centre falls
in. Vectorized, a block of faces at a time where a pass makes per-face temporaries.
"""

from __future__ import annotations

import numpy as np

from multigpu.scene.blocks import blocks


def face_labels(verts, faces, split: str, merge_below: int) -> np.ndarray:
    """Object of every face for ``components`` or ``grid:N``."""
    if split == "components":
        return merge_small(component_labels(faces, verts), verts, faces, merge_below)
    return grid_labels(verts, faces, int(split.split(":")[1]))


def face_centres(verts, faces, s: int, e: int) -> np.ndarray:
    """(e-s, 3) float64 centres of faces ``s:e``."""
    return verts[faces[s:e]].mean(axis=1)


def component_labels(faces: np.ndarray, verts: np.ndarray, compiled: bool | None = None) -> np.ndarray:
    """A label per face, equal for faces connected through shared vertices, ordered as the
    components' lowest vertex (vertices at the same position are one vertex: STL and
    split-normal OBJ duplicate them). Compiled union-find where numba is installed (``None``):
    a parent per vertex, nothing per edge; ``compiled=False``: scipy's sparse graph (the
    reference: its edge lists cost ~30 bytes a face)."""
    from multigpu.core import jit

    _, canon = np.unique(verts, axis=0, return_inverse=True)
    canon = canon.ravel().astype(np.int32 if len(verts) < 2**31 else np.int64)
    n_verts = int(canon.max()) + 1
    if jit.use(compiled):
        from multigpu.scene.labels_kernel import vertex_roots

        return vertex_roots(canon, np.ascontiguousarray(faces), n_verts)[canon[faces[:, 0]]]
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows = np.concatenate([canon[faces[:, 0]], canon[faces[:, 1]]])
    cols = np.concatenate([canon[faces[:, 1]], canon[faces[:, 2]]])
    g = coo_matrix((np.ones(rows.size, dtype=np.float32), (rows, cols)), shape=(n_verts, n_verts))
    del rows, cols
    _, vlabel = connected_components(g, directed=False)  # numbered in order of their lowest vertex
    return vlabel[canon[faces[:, 0]]]


def grid_labels(verts, faces, n: int) -> np.ndarray:
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for s, e in blocks(len(faces)):
        cen = face_centres(verts, faces, s, e)
        lo, hi = np.minimum(lo, cen.min(0)), np.maximum(hi, cen.max(0))
    size = max(float((hi - lo).max()), 1e-12) / n
    code = np.empty(len(faces), dtype=np.int64)
    for s, e in blocks(len(faces)):
        cell = ((face_centres(verts, faces, s, e) - lo) / size).astype(np.int64)
        cell = np.minimum(cell, n - 1)  # the far edge is in the last cell
        code[s:e] = (cell[:, 0] * n + cell[:, 1]) * n + cell[:, 2]
    return np.unique(code, return_inverse=True)[1].ravel()


def merge_small(labels, verts, faces, merge_below: int) -> np.ndarray:
    """Merge components with fewer than ``merge_below`` faces by the grid cell (1/16 of the
    extent) of their centre: a small part stays whole, neighbouring small parts share an object."""
    uniq, inv, counts = np.unique(labels, return_inverse=True, return_counts=True)
    small_comp = counts < merge_below
    if not small_comp.any():
        return inv
    comp_cen = np.zeros((uniq.size, 3))
    for s, e in blocks(len(faces)):
        face_cen = face_centres(verts, faces, s, e)
        for a in range(3):  # axes
            comp_cen[:, a] += np.bincount(inv[s:e], weights=face_cen[:, a], minlength=uniq.size)
    comp_cen /= counts[:, None]
    cen = comp_cen[small_comp]
    lo, hi = cen.min(0), cen.max(0)
    cell = np.minimum(((cen - lo) / (max(float((hi - lo).max()), 1e-12) / 16)).astype(np.int64), 15)
    cell_id = np.full(uniq.size, -1, dtype=np.int64)
    cell_id[small_comp] = uniq.size + np.unique(cell[:, 0] * 256 + cell[:, 1] * 16 + cell[:, 2],
                                                return_inverse=True)[1].ravel()
    comp_new = np.where(small_comp, cell_id, np.arange(uniq.size))
    return np.unique(comp_new[inv], return_inverse=True)[1].ravel()
