"""Parts compiled (``parts._cut_in_place``): each cut object's triangles keyed by the Z-order
code of their centroid in the object's own box (one pass, where the reference makes some forty
numpy passes over every triangle), then reordered and cut, with each part's bounds (one pass).
The same keys, indices and bounds as the reference (tests/test_culling.py). Load time only."""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all


def _keys(src, first, base, tris, starts, pos, lo, span, key):
    """``key[starts[k] + t]``: object k (of the block) in the high bits, the 30-bit Z-order code of
    its triangle t's centroid in its box (``lo``, ``span``, relative to the scene's origin) below."""
    for k in range(first.shape[0]):
        for t in range(tris[k]):
            i = first[k] + 3 * t
            a, b, c = base[k] + src[i], base[k] + src[i + 1], base[k] + src[i + 2]
            code = np.uint64(0)
            for axis in range(3):
                m = ((np.float64(pos[a, axis]) + np.float64(pos[b, axis])) + np.float64(pos[c, axis])) / 3.0
                cell = min(max((m - lo[k, axis]) / span[k, axis] * 1023.0, 0.0), 1023.0)
                v = np.uint64(cell)
                for bit in range(10):
                    code |= ((v >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
            key[starts[k] + t] = (np.uint64(k) << np.uint64(30)) | code


def _apply(order, src, out, first, base, starts, per, part_first, pos, origin, counts, bmin, bmax):
    """Each object's triangles in ``order`` from ``src`` into ``out`` at the object's own range;
    every run of ``per[k]`` of them a part: its index count and bounds (world space)."""
    for k in range(first.shape[0]):
        for j in range(starts[k], starts[k + 1]):
            t = order[j] - starts[k]  # the triangle's place in the object before, ``d`` after
            d = j - starts[k]
            p = part_first[k] + d // per[k]
            counts[p] += 3
            for v in range(3):
                vi = src[first[k] + 3 * t + v]
                out[first[k] + 3 * d + v] = vi
                g = base[k] + vi
                for axis in range(3):
                    w = np.float64(pos[g, axis]) + origin[axis]
                    if w < bmin[p, axis]:
                        bmin[p, axis] = w
                    if w > bmax[p, axis]:
                        bmax[p, axis] = w


compile_all(globals(), ("_keys", "_apply"))
