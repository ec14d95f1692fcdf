"""A box's corners, edges and faces as index tables: shared by the numpy box projection
(``bounds``) and its compiled kernel (``bounds_kernel.py``), where they are compile-time
constants rather than arguments (every array argument costs a compiled call its unboxing)."""

from __future__ import annotations

import numpy as np

# corner sign patterns of a box, (8, 3) (corner k: bit 2 = x, bit 1 = y, bit 0 = z)
SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
# the 12 edges as pairs of corner indices (corners differing in exactly one sign)
EDGES = np.array([(i, j) for i in range(8) for j in range(i + 1, 8)
                  if np.count_nonzero(SIGNS[i] != SIGNS[j]) == 1])
# the 6 faces as corner cycles, and each face corner's successor around its cycle
FACES = np.array([[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]])
NEXT = np.roll(FACES, -1, axis=1)
for _t in (SIGNS, EDGES, FACES, NEXT):
    _t.setflags(write=False)


def clip_matrix(proj: np.ndarray, view: np.ndarray) -> np.ndarray:
    """``proj @ view`` with each entry's four products added left to right (as the kernel's
    ``_clip_matrix`` adds them: BLAS may order or fuse them differently)."""
    return proj[:, 0:1] * view[0] + proj[:, 1:2] * view[1] + proj[:, 2:3] * view[2] + proj[:, 3:4] * view[3]
