"""Scenes from names and files: the built-in plant, users' models through trimesh, the cache.

A scene graph (glTF/GLB, multi-object OBJ) gives one object per node instance with its
transform applied. A single mesh is split into objects by connected components
(``components``) or by a spatial grid (``grid:N``, N cells along the longest axis, the paper's
future-work idea); with ``components``, pieces under ``merge_below`` triangles are merged by
grid cell so object counts stay sane. Faces with non-finite vertices and degenerate faces are
dropped and counted (``scene.meta['warnings']``).

Loaded and generated scenes are cached as ``.npz`` in ``$MULTIGPU_CACHE`` (default
``~/.cache/multigpu``), keyed by source path, size, mtime and options.
"""

from __future__ import annotations

import hashlib
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError, check_file
from .scene import FORMAT_VERSION, Scene

FORMATS = {".obj", ".ply", ".stl", ".off", ".gltf", ".glb"}


@dataclass(frozen=True)
class SceneSpec:
    """What to load: a built-in scene by name or a model file, and how to split it."""

    scene: str = "plant"
    model: str | None = None
    split: str = "components"
    merge_below: int = 64
    triangles: int = 300_000
    copies: int = 1
    seed: int = 0
    cluster: int = 0  # split objects above this many triangles into clusters (0: as modelled)

    def __post_init__(self):
        if self.model is None and self.scene not in BUILTIN:
            raise InputError(f"--scene: unknown scene '{self.scene}' (known: {', '.join(BUILTIN)})")
        if not re.fullmatch(r"components|grid:[1-9][0-9]*", self.split):
            raise InputError(f"--split must be 'components' or 'grid:N' with N >= 1, got '{self.split}'")
        if self.triangles < 1000:
            raise InputError(f"--triangles must be >= 1000, got {self.triangles}")
        if self.seed < 0:
            raise InputError(f"--seed must be >= 0, got {self.seed}")
        if self.copies < 1:
            raise InputError(f"--copies must be >= 1, got {self.copies}")
        if self.cluster < 0:
            raise InputError(f"--cluster must be >= 0 (0 keeps objects whole), got {self.cluster}")


def cache_dir() -> Path:
    return Path(os.environ.get("MULTIGPU_CACHE", Path.home() / ".cache" / "multigpu"))


def _key(*parts) -> str:
    return hashlib.sha1(repr((FORMAT_VERSION,) + parts).encode()).hexdigest()[:16]


def load_scene(spec: SceneSpec, use_cache: bool = True) -> tuple[Scene, dict]:
    """The scene for ``spec`` and load facts (seconds, whether the cache was hit)."""
    t0 = time.perf_counter()
    if spec.model is not None:
        src = check_file(spec.model, "--model", "model file")
        if src.suffix.lower() not in FORMATS:
            raise InputError(f"--model {src}: unsupported extension '{src.suffix}' (use {', '.join(sorted(FORMATS))})")
        st = src.stat()
        key = _key(str(src.resolve()), st.st_size, st.st_mtime_ns, spec.split, spec.merge_below, spec.cluster)
        name = f"{src.stem}-{key}.npz"
        make = lambda: load_model(src, spec.split, spec.merge_below)
    else:
        key = _key(spec.scene, spec.triangles, spec.copies, spec.seed, spec.cluster)
        name = f"{spec.scene}-{key}.npz"
        make = lambda: BUILTIN[spec.scene](spec)

    def build() -> Scene:
        scene = make()
        if spec.cluster:
            from .cluster import split_objects

            scene = split_objects(scene, spec.cluster)
        return scene
    path = cache_dir() / name
    if use_cache and path.is_file():
        try:
            scene = Scene.load(path)
            return scene, {"seconds": time.perf_counter() - t0, "cached": True, "cache": str(path)}
        except InputError:
            path.unlink(missing_ok=True)  # stale or damaged: rebuild
    scene = build()
    if use_cache:
        try:
            scene.save(path)
        except OSError:
            pass  # a read-only cache only costs time
    return scene, {"seconds": time.perf_counter() - t0, "cached": False, "cache": str(path) if use_cache else None}


def _plant(spec: SceneSpec) -> Scene:
    from .plant import generate_plant

    return generate_plant(spec.triangles, spec.copies, spec.seed)


def _fill(spec: SceneSpec) -> Scene:
    from .fillscene import generate_fill

    return generate_fill(spec.triangles, panels=24 * spec.copies, seed=spec.seed)


# built-in scenes: the plant (triangle-bound, the paper's kind) and a fill-bound contrast;
# for ``fill``, ``--copies`` multiplies the 24 panels (depth complexity)
BUILTIN = {"plant": _plant, "fill": _fill}


# ---------------------------------------------------------------- model files

