"""Scenes from names and files: the built-in plant, users' models through trimesh, the cache.

Objects (``--split``): ``auto`` (default) takes one object per node instance of a scene graph
(glTF/GLB, multi-object OBJ; transforms applied) and the connected components of a single
mesh; ``components`` and ``grid:N`` (N cells along the longest axis, the paper's future-work
idea) apply to any file, scene graphs included. With components, pieces under ``merge_below``
triangles are merged by grid cell so object counts stay sane. Then, for the wall the scene is
loaded for (``ranks``), objects too big to balance are cut into spatial clusters
(``cluster.auto_cluster``: no object above 1/(4K) of the triangles, at least 8 objects per
rank, and on walls of 9+ ranks no object above 1/(64K)), unless ``--cluster N`` (explicit
size, 0 = never) says otherwise. ``meta['objects']`` records what was done and why. Faces
with non-finite vertices and degenerate faces are dropped and counted
(``scene.meta['warnings']``); a file shorter than its header promises is refused.

Up axis (``meta['up']``, used by generated camera paths): ``--up`` if given; glTF's +Y by its
specification; for a flat scene (smallest extent under 0.35 of the largest: a city, a track) its thin axis; else
the format's usual convention: +Y for OBJ and PLY (Blender/Maya exports, scanned data), +Z for
STL and OFF (CAD, 3-D printing). ``meta['up_source']`` says which rule decided.

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

from multigpu.errors import InputError, check_file
from multigpu.scene import lod as scene_lod
from multigpu.scene import looks
from multigpu.scene import parts as scene_parts
from multigpu.scene.blocks import blocks, per_object
from multigpu.scene.labels import face_labels
from multigpu.scene.layout import FORMAT_VERSION, Scene

FORMATS = {".obj", ".ply", ".stl", ".off", ".gltf", ".glb"}
#: up axis by format convention, where the format has one (glTF: the specification)
FORMAT_UP = {".gltf": "+y", ".glb": "+y", ".obj": "+y", ".ply": "+y", ".stl": "+z", ".off": "+z"}
AXES = {"x": 0, "y": 1, "z": 2}
#: a scene whose smallest extent is under this share of its largest is flat: its thin axis is up
FLAT = 0.35


@dataclass(frozen=True)
class SceneSpec:
    """What to load: a built-in scene by name or a model file, and how to split it."""

    scene: str = "plant"
    model: str | None = None
    split: str = "auto"
    merge_below: int = 64
    triangles: int = 100_000  # the one default size of the built-in scenes
    copies: int = 1
    seed: int = 0
    cluster: int | None = None  # cut objects above N triangles into clusters (0: never; None: auto)
    ranks: int = 4  # the wall the scene is prepared for (automatic clustering)
    up: str | None = None  # x|y|z|-x|-y|-z, None: format convention / heuristic
    lods: bool = True  # build (and cache, and hold) levels of detail: only where the run can draw them

    def __post_init__(self):
        if self.model is None and self.scene not in BUILTIN:
            known = ", ".join(BUILTIN)
            raise InputError.of("scene", f"must be one of {known} (or give a model file), got '{self.scene}'")
        if not re.fullmatch(r"auto|components|grid:[1-9][0-9]*", self.split):
            raise InputError.of("split", f"must be 'auto', 'components' or 'grid:N' with N >= 1, got '{self.split}'")
        if self.up is not None and not re.fullmatch(r"[+-]?[xyz]", self.up):
            raise InputError.of("up", f"must be one of x, y, z, -x, -y, -z, got '{self.up}'")
        if self.ranks < 1:
            raise InputError(f"ranks must be >= 1, got {self.ranks}")
        if self.triangles < 1000:
            raise InputError.of("triangles", f"must be >= 1000, got {self.triangles}")
        if self.seed < 0:
            raise InputError.of("seed", f"must be >= 0, got {self.seed}")
        if self.copies < 1:
            raise InputError.of("copies", f"must be >= 1, got {self.copies}")
        if self.cluster is not None and self.cluster < 0:
            raise InputError.of("cluster", f"must be >= 0 (0 keeps objects whole), got {self.cluster}")


def cache_dir() -> Path:
    return Path(os.environ.get("MULTIGPU_CACHE", Path.home() / ".cache" / "multigpu"))


def _key(*parts) -> str:
    """The cache key: the format, the part size and levels of detail (the cached layout), the spec."""
    shape = (FORMAT_VERSION, scene_parts.PART_TRIS, scene_lod.LEVELS, scene_lod.RATIO, scene_lod.MIN_TRIS)
    return hashlib.sha1(repr(shape + parts).encode()).hexdigest()[:16]


def load_scene(spec: SceneSpec, use_cache: bool = True) -> tuple[Scene, dict]:
    """The scene for ``spec`` and load facts (seconds, whether the cache was hit)."""
    t0 = time.perf_counter()
    cluster = "auto" if spec.cluster is None else spec.cluster
    wall = spec.ranks if spec.cluster is None else None  # the automatic choice depends on the wall
    if spec.model is not None:
        src = check_file(spec.model, "model", "model file")
        if src.suffix.lower() not in FORMATS:
            known = ", ".join(sorted(FORMATS))
            raise InputError.of("model", f"{src}: unsupported extension '{src.suffix}' (use {known})")
        st = src.stat()
        key = _key(str(src.resolve()), st.st_size, st.st_mtime_ns, spec.split, spec.merge_below, cluster, wall,
                   *(() if spec.lods else ("no levels of detail",)))
        name = f"{src.stem}-{key}.npz"
        make = lambda: load_model(src, spec.split, spec.merge_below)
    else:
        key = _key(spec.scene, spec.triangles, spec.copies, spec.seed, cluster, wall,
                   *(() if spec.lods else ("no levels of detail",)))
        name = f"{spec.scene}-{key}.npz"
        make = lambda: BUILTIN[spec.scene](spec)

    def build() -> Scene:
        from multigpu.scene.cluster import auto_cluster, split_objects
        from multigpu.scene.parts import with_parts

        scene = make()
        modelled = scene.n_objects
        if spec.cluster is None:
            size, why = auto_cluster(scene.tris, spec.ranks)
        else:
            size, why = spec.cluster, ("--cluster 0: objects kept as modelled" if spec.cluster == 0
                                       else f"--cluster {spec.cluster}: objects above it cut into clusters")
        if size:
            scene = split_objects(scene, size)
        scene.meta["objects"] = {"split": scene.meta.get("split", spec.split), "modelled": modelled,
                                 "objects": scene.n_objects, "cluster": int(size), "why": why}
        scene = with_parts(scene)  # parts for culling, then levels of detail where the run can use them
        return scene_lod.with_lods(scene) if spec.lods else scene
    path = cache_dir() / name
    scene, cached = None, False
    if use_cache and path.is_file():
        try:
            scene, cached = Scene.load(path), True
        except InputError:
            path.unlink(missing_ok=True)  # stale or damaged: rebuild
    if scene is None:
        scene = build()
        if use_cache:
            try:
                scene.save(path)
                scene = Scene.load(path)  # the built arrays go; the file's mapped pages are shared per host
            except OSError:
                pass  # a read-only cache only costs time
    if spec.up is not None:
        scene.meta["up"], scene.meta["up_source"] = axis_vector(spec.up), "--up"
    info = {"seconds": time.perf_counter() - t0, "cached": cached, "cache": str(path) if use_cache else None}
    return scene, info


def axis_vector(name: str) -> list[float]:
    """'y', '+y' or '-z' as a unit vector."""
    v = [0.0, 0.0, 0.0]
    v[AXES[name[-1]]] = -1.0 if name.startswith("-") else 1.0
    return v


def axis_name(v) -> str:
    """A unit axis vector back to '+y' / '-z' (the nearest axis)."""
    v = np.asarray(v, dtype=np.float64)
    i = int(np.argmax(np.abs(v)))
    return ("-" if v[i] < 0 else "+") + "xyz"[i]


def _plant(spec: SceneSpec) -> Scene:
    from multigpu.scene.plant import generate_plant

    return generate_plant(spec.triangles, spec.copies, spec.seed)


def _fill(spec: SceneSpec) -> Scene:
    from multigpu.scene.fill import generate_fill

    return generate_fill(spec.triangles, panels=24 * spec.copies, seed=spec.seed)


def _city(spec: SceneSpec) -> Scene:
    from multigpu.scene.city import generate_city

    return generate_city(spec.triangles, spec.seed)


# built-in scenes: the plant (triangle-bound, the paper's kind), a fill-bound contrast, and a
# city of many small objects on big ground pieces (per-frame overhead); for ``fill``,
# ``--copies`` multiplies the 24 panels (depth complexity)
BUILTIN = {"plant": _plant, "fill": _fill, "city": _city}


# ---------------------------------------------------------------- model files

def load_model(path: Path, split: str = "auto", merge_below: int = 64) -> Scene:
    """Load a model file through trimesh into the GPU layout (one object per node or piece)."""
    import trimesh

    kind = path.suffix.lstrip(".").upper()
    declared = declared_counts(path)
    _check_size(path, declared)
    try:
        with np.errstate(all="ignore"):
            loaded = trimesh.load(str(path), process=False)
    except Exception as exc:
        why = str(exc).splitlines()[0] if str(exc) else "corrupt file"
        promise = (f"; the header promises {declared[0]} vertices and {declared[1]} faces: truncated or corrupt"
                   if declared and declared[0] >= 0 else "")
        what = f"{exc.__class__.__name__}: {why}"
        raise InputError.of("model", f"{path}: cannot read as {kind} ({what}){promise}") from None
    warnings: list[str] = []
    if isinstance(loaded, trimesh.Scene):
        meshes = [g for g in loaded.dump(concatenate=False) if isinstance(g, trimesh.Trimesh)]
        meshes = [m for m in meshes if len(m.faces)]
        if not meshes:
            raise InputError.of("model", f"{path}: the file holds no triangles (empty, or not a {kind} file)")
        if len(meshes) > 1:
            del loaded  # the meshes (transforms applied) are copies: _from_meshes lets them go
            return _from_meshes(meshes, path, warnings, split, merge_below)
        mesh = meshes.pop()  # the list lets it go with the rest
    elif isinstance(loaded, trimesh.Trimesh):
        mesh = loaded
    else:
        raise InputError.of("model", f"{path}: holds no triangle mesh (got {type(loaded).__name__})")
    if len(mesh.faces) == 0:
        raise InputError.of("model", f"{path}: the mesh is empty (no triangles)")
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    _check_complete(path, declared, len(verts), len(faces))
    _check_indices_and_range(verts, faces, path)
    faces = _narrow(faces, len(verts))
    (rgba, colors_from), normals = looks.mesh_colors(mesh), looks.mesh_normals(mesh)
    del mesh, loaded  # trimesh's int64 faces go: the model is held once, as verts and faces
    faces = _clean_faces(verts, faces, path, warnings)
    split = "components" if split == "auto" else split
    look = Look(rgba, normals, None, {"colors": colors_from, "materials": int(colors_from == "material")})
    return _from_labels(verts, faces, face_labels(verts, faces, split, merge_below), path, warnings, {"split": split},
                        look)


def _narrow(faces: np.ndarray, n_verts: int) -> np.ndarray:
    """``faces`` as int32 where the vertex count allows (half the bytes of trimesh's int64;
    every later pass indexes with it), converted a block at a time."""
    if n_verts >= 2**31 or faces.dtype == np.int32:
        return faces
    out = np.empty(faces.shape, dtype=np.int32)
    for s, e in blocks(len(faces)):
        out[s:e] = faces[s:e]
    return out


def declared_counts(path: Path) -> tuple[int, int] | None:
    """(vertices, faces) a file's header promises, where the format has one: PLY's element
    counts, binary STL's triangle count (vertices then unknown: -1). None otherwise."""
    suffix = path.suffix.lower()
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return None
    if suffix == ".ply" and head.startswith(b"ply"):
        end = head.find(b"end_header")
        text = head[:end if end >= 0 else len(head)].decode("ascii", "replace")
        counts = dict(re.findall(r"^element\s+(\w+)\s+(\d+)", text, flags=re.M))
        if "vertex" in counts:
            return int(counts["vertex"]), int(counts.get("face", 0))
    if suffix == ".stl" and len(head) >= 84 and not head[:5].lower().startswith(b"solid"):
        n = int(np.frombuffer(head[80:84], dtype="<u4")[0])
        return -1, n
    return None


