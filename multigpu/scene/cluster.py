"""Split big objects into spatially coherent clusters of at most ``max_tris`` triangles.

The balancer culls and counts whole objects, so an object straddling a split is drawn (all of
its triangles transformed) by every rank it touches. Objects of hundreds or thousands of
triangles (slabs, long pipes, tanks) make most of that overlap. Cutting them into clusters
along a Z-order curve of their triangle centroids keeps each cluster compact on screen, so a
split cuts few clusters and each cut costs few triangles; the draw list merges consecutive
visible clusters into one command, so more objects cost no more draw calls. Vertices, normals
and colours are shared with the original object, so images do not change. Pure numpy.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.drawlist import morton_codes
from multigpu.core.triangles import triangle_objects
from multigpu.errors import InputError
from multigpu.scene.blocks import blocks, per_object
from multigpu.scene.layout import Scene

#: automatic clusters are never smaller than this (tiny pieces only add per-object cost)
MIN_CLUSTER = 64
#: walls of at least this many ranks always cut big objects (overlap grows with the wall)
BIG_WALL = 9


def auto_cluster(tris: np.ndarray, ranks: int) -> tuple[int, str]:
    """Cluster size that makes a scene balanceable on ``ranks`` ranks, and why (0: keep).

    The balancer moves whole objects, so one object holding a share ``s`` of the triangles
    bounds the triangle imbalance below by ``s * K``, a scene of few objects leaves the splits
    few places to go, and an object straddling a split is drawn by both sides. Objects are cut
    when one holds more than 1/(4K) of the triangles, when there are fewer than 8 objects per
    rank, or on walls of ``BIG_WALL`` ranks or more, where straddling objects multiply (the
    plant at 4x4: overlap 3.21 whole, 2.77 / 2.47 with clusters of 333 / 64 triangles,
    ``multigpu experiment walls``). Clusters then hold at most 1/(64K) of the triangles (and
    at least ``MIN_CLUSTER``). Smaller walls keep scenes as modelled otherwise, so their
    objects (and draw order) do not depend on the wall."""
    tris = np.asarray(tris, dtype=np.int64)
    total, k = int(tris.sum()), int(ranks)
    if total == 0:
        return 0, "no triangles"
    share = float(tris.max()) / total
    reasons = []
    if share > 1.0 / (4 * k):
        reasons.append(f"one object holds {share:.1%} of the triangles (more than 1/(4K) = {1 / (4 * k):.1%})")
    if tris.size < 8 * k:
        reasons.append(f"{tris.size} objects for {k} ranks (fewer than 8 per rank)")
    if k >= BIG_WALL:
        reasons.append(f"a {k}-rank wall (objects straddling splits multiply)")
    if not reasons:
        return 0, f"kept as modelled: largest object {share:.1%} of the triangles, {tris.size} objects for {k} ranks"
    size = max(MIN_CLUSTER, -(-total // (64 * k)))
    if tris.max() <= size:
        return 0, "kept as modelled: " + "; ".join(reasons) + f", but no object exceeds {size} triangles"
    return size, f"objects above {size} triangles cut into clusters for {k} ranks: " + "; ".join(reasons)


def split_objects(scene: Scene, max_tris: int) -> Scene:
    """The scene with every object above ``max_tris`` triangles cut into near-equal clusters."""
    if max_tris < 1:
        raise InputError.of("cluster", f"must be >= 1 triangle (0 keeps objects whole), got {max_tris}")
    tris = scene.tris
    if tris.size == 0 or tris.max() <= max_tris:
        return scene
    return cut(scene, max_tris)[0]


def cut(scene: Scene, max_tris: int) -> tuple[Scene, np.ndarray]:
    """Every object above ``max_tris`` triangles cut into near-equal clusters along a Z-order
    curve of its triangle centroids: the scene whose objects are the clusters, in (object,
    cluster) order, and (N,) the cluster count of each original object (1 where kept whole)."""
    tris = scene.tris
    tri, obj = triangle_objects(scene)  # (T, 3) absolute vertices, object of each triangle
    pos = scene.vertices[:, :3]
    centroid = lambda s, e: pos[tri[s:e]].astype(np.float64).mean(axis=1)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)  # the centroids' box, then their codes in it
    for s, e in blocks(len(obj)):
        c = centroid(s, e)
        lo, hi = np.minimum(lo, c.min(axis=0)), np.maximum(hi, c.max(axis=0))
    key = np.zeros(len(obj), dtype=np.uint64)  # small objects keep their order
    for s, e in blocks(len(obj)):
        big = tris[obj[s:e]] > max_tris
        if big.any():
            key[s:e] = np.where(big, morton_codes(centroid(s, e), box=(lo, hi)), np.uint64(0))
    order = np.lexsort((np.arange(len(obj)), key, obj))
    del key
    tri, obj = tri[order], obj[order]
    # rank of each triangle within its object, and the object's cluster count and size
    counts = np.bincount(obj, minlength=scene.n_objects)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    within = np.arange(len(obj)) - start[obj]
    n_clusters = -(-counts // max_tris)
    per = -(-counts // np.maximum(n_clusters, 1))  # near-equal cluster sizes
    cluster = within // np.maximum(per[obj], 1)
    del within
    first_of_obj = np.concatenate([[0], np.cumsum(n_clusters)[:-1]])
    cid = first_of_obj[obj] + cluster  # new object id, in (object, cluster) order
    del cluster, obj
    # inside a cluster keep the modelled triangle order (vertex reuse as the modeller left it)
    keep = np.lexsort((order, cid))
    del order
    tri, cid = tri[keep], cid[keep]
    del keep
    n_new = int(n_clusters.sum())
    new_counts = np.bincount(cid, minlength=n_new)
    parent = np.repeat(np.arange(scene.n_objects), n_clusters)
    starts = np.concatenate([[0], np.cumsum(new_counts)[:-1]])
    base = scene.base_vertex[parent]
    bmin, bmax, radii = np.full((n_new, 3), np.inf), np.full((n_new, 3), -np.inf), np.zeros(n_new)
    local = np.empty(tri.size, dtype=np.uint32)
    for s, e in blocks(len(cid)):  # blocks of triangles: the (T, 3, 3) corners never whole
        world = pos[tri[s:e]].astype(np.float64) + scene.origin
        per_object(np.minimum, world.min(axis=1), cid[s:e], bmin)
        per_object(np.maximum, world.max(axis=1), cid[s:e], bmax)
        local[3 * s:3 * e] = (tri[s:e] - base[cid[s:e]][:, None]).astype(np.uint32).ravel()
    centers = (bmin + bmax) / 2
    for s, e in blocks(len(cid)):
        world = pos[tri[s:e]].astype(np.float64) + scene.origin
        per_object(np.maximum, np.linalg.norm(world - centers[cid[s:e]][:, None, :], axis=2).max(axis=1),
                    cid[s:e], radii)
    return Scene(vertices=scene.vertices, indices=local, first_index=starts * 3,
                 index_count=new_counts.astype(np.int64) * 3, base_vertex=base, bmin=bmin, bmax=bmax,
                 centers=centers, radii=radii, colors=scene.colors[parent], origin=scene.origin, name=scene.name,
                 body=(np.arange(scene.n_objects) if scene.body is None else scene.body)[parent],
                 **{k: getattr(scene, k)[parent] for k in ("morph_lo", "morph_hi") if getattr(scene, k) is not None},
                 **{k: getattr(scene, k) for k in Scene.PER_VERTEX},
                 meta={**scene.meta, "cluster": int(max_tris), "modelled_objects": scene.n_objects}), n_clusters
