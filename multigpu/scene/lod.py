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
parts; the GL index buffer holds every level (``core/drawlist.py``). A scene with vertex
colours is simplified with them weighed (``meshopt_simplifyWithAttributes``, ``COLOR_WEIGHT``), so
a colour border stays where the model has it instead of being smeared across coarser triangles
(texture coordinates likewise, ``UV_WEIGHT``: the image does not slide over the surface); UV seams,
borders between materials, and sharp edges, are already seams (vertices split there), which the
simplifier keeps.
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
#: a full colour change (1 in each of R, G, B) weighs as an error of this share of the object's size
COLOR_WEIGHT = 0.5
#: a texture coordinate moved by the whole image weighs as an error of this share of the object's size
UV_WEIGHT = 0.5


def cut_from_one(scene: Scene) -> bool:
    """Whether the scene's objects were cut from bigger surfaces (a grid split or clusters): their
    borders meet their neighbours' and must stay where they are at every level (no cracks)."""
    objects = scene.meta.get("objects", {})
    return str(objects.get("split", "")).startswith("grid") or int(objects.get("cluster", 0) or 0) > 0


def simplify(positions: np.ndarray, indices: np.ndarray, target_tris: int, lock: bool,
             colors: np.ndarray | None = None, weights: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """One simplified index list of a mesh (``positions`` (V, 3) float32, ``indices`` (3T,) uint32
    relative to them) aiming at ``target_tris`` triangles, and its absolute error (world units);
    ``lock``: its border vertices stay; ``colors`` (V, k) float32 attributes (colours in [0, 1],
    texture coordinates): weighed with the positions, ``weights`` (k,) of the mesh's size per unit
    of each (default ``COLOR_WEIGHT``)."""
    import meshoptimizer as mo

    dst = np.empty_like(indices)
    err = np.zeros(1, dtype=np.float32)
    options = mo.SIMPLIFY_ERROR_ABSOLUTE | (mo.SIMPLIFY_LOCK_BORDER if lock else 0)
    target = 3 * max(int(target_tris), 1)
    if colors is None:
        n = mo.simplify(dst, indices, positions, target_index_count=target, target_error=1e30, options=options,
                        result_error=err)
    else:
        size = float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0)))
        share = np.full(colors.shape[1], COLOR_WEIGHT) if weights is None else np.asarray(weights)
        weights = (share * max(size, 1e-12)).astype(np.float32)
        n = _with_attributes(dst, indices, positions, np.ascontiguousarray(colors, dtype=np.float32), weights,
                             target, options, err)
    return dst[:n].copy(), float(err[0])


def _with_attributes(dst, indices, positions, attributes, weights, target: int, options: int, err) -> int:
    """``meshopt_simplifyWithAttributes`` through the binding's library with its C signature
    declared (meshoptimizer 0.2.30a0's Python wrapper declares none: its size_t and float
    arguments would not be passed as such)."""
    import ctypes

    from meshoptimizer._loader import lib

    f = lib.meshopt_simplifyWithAttributes
    if f.restype is not ctypes.c_size_t:
        P = ctypes.POINTER
        f.argtypes = [P(ctypes.c_uint), P(ctypes.c_uint), ctypes.c_size_t, P(ctypes.c_float), ctypes.c_size_t,
                      ctypes.c_size_t, P(ctypes.c_float), ctypes.c_size_t, P(ctypes.c_float), ctypes.c_size_t,
                      P(ctypes.c_ubyte), ctypes.c_size_t, ctypes.c_float, ctypes.c_uint, P(ctypes.c_float)]
        f.restype = ctypes.c_size_t
    fp = lambda a, t: a.ctypes.data_as(ctypes.POINTER(t))
    indices, positions = np.ascontiguousarray(indices, np.uint32), np.ascontiguousarray(positions, np.float32)
    return int(f(fp(dst, ctypes.c_uint), fp(indices, ctypes.c_uint), indices.size, fp(positions, ctypes.c_float),
                 len(positions), 12, fp(attributes, ctypes.c_float), 4 * attributes.shape[1],
                 fp(weights, ctypes.c_float), len(weights), ctypes.POINTER(ctypes.c_ubyte)(), target, 1e30, options,
                 fp(err, ctypes.c_float)))


def _attributes(scene: Scene, lo: int, hi: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Vertices ``lo:hi``'s attributes the simplifier weighs and their weights: vertex colours
    (``COLOR_WEIGHT``) and texture coordinates (``UV_WEIGHT``), where the scene has them."""
    cols, weights = [], []
    if scene.vertex_colors is not None:
        cols.append(np.asarray(scene.vertex_colors[lo:hi, :3], dtype=np.float32) / 255.0)
        weights += [COLOR_WEIGHT] * 3
    if scene.texcoords is not None:
        cols.append(np.asarray(scene.texcoords[lo:hi, :2], dtype=np.float32))
        weights += [UV_WEIGHT] * 2
    if not cols:
        return None, None
    return np.ascontiguousarray(np.concatenate(cols, axis=1)), np.asarray(weights)


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
    colors, weights = _attributes(scene, base + lo, base + hi)
    last, prev, prev_err, out = local - np.uint32(lo), c // 3, 0.0, []
    for lv in range(1, levels):  # levels, not objects
        got, err = simplify(verts, last, int(c // 3 * ratio ** lv), lock, colors, weights)  # from the level before
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