def _check_size(path: Path, declared) -> None:
    """Binary STL: the header's triangle count fixes the file size; refuse a shorter file."""
    if declared is None or path.suffix.lower() != ".stl":
        return
    want_f = declared[1]
    size = path.stat().st_size
    if size < 84 + 50 * want_f:
        raise InputError.of("model", f"{path}: not a complete binary STL: its header promises {want_f} triangles "
                         f"({84 + 50 * want_f} bytes), the file has {size} bytes (truncated, or not an STL file)")


def _check_complete(path: Path, declared, n_verts: int, n_faces: int) -> None:
    """Refuse a file that holds fewer vertices or faces than its header promises (truncated).
    (Polygons with more than 3 corners become several triangles, so more faces is fine.)"""
    if declared is None or declared[0] < 0:
        return
    want_v, want_f = declared
    if n_verts < want_v or n_faces < want_f:
        raise InputError.of("model", f"{path}: truncated: the header promises {want_v} vertices and {want_f} faces, "
                         f"the file holds {n_verts} and {n_faces}")


#: coordinates beyond this (in model units) leave float64 no precision for a renderer
MAX_COORD = 1e15


def _check_indices_and_range(verts, faces, path) -> None:
    """Refuse face indices outside the vertex list and coordinates no renderer can use."""
    if faces.size and (faces.min() < 0 or faces.max() >= len(verts)):
        bad = int(faces.max()) if faces.max() >= len(verts) else int(faces.min())
        raise InputError.of("model", f"{path}: a face uses vertex index {bad}, but the file has "
                         f"{len(verts)} vertices (corrupt or truncated file)")
    finite = np.isfinite(verts).all(axis=1)
    if finite.any():
        reach = max(float(np.abs(verts[s:e][finite[s:e]]).max(initial=0.0)) for s, e in blocks(len(verts)))
        if reach > MAX_COORD:
            raise InputError.of("model", f"{path}: coordinates reach {reach:.3g}, beyond +-{MAX_COORD:g} "
                             "(rescale the model; --offset moves a scene far from the origin)")