def load_model(path: Path, split: str = "components", merge_below: int = 64) -> Scene:
    """Load a model file through trimesh into the GPU layout (one object per node or piece)."""
    import trimesh

    kind = path.suffix.lstrip(".").upper()
    try:
        with np.errstate(all="ignore"):
            loaded = trimesh.load(str(path), process=False)
    except Exception as exc:
        why = str(exc).splitlines()[0] if str(exc) else "corrupt file"
        raise InputError(f"--model {path}: cannot read as {kind} ({exc.__class__.__name__}: {why})") from None
    warnings: list[str] = []
    if isinstance(loaded, trimesh.Scene):
        meshes = [g for g in loaded.dump(concatenate=False) if isinstance(g, trimesh.Trimesh)]
        meshes = [m for m in meshes if len(m.faces)]
        if not meshes:
            raise InputError(f"--model {path}: the file holds no triangles (empty, or not a {kind} file)")
        if len(meshes) > 1:
            return _from_meshes(meshes, path, warnings)
        mesh = meshes[0]
    elif isinstance(loaded, trimesh.Trimesh):
        mesh = loaded
    else:
        raise InputError(f"--model {path}: holds no triangle mesh (got {type(loaded).__name__})")
    if len(mesh.faces) == 0:
        raise InputError(f"--model {path}: the mesh is empty (no triangles)")
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    _check_indices_and_range(verts, faces, path)
    faces = _clean_faces(verts, faces, path, warnings)
    if split == "components":
        labels = _component_labels(faces, verts)
        labels = _merge_small(labels, verts, faces, merge_below)
    else:
        labels = _grid_labels(verts, faces, int(split.split(":")[1]))
    return _from_labels(verts, faces, labels, path, warnings, {"split": split})


#: coordinates beyond this (in model units) leave float64 no precision for a renderer
MAX_COORD = 1e15


def _check_indices_and_range(verts, faces, path) -> None:
    """Refuse face indices outside the vertex list and coordinates no renderer can use."""
    if faces.size and (faces.min() < 0 or faces.max() >= len(verts)):
        bad = int(faces.max()) if faces.max() >= len(verts) else int(faces.min())
        raise InputError(f"--model {path}: a face uses vertex index {bad}, but the file has "
                         f"{len(verts)} vertices (corrupt or truncated file)")
    finite = np.isfinite(verts).all(axis=1)
    if finite.any():
        reach = float(np.abs(verts[finite]).max())
        if reach > MAX_COORD:
            raise InputError(f"--model {path}: coordinates reach {reach:.3g}, beyond +-{MAX_COORD:g} "
                             "(rescale the model; --offset moves a scene far from the origin)")


def _clean_faces(verts, faces, path, warnings) -> np.ndarray:
    bad_v = ~np.isfinite(verts).all(axis=1)
    bad = bad_v[faces].any(axis=1)
    if bad.any():
        warnings.append(f"dropped {int(bad.sum())} faces with non-finite vertices")
    f = faces[~bad]
    degenerate = _degenerate(verts, f)
    if degenerate.any():
        warnings.append(f"dropped {int(degenerate.sum())} degenerate faces")
    f = f[~degenerate]
    if len(f) == 0:
        raise InputError(f"--model {path}: no valid triangles (all faces degenerate or non-finite)")
    return f


