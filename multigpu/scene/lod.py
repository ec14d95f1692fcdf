"""Levels of detail: every object of enough triangles simplified, once at load, into coarser meshes.

Each level is made by meshoptimizer's simplifier (``meshopt_simplify``; chosen over
fast-simplification by ``multigpu bench simplify``: it keeps the object's own vertices, so a
level is only an index list beside the original, and it reports each level's geometric error,
which is what choosing a level by its size on screen needs).

Level 0 is the object as modelled; level l in 1..LEVELS-1 aims at ``RATIO ** l`` of its
triangles, simplified from level l-1 (a quarter of the work of starting from the full mesh each
time; the level's error is then the sum of the steps' errors, a bound on its distance from the
original). A level is kept only where it drops at least a quarter of the triangles of the one
before; an object's levels past its last kept one hold no indices and an infinite error (never
chosen), so every object has ``LEVELS`` columns and choosing is one vectorised pass
(``core/lod.py``). ``lod_error`` is the
simplifier's absolute error (world units: how far the simplified surface may lie from the
original). Borders are locked where objects were cut from
one surface (``--split grid``, clusters: ``cut_from_one``); whole objects (the plant's open pipes,
whose every vertex lies on a border) simplify freely. Built once, stored in the scene cache beside the
parts; the GL index buffer holds every level (``core/drawlist.py``).
"""

from __future__ import annotations

import numpy as np

from multigpu.scene.layout import Scene

#: levels per object, the full one included
LEVELS = 4
#: each level aims at this share of the triangles of the one before
RATIO = 0.25
#: objects of fewer triangles keep only their full level
MIN_TRIS = 16
#: objects of at least this many triangles are simplified in a thread pool (their time is the C++'s)
THREADED_TRIS = 1024
#: a level must drop at least this share of the previous level's triangles to be kept
MIN_DROP = 0.25


def cut_from_one(scene: Scene) -> bool:
    """Whether the scene's objects were cut from bigger surfaces (a grid split or clusters): their
    borders meet their neighbours' and must stay where they are at every level (no cracks)."""
    objects = scene.meta.get("objects", {})
    return str(objects.get("split", "")).startswith("grid") or int(objects.get("cluster", 0) or 0) > 0


def simplify(positions: np.ndarray, indices: np.ndarray, target_tris: int, lock: bool) -> tuple[np.ndarray, float]:
    """One simplified index list of a mesh (``positions`` (V, 3) float32, ``indices`` (3T,) uint32
    relative to them) aiming at ``target_tris`` triangles, and its absolute error (world units);
    ``lock``: its border vertices stay."""
    import meshoptimizer as mo

    dst = np.empty_like(indices)
    err = np.zeros(1, dtype=np.float32)
    options = mo.SIMPLIFY_ERROR_ABSOLUTE | (mo.SIMPLIFY_LOCK_BORDER if lock else 0)
    n = mo.simplify(dst, indices, positions, target_index_count=3 * max(int(target_tris), 1), target_error=1e30,
                    options=options, result_error=err)
    return dst[:n].copy(), float(err[0])


def coarsest(count: np.ndarray) -> np.ndarray:
    """(N,) index count of each object's coarsest level (of ``lod_count`` (N, L))."""
    last = (count > 0).sum(axis=1) - 1
    return count[np.arange(count.shape[0]), np.maximum(last, 0)]


def _chain(scene: Scene, i: int, levels: int, ratio: float, lock: bool) -> list[tuple[np.ndarray, float]]:
    """Object ``i``'s coarser levels, each simplified from the one before: (indices relative to its
    base vertex, error bound) per level kept, until one fails to drop ``MIN_DROP``."""
    s, c = int(scene.first_index[i]), int(scene.index_count[i])
    local = np.asarray(scene.indices[s:s + c], dtype=np.uint32)
    lo, hi = int(local.min()), int(local.max()) + 1
    base = int(scene.base_vertex[i])
    verts = np.ascontiguousarray(scene.vertices[base + lo:base + hi, :3], dtype=np.float32)
    last, prev, prev_err, out = local - np.uint32(lo), c // 3, 0.0, []
    for lv in range(1, levels):  # levels, not objects
        got, err = simplify(verts, last, int(c // 3 * ratio ** lv), lock)  # from the level before
        t = got.size // 3
        if t == 0 or t > prev * (1 - MIN_DROP):
            break
        prev, prev_err, last = t, prev_err + err, got  # errors add up along the chain: a bound
        out.append((got + np.uint32(lo), prev_err))
    return out


def with_lods(scene: Scene, levels: int = LEVELS, ratio: float = RATIO, min_tris: int = MIN_TRIS,
              lock: bool | None = None) -> Scene:
    """``scene`` with its levels of detail (``Scene.LODS``): each object simplified in place of
    its own vertices (``lock`` its borders; None: where ``cut_from_one``). Load time only: the
    objects in a thread per core (the simplifier's C++ runs without the GIL), gathered in
    object order, so the result is the same with any number of threads."""
    import os
    from concurrent.futures import ThreadPoolExecutor

    lock = cut_from_one(scene) if lock is None else lock
    n = scene.n_objects
    count = np.zeros((n, levels), dtype=np.int64)
    first = np.zeros((n, levels), dtype=np.int64)
    count[:, 0], first[:, 0] = scene.index_count, scene.first_index  # level 0: the scene's own range
    error = np.full((n, levels), np.inf)
    error[:, 0] = 0.0
    extra: list[np.ndarray] = []
    at = int(scene.indices.shape[0])  # levels are stored after the scene's own indices
    todo = np.flatnonzero(scene.tris >= min_tris)
    big = todo[scene.tris[todo] >= THREADED_TRIS]  # the simplifier's time: threads; small ones are Python's
    workers = max(1, min(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1, 8))
    with ThreadPoolExecutor(workers) as pool:
        futures = {int(i): pool.submit(_chain, scene, int(i), levels, ratio, lock) for i in big}
        chains = {int(i): _chain(scene, int(i), levels, ratio, lock) for i in todo if int(i) not in futures}
        for i in todo:  # objects in order, whichever thread simplified them
            chain = futures[i].result() if i in futures else chains[i]
            for lv, (got, err) in enumerate(chain, 1):
                count[i, lv], first[i, lv], error[i, lv] = got.size, at, err
                extra.append(got)
                at += got.size
    indices = np.concatenate([np.asarray(scene.indices, dtype=np.uint32), *extra]) if extra else scene.indices
    meta = {**scene.meta, "lods": {"levels": int(levels), "ratio": float(ratio), "min_tris": int(min_tris),
                                   "locked_borders": lock,
                                   "objects": int(np.isfinite(error[:, 1]).sum()) if levels > 1 else 0,
                                   "coarsest_triangles": int(coarsest(count).sum() // 3)}}
    return Scene(**{**scene._arrays(lods=False), "indices": indices}, name=scene.name, meta=meta,
                 lod_first=first, lod_count=count, lod_error=error)
