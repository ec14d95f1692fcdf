"""Per-triangle screen rects: the ground truth of what a screen region needs drawn.

The balancer culls whole objects by their bounding volumes; this module projects every
triangle instead (near-plane clipped, exact for the triangle's visible part) so a measurement
can say how many triangles a region really needs, which objects have at least one such
triangle, and check that no needed object is ever missing from a rank's draw list. Pure numpy,
used by the accuracy report and tests, never on the per-frame path.
"""

from __future__ import annotations

import numpy as np

# the 3 edges of a triangle as vertex index pairs
_EDGES = ((0, 1), (1, 2), (2, 0))


def triangle_objects(scene, block: int = 1 << 18) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3) absolute vertex indices of every triangle (int32 where the vertex count allows)
    and (T,) int64 its object id, objects in buffer order. Made ``block`` triangles at a time:
    the temporaries stay small at any scale."""
    from multigpu.core.drawlist import owners

    order = np.argsort(scene.first_index, kind="stable")
    counts = scene.index_count[order].astype(np.int64)
    first = scene.first_index[order].astype(np.int64)
    base = scene.base_vertex[order].astype(np.int64)
    starts = np.zeros(order.size + 1, dtype=np.int64)  # where each object's indices go in the output
    np.cumsum(counts, out=starts[1:])
    n = int(starts[-1]) // 3
    tri = np.empty((n, 3), dtype=np.int32 if scene.vertices.shape[0] < 2**31 else np.int64)
    obj = np.empty(n, dtype=np.int64)
    flat = tri.reshape(-1)
    for s in range(0, n, block):
        e = min(s + block, n)
        k = owners(starts, 3 * s, 3 * e)  # which object (in ``order``) every index is of
        src = first[k] + np.arange(3 * s, 3 * e, dtype=np.int64) - starts[k]
        flat[3 * s:3 * e] = scene.indices[src].astype(np.int64) + base[k]
        obj[s:e] = order[k[::3]]
    return tri, obj


def triangle_rects(world: np.ndarray, tri: np.ndarray, view: np.ndarray, proj: np.ndarray,
                   chunk: int = 1 << 18) -> np.ndarray:
    """(T, 4) normalized rects ``[xmin, ymin, xmax, ymax]`` of triangles, NaN where unseen.

    ``world`` (V, 3) float64 vertex positions, ``tri`` (T, 3) vertex indices. Each triangle is
    clipped against the near plane (its vertices in front plus its edges' crossings), then its
    NDC bounds are clipped to the screen; triangles wholly behind the near plane, beyond the
    far plane or outside a side of the frustum get NaN.
    """
    M = np.asarray(proj, dtype=np.float64) @ np.asarray(view, dtype=np.float64)
    out = np.full((tri.shape[0], 4), np.nan)
    for s in range(0, tri.shape[0], chunk):  # blocks of triangles, not triangles
        t = tri[s:s + chunk]
        c = world[t] @ M[:, :3].T + M[:, 3]  # (n, 3, 4) clip coordinates
        d = c[..., 2] + c[..., 3]  # >= 0: in front of the near plane
        pts = [c[:, i] for i in range(3)]
        ok = [d[:, i] >= 0 for i in range(3)]
        for i, j in _EDGES:  # 3 edges, not triangles
            cross = (d[:, i] >= 0) != (d[:, j] >= 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                u = np.where(cross, d[:, i] / (d[:, i] - d[:, j]), 0.0)
            pts.append(c[:, i] + u[:, None] * (c[:, j] - c[:, i]))
            ok.append(cross)
        P = np.stack(pts, axis=1)  # (n, 6, 4)
        K = np.stack(ok, axis=1)  # (n, 6)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(K, P[..., 0] / P[..., 3], np.nan)
            y = np.where(K, P[..., 1] / P[..., 3], np.nan)
        seen = K.any(axis=1)
        beyond_far = (c[..., 2] > c[..., 3]).all(axis=1)
        outside = np.zeros(len(t), dtype=bool)
        for axis in (0, 1):  # all three vertices beyond the same side plane
            outside |= (c[..., axis] > c[..., 3]).all(axis=1) | (c[..., axis] < -c[..., 3]).all(axis=1)
        keep = seen & ~beyond_far & ~outside
        xs, ys = x[keep], y[keep]
        r = np.stack([np.nanmin(xs, axis=1), np.nanmin(ys, axis=1), np.nanmax(xs, axis=1), np.nanmax(ys, axis=1)],
                     axis=1) * 0.5 + 0.5
        off = (r[:, 2] < 0) | (r[:, 0] > 1) | (r[:, 3] < 0) | (r[:, 1] > 1)
        r = np.clip(r, 0.0, 1.0)
        r[off] = np.nan
        block = out[s:s + chunk]
        block[keep] = r
    return out