def _clean_faces(verts, faces, path, warnings) -> np.ndarray:
    """``faces`` without those using a non-finite vertex or of zero area (the same array
    when none is dropped: no copy)."""
    bad_v = ~np.isfinite(verts).all(axis=1)
    bad = np.zeros(len(faces), dtype=bool)
    for s, e in blocks(len(faces)):
        bad[s:e] = bad_v[faces[s:e]].any(axis=1)
    if bad.any():
        warnings.append(f"dropped {int(bad.sum())} faces with non-finite vertices")
    degenerate = _degenerate(verts, faces) & ~bad
    if degenerate.any():
        warnings.append(f"dropped {int(degenerate.sum())} degenerate faces")
    bad |= degenerate
    if bad.all():
        raise InputError.of("model", f"{path}: no valid triangles (all faces degenerate or non-finite)")
    return faces[~bad] if bad.any() else faces


def _degenerate(verts, faces) -> np.ndarray:
    """(F,) True for faces of zero (or non-finite) area."""
    out = np.empty(len(faces), dtype=bool)
    for s, e in blocks(len(faces)):
        tri = verts[faces[s:e]]
        area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        out[s:e] = ~(area2 > 0)
    return out


@dataclass
class Look:
    """What a model file says of its look, aligned with its vertices: ``rgba`` (V, 4) uint8 or
    None, ``normals`` (V, 3) or None (then crease-angle normals are computed), ``groups`` (F,):
    the file's mesh of each face (faces of different meshes are never smooth across), and what
    ``scene info`` reports (``meta``)."""

    rgba: np.ndarray | None = None
    normals: np.ndarray | None = None
    groups: np.ndarray | None = None
    meta: dict | None = None


