"""Users' model files through trimesh into the scene layout: objects, up axis, look, checks.

Objects (``--split``): ``auto`` takes one object per node instance of a scene graph (glTF/GLB,
multi-object OBJ; transforms applied) and the connected components of a single mesh;
``components`` and ``grid:N`` apply to any file (``labels.py``). Faces with non-finite vertices
and degenerate faces are dropped and counted (``scene.meta['warnings']``); a file shorter than
its header promises, face indices out of range and coordinates beyond ``MAX_COORD`` are refused.
The look (colours, normals, glTF alpha) is the file's (``looks.py``). Up axis: ``guess_up``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multigpu.errors import InputError
from multigpu.scene import looks, simulation, textures
from multigpu.scene.blocks import blocks, per_object
from multigpu.scene.gltf_load import animated, joined, mesh_deltas, mesh_skins, nodes_of, skin_pack
from multigpu.scene.gltf_load import pack as pack_morphs
from multigpu.scene.gltf_motion import check as check_animations
from multigpu.scene.labels import face_labels
from multigpu.scene.layout import Scene

FORMATS = {".obj", ".ply", ".stl", ".off", ".gltf", ".glb", *simulation.FORMATS}
#: up axis by format convention, where the format has one (glTF: the specification)
FORMAT_UP = {".gltf": "+y", ".glb": "+y", ".obj": "+y", ".ply": "+y", ".stl": "+z", ".off": "+z"}
AXES = {"x": 0, "y": 1, "z": 2}
#: a scene whose smallest extent is under this share of its largest is flat: its thin axis is up
FLAT = 0.35


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


def load_model(path: Path, split: str = "auto", merge_below: int = 64,
               coloring: simulation.Coloring | None = None) -> Scene:
    """Load a model file through trimesh (a simulation's through meshio: ``simulation.py``, coloured
    by ``coloring``) into the GPU layout (one object per node or piece)."""
    import trimesh

    kind = path.suffix.lstrip(".").upper()
    declared = declared_counts(path)
    _check_size(path, declared)
    if path.suffix.lower() in (".gltf", ".glb"):
        check_animations(path)
    warnings: list[str] = []
    sim = sources = None
    if path.suffix.lower() in simulation.FORMATS:
        coloring = coloring or simulation.Coloring()
        loaded, sim = simulation.load(path, coloring.color_by, coloring.colormap, coloring.range)
        warnings += sim.pop("warnings")
        sources = sim.pop("sources")
    else:
        try:
            with np.errstate(all="ignore"):
                loaded = trimesh.load(str(path), process=False)
        except Exception as exc:
            why = str(exc).splitlines()[0] if str(exc) else "corrupt file"
            promise = (f"; the header promises {declared[0]} vertices and {declared[1]} faces: truncated or corrupt"
                       if declared and declared[0] >= 0 else "")
            what = f"{exc.__class__.__name__}: {why}"
            raise InputError.of("model", f"{path}: cannot read as {kind} ({what}){promise}") from None
    nodes = morph = skin = None  # an animated glTF's node of each mesh, its morph targets' deltas, its skins
    if isinstance(loaded, trimesh.Scene):
        meshes = [g for g in loaded.dump(concatenate=False) if isinstance(g, trimesh.Trimesh)]
        meshes = [m for m in meshes if len(m.faces)]
        if not meshes:
            raise InputError.of("model", f"{path}: the file holds no triangles (empty, or not a {kind} file)")
        nodes = nodes_of(path, loaded, meshes) if path.suffix.lower() in (".gltf", ".glb") else None
        morph = mesh_deltas(path, meshes, nodes)  # (V, T, 3) world deltas of a glTF's morph targets, or None
        skin = mesh_skins(path, meshes, nodes)  # its skins' (V, 4) joints and weights, or None
        if len(meshes) > 1:
            del loaded  # the meshes (transforms applied) are copies: _from_meshes lets them go
            morph = None if morph is None else joined(morph, [len(m.vertices) for m in meshes])
            return animated(_from_meshes(meshes, path, warnings, split, merge_below, nodes, morph, skin), path, nodes,
                            split)
        morph = None if morph is None else joined(morph, [len(meshes[0].vertices)])
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
    layers = _layers(path, warnings)
    uv, image = textures.mesh_texture(mesh)
    texcoords = None if uv is None else _with_layer(uv, layers.layer(image, _material_name(mesh), _cutoff(mesh)))
    del mesh, loaded  # trimesh's int64 faces go: the model is held once, as verts and faces
    faces = _clean_faces(verts, faces, path, warnings)
    split = "components" if split == "auto" else split
    look = Look(rgba, normals, None, {"colors": colors_from, "materials": int(colors_from == "material")},
                texcoords, layers.pack(warnings), morph, skin, sources)
    scene = _from_labels(verts, faces, face_labels(verts, faces, split, merge_below), path, warnings,
                         {"split": split}, look)
    if sim is not None:
        scene.meta["simulation"] = sim
    return animated(scene, path, None if nodes is None else nodes * scene.n_objects, "auto")



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


def _layers(path: Path, warnings: list[str]) -> textures.Layers:
    """The model's texture layers, to be filled mesh by mesh, with its glTF samplers; a warning
    per image file it names that cannot be read (the material's colour stands in)."""
    doc = textures.gltf_json(path) if path.suffix.lower() in (".gltf", ".glb") else None
    for image in textures.missing_images(path, doc):
        warnings.append(f"texture {image}: missing or unreadable: its material's colour stands in")
    return textures.Layers(textures.gltf_samplers(doc))


def _material_name(mesh) -> str | None:
    return getattr(getattr(getattr(mesh, "visual", None), "material", None), "name", None)


def _cutoff(mesh) -> float:
    """The alpha below which a textured MASK material's fragments are left out (0: none)."""
    mode, cutoff = looks.mesh_alpha(mesh)
    return cutoff if mode == "MASK" else 0.0


def _put_texture(mesh, layers: textures.Layers, uvl: np.ndarray | None, at: int, n: int) -> np.ndarray | None:
    """A textured ``mesh``'s UVs and layer into rows ``at:`` of the model's (``n``, 3) ``uvl``,
    made (untextured: layer -1) at the first textured mesh; ``uvl`` as it is otherwise."""
    uv, image = textures.mesh_texture(mesh)
    layer = -1 if uv is None else layers.layer(image, _material_name(mesh), _cutoff(mesh))
    if layer >= 0:
        if uvl is None:
            uvl = np.zeros((n, 3), dtype=np.float32)
            uvl[:, 2] = -1.0
        uvl[at:at + len(uv), :2], uvl[at:at + len(uv), 2] = uv, layer
    return uvl


def _with_layer(uv: np.ndarray, layer: int) -> np.ndarray | None:
    """(V, 3) float32 UV and texture layer per vertex (None: the layer could not be had)."""
    if layer < 0:
        return None
    return np.concatenate([uv, np.full((len(uv), 1), layer, dtype=np.float32)], axis=1)


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
    texcoords: np.ndarray | None = None  # (V, 3) UV and layer (-1: untextured), ``textures.mesh_texture``
    textures: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # ``textures.Layers.pack``
    morph: np.ndarray | None = None  # (V, T, 3) a glTF's morph target deltas (``gltf_load.mesh_deltas``)
    skin: tuple | None = None  # (V, 4) joints and weights of a glTF's skins (``gltf_load.mesh_skins``)
    sources: np.ndarray | None = None  # (V, 2) a simulation's point and cell of each vertex (``simulation.load``)


def _from_labels(verts, faces, labels, path, warnings, meta, look: Look | None = None) -> Scene:
    """One object per label: faces in label order, one shared vertex buffer (base vertex 0).
    Normals are the file's, else crease-angle ones (``looks.crease_normals``: a vertex on a sharp
    edge is split); colours the file's (``looks``), else one neutral grey. Every pass over the
    faces goes a block at a time, in label order through ``order`` (no sorted copy of the faces)."""
    look = look or Look()
    rgba, normals, uvl = look.rgba, look.normals, look.texcoords
    looked = dict(look.meta or {"colors": "none", "materials": 0})
    looked["textures"] = textures.texture_info(look.textures)
    if normals is None:
        source, normals, faces = looks.crease_normals(verts, faces, look.groups)
        looked["normals"] = (f"computed: smooth below a {looks.CREASE:g} degree crease "
                             f"({len(source) - len(verts):+d} vertices on sharp edges)")
        verts = verts[source]
        rgba = rgba[source] if rgba is not None else None
        uvl = uvl[source] if uvl is not None else None
        look.morph = look.morph[source] if look.morph is not None else None
        look.skin = None if look.skin is None else tuple(a[source] for a in look.skin)
        look.sources = None if look.sources is None else look.sources[source]
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
                 texcoords=None if uvl is None else np.ascontiguousarray(uvl[used], dtype=np.float32),
                 sources=None if look.sources is None else np.ascontiguousarray(look.sources[used], dtype=np.int64),
                 **({} if uvl is None else dict(zip(("texels", "texture_levels", "texture_modes"), look.textures))),
                 **({} if look.morph is None else pack_morphs(look.morph, used, sorted_blocks, n)),
                 **({} if look.skin is None else skin_pack(*look.skin, verts, used, sorted_blocks)),
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


def _from_meshes(meshes, path, warnings, split: str = "auto", merge_below: int = 64,
                 nodes: list[int] | None = None, morph: np.ndarray | None = None, skin=None) -> Scene:
    """One object per scene-graph node instance (transforms already applied by trimesh), or
    the whole graph's triangles cut by an explicit ``--split components|grid:N``; ``nodes``: the
    glTF node of each mesh (an animated file's), kept per object in ``meta['gltf_nodes']``."""
    sizes = np.array([len(m.vertices) for m in meshes])
    n_faces = np.array([len(m.faces) for m in meshes])
    n_meshes = len(meshes)
    big = int(sizes.sum()) >= 2**31
    verts = np.empty((int(sizes.sum()), 3), dtype=np.float64)
    faces = np.empty((int(n_faces.sum()), 3), dtype=np.int64 if big else np.int32)
    rgba = np.empty((len(verts), 4), dtype=np.uint8)
    normals = np.empty((len(verts), 3), dtype=np.float64)
    any_rgba, all_normals, materials, kinds = False, True, set(), set()
    layers, uvl = _layers(path, warnings), None
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
        uvl = _put_texture(m, layers, uvl, v, len(verts))
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
    if layers.dropped:
        warnings.append(f"more than {textures.MAX_LAYERS} distinct textures: {layers.dropped} parts past them "
                        "show their material's colour")
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
    look = Look(rgba if any_rgba else None, normals if all_normals else None, labels, look_meta, uvl,
                layers.pack(warnings) if uvl is not None else None, morph, skin)
    if split != "auto":
        objects = face_labels(verts, faces, split, merge_below)
        return _from_labels(verts, faces, objects, path, warnings, {"split": split}, look)
    kept, labels = np.unique(labels, return_inverse=True)
    meta = {"split": "nodes", **({} if nodes is None else {"gltf_nodes": [nodes[k] for k in kept.tolist()]})}
    return _from_labels(verts, faces, labels.ravel(), path, warnings, meta, look)