def _degenerate(verts, faces) -> np.ndarray:
    """(F,) True for faces of zero (or non-finite) area."""
    tri = verts[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return ~(area2 > 0)


def _component_labels(faces: np.ndarray, verts: np.ndarray) -> np.ndarray:
    """Connected components over shared vertices (scipy's sparse graph, vectorized)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    # vertices at the same position are one vertex (STL and split-normal OBJ duplicate them)
    _, canon = np.unique(verts, axis=0, return_inverse=True)
    faces = canon.ravel()[faces]
    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    cols = np.concatenate([faces[:, 1], faces[:, 2]])
    n_verts = int(faces.max()) + 1
    g = coo_matrix((np.ones(rows.size, dtype=np.int8), (rows, cols)), shape=(n_verts, n_verts))
    _, vlabel = connected_components(g, directed=False)
    return vlabel[faces[:, 0]]


def _grid_labels(verts, faces, n: int) -> np.ndarray:
    cen = verts[faces].mean(axis=1)
    lo, hi = cen.min(0), cen.max(0)
    size = max(float((hi - lo).max()), 1e-12) / n
    cell = np.minimum(((cen - lo) / size).astype(np.int64), n)
    return np.unique(cell, axis=0, return_inverse=True)[1].ravel()


def _merge_small(labels, verts, faces, merge_below: int) -> np.ndarray:
    """Merge components with fewer than ``merge_below`` faces by the grid cell of their centre."""
    uniq, inv, counts = np.unique(labels, return_inverse=True, return_counts=True)
    small = counts[inv] < merge_below
    if not small.any():
        return inv
    cen = verts[faces[small]].mean(axis=1)
    lo, hi = cen.min(0), cen.max(0)
    cell = np.minimum(((cen - lo) / (max(float((hi - lo).max()), 1e-12) / 16)).astype(np.int64), 16)
    cell_id = cell[:, 0] * 289 + cell[:, 1] * 17 + cell[:, 2]
    out = inv.copy()
    out[small] = uniq.size + np.unique(cell_id, return_inverse=True)[1].ravel()
    return np.unique(out, return_inverse=True)[1].ravel()


def _normals(verts, faces) -> np.ndarray:
    """Area-weighted vertex normals (vectorized)."""
    tri = verts[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vn = np.zeros_like(verts)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    norm = np.linalg.norm(vn, axis=1, keepdims=True)
    return np.where(norm > 0, vn / np.where(norm > 0, norm, 1), [0, 0, 1])


def _colors(n: int, seed: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (0.35 + 0.6 * rng.random((n, 3))).astype(np.float32)


def _from_labels(verts, faces, labels, path, warnings, meta) -> Scene:
    """One object per label: faces sorted by label, one shared vertex buffer (base vertex 0)."""
    order = np.argsort(labels, kind="stable")
    faces, labels = faces[order], labels[order]
    n = int(labels.max()) + 1
    counts = np.bincount(labels, minlength=n)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]]) * 3
    normals = _normals(verts, faces)
    used = np.unique(faces)
    # compact the vertex buffer to the vertices faces use
    remap = np.full(len(verts), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    v = verts[used]
    f = remap[faces]
    tri = v[f]  # (T, 3, 3)
    starts = first // 3
    bmin = np.minimum.reduceat(tri.min(axis=1), starts)
    bmax = np.maximum.reduceat(tri.max(axis=1), starts)
    centers = (bmin + bmax) / 2
    d = np.linalg.norm(tri - centers[labels][:, None, :], axis=2).max(axis=1)
    radii = np.maximum.reduceat(d, starts)
    origin = (bmin.min(axis=0) + bmax.max(axis=0)) / 2  # float32 vertices relative to it
    return Scene(vertices=np.concatenate([v - origin, normals[used]], axis=1).astype(np.float32),
                 indices=f.ravel().astype(np.uint32), first_index=first.astype(np.int64),
                 index_count=(counts * 3).astype(np.int64), base_vertex=np.zeros(n, dtype=np.int64),
                 bmin=bmin, bmax=bmax, centers=centers, radii=radii, colors=_colors(n), origin=origin,
                 name=Path(path).stem, meta={**meta, "source": str(path), "warnings": warnings,
                                              "up": _guess_up(bmin, bmax)})


def _guess_up(bmin, bmax) -> list[float]:
    """The axis of smallest extent is taken as up for wide scenes (z for CAD, y for glTF)."""
    ext = bmax.max(0) - bmin.min(0)
    up = [0.0, 0.0, 0.0]
    up[int(np.argmin(ext)) if ext.min() < 0.5 * ext.max() else 2] = 1.0
    return up


def _from_meshes(meshes, path, warnings) -> Scene:
    """One object per scene-graph node instance (transforms already applied by trimesh)."""
    sizes = np.array([len(m.vertices) for m in meshes])
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    verts = np.concatenate([np.asarray(m.vertices, dtype=np.float64) for m in meshes])
    faces = np.concatenate([np.asarray(m.faces, dtype=np.int64) + o for m, o in zip(meshes, offsets)])
    labels = np.repeat(np.arange(len(meshes)), [len(m.faces) for m in meshes])
    local = faces - np.repeat(offsets, [len(m.faces) for m in meshes])[:, None]  # indices within each mesh
    own = np.repeat(sizes, [len(m.faces) for m in meshes])[:, None]
    if (local < 0).any() or (local >= own).any():
        raise InputError(f"--model {path}: a face uses a vertex index outside its mesh (corrupt file)")
    _check_indices_and_range(verts, faces, path)
    bad_v = ~np.isfinite(verts).all(axis=1)
    bad_obj = np.zeros(len(meshes), dtype=bool)
    np.logical_or.at(bad_obj, labels, bad_v[faces].any(axis=1))
    if bad_obj.any():
        warnings.append(f"dropped {int(bad_obj.sum())} objects with non-finite vertices")
        keep = ~bad_obj[labels]
        faces, labels = faces[keep], labels[keep]
        if len(faces) == 0:
            raise InputError(f"--model {path}: every object has non-finite vertices")
    degenerate = _degenerate(verts, faces)
    if degenerate.any():
        warnings.append(f"dropped {int(degenerate.sum())} degenerate faces")
        faces, labels = faces[~degenerate], labels[~degenerate]
    labels = np.unique(labels, return_inverse=True)[1].ravel()
    return _from_labels(verts, faces, labels, path, warnings, {"split": "nodes"})