def _from_labels(verts, faces, labels, path, warnings, meta, look: Look | None = None) -> Scene:
    """One object per label: faces in label order, one shared vertex buffer (base vertex 0).
    Normals are the file's, else crease-angle ones (``looks.crease_normals``: a vertex on a sharp
    edge is split); colours the file's (``looks``), else one neutral grey. Every pass over the
    faces goes a block at a time, in label order through ``order`` (no sorted copy of the faces)."""
    look = look or Look()
    rgba, normals = look.rgba, look.normals
    looked = dict(look.meta or {"colors": "none", "materials": 0})
    if normals is None:
        source, normals, faces = looks.crease_normals(verts, faces, look.groups)
        looked["normals"] = (f"computed: smooth below a {looks.CREASE:g} degree crease "
                             f"({len(source) - len(verts):+d} vertices on sharp edges)")
        verts = verts[source]
        rgba = rgba[source] if rgba is not None else None
    else:
        looked["normals"] = "from the file"
    order = np.argsort(labels, kind="stable")
    n = int(labels.max()) + 1
    counts = np.bincount(labels, minlength=n)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]]) * 3
    sorted_blocks = lambda: ((s, e, faces[order[s:e]], labels[order[s:e]]) for s, e in blocks(len(faces)))
    if rgba is None:
        colors, vertex_colors = np.tile(np.array(looks.NEUTRAL, dtype=np.float32), (n, 1)), None
    else:
        colors, vertex_colors = looks.split_colors(rgba, faces, labels, n)
    looked["vertex_colors"] = vertex_colors is not None
    used = np.zeros(len(verts), dtype=bool)  # compact the vertex buffer to the vertices faces use
    for s, e in blocks(len(faces)):
        used[faces[s:e]] = True
    used = np.flatnonzero(used)
    remap = np.full(len(verts), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    bmin, bmax, radii = np.full((n, 3), np.inf), np.full((n, 3), -np.inf), np.zeros(n)
    for s, e, f, lab in sorted_blocks():
        tri = verts[f]  # (b, 3, 3)
        per_object(np.minimum, tri.min(axis=1), lab, bmin)
        per_object(np.maximum, tri.max(axis=1), lab, bmax)
    centers = (bmin + bmax) / 2
    for s, e, f, lab in sorted_blocks():
        d = np.linalg.norm(verts[f] - centers[lab][:, None, :], axis=2).max(axis=1)
        per_object(np.maximum, d, lab, radii)
    origin = (bmin.min(axis=0) + bmax.max(axis=0)) / 2  # float32 vertices relative to it
    vertices = np.empty((used.size, 6), dtype=np.float32)
    for s, e in blocks(used.size):
        vertices[s:e, :3] = verts[used[s:e]] - origin
        vertices[s:e, 3:] = normals[used[s:e]]
    del normals
    indices = np.empty(faces.size, dtype=np.uint32)
    for s, e, f, _ in sorted_blocks():
        indices[3 * s:3 * e] = remap[f].ravel()
    return Scene(vertices=vertices,
                 indices=indices, first_index=first.astype(np.int64),
                 index_count=(counts * 3).astype(np.int64), base_vertex=np.zeros(n, dtype=np.int64),
                 bmin=bmin, bmax=bmax, centers=centers, radii=radii, colors=colors, origin=origin,
                 vertex_colors=None if vertex_colors is None else np.ascontiguousarray(vertex_colors[used]),
                 name=Path(path).stem, meta={**meta, "source": str(path), "warnings": warnings, "look": looked,
                                              **guess_up(Path(path).suffix.lower(), bmin, bmax)})


def guess_up(suffix: str, bmin, bmax) -> dict:
    """The up axis by the rules in the module doc: {'up': vector, 'up_source': why}."""
    if suffix in (".gltf", ".glb"):
        return {"up": axis_vector("+y"), "up_source": "glTF convention (+Y up)"}
    ext = np.asarray(bmax).max(0) - np.asarray(bmin).min(0)
    if ext.max() > 0 and ext.min() < FLAT * ext.max():
        thin = "xyz"[int(np.argmin(ext))]
        return {"up": axis_vector(thin), "up_source": f"flat scene: its thin axis ({thin})"}
    conv = FORMAT_UP.get(suffix, "+z")
    return {"up": axis_vector(conv), "up_source": f"{suffix[1:].upper()} convention ({conv[1:].upper()} up)"}


def _from_meshes(meshes, path, warnings, split: str = "auto", merge_below: int = 64) -> Scene:
    """One object per scene-graph node instance (transforms already applied by trimesh), or
    the whole graph's triangles cut by an explicit ``--split components|grid:N``."""
    sizes = np.array([len(m.vertices) for m in meshes])
    n_faces = np.array([len(m.faces) for m in meshes])
    n_meshes = len(meshes)
    big = int(sizes.sum()) >= 2**31
    verts = np.empty((int(sizes.sum()), 3), dtype=np.float64)
    faces = np.empty((int(n_faces.sum()), 3), dtype=np.int64 if big else np.int32)
    rgba = np.empty((len(verts), 4), dtype=np.uint8)
    normals = np.empty((len(verts), 3), dtype=np.float64)
    any_rgba, all_normals, materials, kinds = False, True, set(), set()
    masked = np.zeros(len(faces), dtype=bool)  # faces a MASK material's alpha cutoff hides
    alpha = {"BLEND": 0, "MASK": 0}  # meshes of each glTF alpha mode
    v = f = 0
    for i in range(n_meshes):  # meshes, not frames: each is let go once copied (one copy held)
        m, meshes[i] = meshes[i], None
        mf = np.asarray(m.faces, dtype=np.int64)
        if mf.size and (mf.min() < 0 or mf.max() >= len(m.vertices)):
            raise InputError.of("model", f"{path}: a face uses a vertex index outside its mesh (corrupt file)")
        verts[v:v + len(m.vertices)] = m.vertices
        faces[f:f + len(mf)] = mf + v
        colors, kind = looks.mesh_colors(m)
        kinds.add(kind)
        if kind == "material":  # a material by name and colour (a loader may copy it per mesh)
            materials.add((getattr(m.visual.material, "name", None), tuple(colors[0])))
        any_rgba |= colors is not None
        rgba[v:v + len(m.vertices)] = colors if colors is not None else np.rint(np.array([*looks.NEUTRAL, 1.0]) * 255)
        mode, cutoff = looks.mesh_alpha(m)
        if mode in alpha:
            alpha[mode] += 1
        if mode == "MASK" and colors is not None:  # a face shows where any corner's alpha reaches the cutoff
            masked[f:f + len(mf)] = colors[mf][:, :, 3].max(axis=1) < np.rint(255 * cutoff)
        nrm = looks.mesh_normals(m) if all_normals else None
        all_normals &= nrm is not None
        if nrm is not None:
            normals[v:v + len(m.vertices)] = nrm
        v, f = v + len(m.vertices), f + len(mf)
        del m, mf
    meshes.clear()
    labels = np.repeat(np.arange(n_meshes), n_faces)
    look_meta = {"colors": ", ".join(sorted(k for k in kinds if k != "none")) or "none", "materials": len(materials),
                 "alpha": {"blend_drawn_opaque": alpha["BLEND"], "mask": alpha["MASK"],
                           "masked_faces": int(masked.sum())}}
    if masked.all():
        raise InputError.of("model", f"{path}: every face lies below its MASK material's alpha cutoff "
                                     "(nothing to draw)")
    if masked.any():
        warnings.append(f"left out {int(masked.sum())} faces below their MASK material's alpha cutoff")
        faces, labels = faces[~masked], labels[~masked]
    _check_indices_and_range(verts, faces, path)
    bad_v = ~np.isfinite(verts).all(axis=1)
    bad_obj = np.zeros(n_meshes, dtype=bool)
    np.logical_or.at(bad_obj, labels, bad_v[faces].any(axis=1))
    if bad_obj.any():
        warnings.append(f"dropped {int(bad_obj.sum())} objects with non-finite vertices")
        keep = ~bad_obj[labels]
        faces, labels = faces[keep], labels[keep]
        if len(faces) == 0:
            raise InputError.of("model", f"{path}: every object has non-finite vertices")
    degenerate = _degenerate(verts, faces)
    if degenerate.any():
        warnings.append(f"dropped {int(degenerate.sum())} degenerate faces")
        faces, labels = faces[~degenerate], labels[~degenerate]
    look = Look(rgba if any_rgba else None, normals if all_normals else None, labels, look_meta)
    if split != "auto":
        objects = face_labels(verts, faces, split, merge_below)
        return _from_labels(verts, faces, objects, path, warnings, {"split": split}, look)
    labels = np.unique(labels, return_inverse=True)[1].ravel()
    return _from_labels(verts, faces, labels, path, warnings, {"split": "nodes"}, look)
