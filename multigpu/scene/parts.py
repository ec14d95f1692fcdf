"""Parts: every object of many triangles cut, inside itself, into spatially compact runs of
triangles with their own bounds, so a rank draws only the parts of an object its region needs.

The balancer sees whole objects (its cost does not grow with the part count); the renderer
culls an object's parts against the region it draws (``core/culling.py``). An object's triangles
are reordered along a Z-order curve of their centroids (``cluster.cut``) and every run of about
``PART_TRIS`` of them is a part, its bounding box kept beside it in the scene cache. Objects of at
most ``PART_TRIS`` triangles are one part each, their own bounds. Images do not change with the
part size: a part is culled only where none of its triangles reaches the region (conservative
bounds, as the objects'), and the reordering is the scene's, the same for every rank and for a
one-rank render. Built once at load, cached; pure numpy.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.drawlist import owners
from multigpu.scene.cluster import cut
from multigpu.scene.layout import Scene

#: triangles per part (objects above it are cut; measured in docs/BENCHMARKS.md, `bench parts`)
PART_TRIS = 64


def with_parts(scene: Scene, size: int = PART_TRIS) -> Scene:
    """``scene`` with its parts: objects above ``size`` triangles reordered inside their own
    index range and cut into parts of at most ``size`` triangles, the others one part each."""
    tris = scene.tris
    big = np.flatnonzero(tris > size)
    n_parts = np.ones(scene.n_objects, dtype=np.int64)
    indices = scene.indices
    if big.size:
        sub, n_cut = cut(scene.objects(big), size)
        n_parts[big] = n_cut
        indices = np.array(scene.indices, dtype=np.uint32)  # a copy: the scene's may be a read-only map
        counts = scene.index_count[big].astype(np.int64)
        starts = np.zeros(big.size + 1, dtype=np.int64)  # each big object's indices in the cut, back to back
        np.cumsum(counts, out=starts[1:])
        first = scene.first_index[big].astype(np.int64)
        block = 1 << 22
        for s in range(0, int(starts[-1]), block):  # blocks of indices, not objects
            e = min(s + block, int(starts[-1]))
            k = owners(starts, s, e)
            indices[first[k] + np.arange(s, e, dtype=np.int64) - starts[k]] = sub.indices[s:e]
    part_start = np.zeros(scene.n_objects + 1, dtype=np.int64)
    np.cumsum(n_parts, out=part_start[1:])
    total = int(part_start[-1])
    part_count = np.empty(total, dtype=np.int64)
    part_bmin, part_bmax = np.empty((total, 3)), np.empty((total, 3))
    whole = np.ones(scene.n_objects, dtype=bool)
    whole[big] = False
    at = part_start[:-1][whole]  # an object kept whole: its own range and bounds
    part_count[at] = scene.index_count[whole]
    part_bmin[at], part_bmax[at] = scene.bmin[whole], scene.bmax[whole]
    if big.size:  # the cut's clusters, in (object, cluster) order, into their objects' part ranges
        rows = np.repeat(part_start[big] - np.concatenate([[0], np.cumsum(n_cut[:-1])]), n_cut) + np.arange(
            int(n_cut.sum()))
        part_count[rows] = sub.index_count
        part_bmin[rows], part_bmax[rows] = sub.bmin, sub.bmax
    meta = {**scene.meta, "parts": {"size": int(size), "parts": total, "objects_cut": int(big.size)}}
    return Scene(**{**scene._arrays(parts=False), "indices": indices}, name=scene.name, meta=meta,
                 part_start=part_start, part_count=part_count, part_bmin=part_bmin, part_bmax=part_bmax)
