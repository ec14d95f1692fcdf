"""What a model looks like: its colours and normals from the file, as the renderer takes them.

Colours (``mesh_colors``): a mesh's vertex colours (PLY, OFF, OBJ, glTF ``COLOR_0``; face colours
spread to their vertices), else its material's colour (glTF ``baseColorFactor``, OBJ ``usemtl`` +
MTL ``Kd``) on every vertex, else none. A model with none is drawn in one neutral grey, not in
random colours: the per-object palette (``palette``, ``--colors objects``) is a view of what the
balancer moves, not of the model. ``split_colors`` turns per-vertex colours into one colour per
object where every object is uniform (a glTF part per material: nothing per vertex is kept).

Normals (``crease_normals``): the file's where it has them (``mesh_normals``); else each vertex's
normal is the area-weighted mean of the faces around it that meet at less than ``CREASE``
degrees, so a box keeps its flat faces and its sharp edges while a scan or a tessellated
cylinder stays smooth. A vertex where faces meet at a sharper angle is split, one copy per
smooth fan. Faces are adjacent where they share an edge by position (STL's unshared vertices
too) within one mesh of the file (``groups``). Pure numpy and scipy: no GL, no MPI.
"""

from __future__ import annotations

import numpy as np

#: faces meeting at less than this angle (degrees) are shaded smooth across their edge
CREASE = 30.0
#: a model's colour where the file gives none (RGB in [0, 1])
NEUTRAL = (0.72, 0.72, 0.72)
#: ``--colors``: the model's own colours, or a colour per object (what the balancer moves)
COLOR_VIEWS = ("model", "objects")


def palette(n: int, seed: int = 7) -> np.ndarray:
    """(n, 3) float32 pastel colours, one per object: the ``--colors objects`` view."""
    rng = np.random.default_rng(seed)
    return (0.35 + 0.6 * rng.random((n, 3))).astype(np.float32)


def mesh_colors(mesh) -> tuple[np.ndarray | None, str]:
    """A trimesh mesh's colours as (V, 4) uint8 RGBA per vertex, or None, and where they came
    from (``vertex colours``, ``face colours``, ``material``, ``none``)."""
    visual = getattr(mesh, "visual", None)
    kind = getattr(visual, "kind", None)
    n = len(mesh.vertices)
    if kind == "vertex":
        return np.ascontiguousarray(np.asarray(visual.vertex_colors, dtype=np.uint8).reshape(n, 4)), "vertex colours"
    if kind == "face":
        out = np.empty((n, 4), dtype=np.uint8)
        out[np.asarray(mesh.faces).ravel()] = np.repeat(np.asarray(visual.face_colors, dtype=np.uint8), 3, axis=0)
        return out, "face colours"
    material = getattr(visual, "material", None)
    rgba = _material_rgba(material)
    if rgba is None:
        return None, "none"
    return np.tile(rgba, (n, 1)), "material"


def _material_rgba(material) -> np.ndarray | None:
    """A material's base colour as (4,) uint8 (glTF PBR ``baseColorFactor``, OBJ ``Kd``), or None."""
    if material is None:
        return None
    if getattr(material, "baseColorTexture", None) is not None and getattr(material, "baseColorFactor", None) is None:
        return np.full(4, 255, dtype=np.uint8)  # glTF: the texture alone (a factor of one)
    for name in ("baseColorFactor", "main_color", "diffuse"):
        c = getattr(material, name, None)
        if c is not None:
            c = np.asarray(c, dtype=np.float64).ravel()
            if c.size >= 3:
                c = np.concatenate([c[:4], [255.0] * (4 - min(c.size, 4))])
                return np.clip(np.rint(c if c.max() > 1.0 else c * 255.0), 0, 255).astype(np.uint8)
    return None


def mesh_alpha(mesh) -> tuple[str, float]:
    """A mesh's glTF ``alphaMode`` (``OPAQUE``, ``MASK``, ``BLEND``) and ``alphaCutoff`` (0.5 by
    the specification where unset). MASK: the faces whose corners all lie below the cutoff are
    left out (exact for a material's one alpha; a face's corners decide where vertex alphas
    vary); BLEND: drawn opaque (``scene info`` says so)."""
    material = getattr(getattr(mesh, "visual", None), "material", None)
    mode = str(getattr(material, "alphaMode", None) or "OPAQUE").upper()
    cutoff = getattr(material, "alphaCutoff", None)
    return mode, 0.5 if cutoff is None else float(cutoff)


def mesh_normals(mesh) -> np.ndarray | None:
    """The normals the file gave a trimesh mesh, (V, 3), or None (none given: trimesh has not
    computed any; its cache holds the file's, transformed with the mesh)."""
    cache = getattr(getattr(mesh, "_cache", None), "cache", {})
    normals = cache.get("vertex_normals") if isinstance(cache, dict) else None
    if normals is None or len(normals) != len(mesh.vertices):
        return None
    normals = np.asarray(normals, dtype=np.float64)
    return normals if np.isfinite(normals).all() else None


def split_colors(rgba: np.ndarray, faces: np.ndarray, labels: np.ndarray, n: int) -> tuple[np.ndarray,
                                                                                             np.ndarray | None]:
    """Per-vertex ``rgba`` (V, 4) as ``(colors (n, 3) float32, vertex_colors or None)``: one colour
    per object where each object's vertices share one (nothing per vertex kept), else the mean as
    the object's colour and the vertex colours as they are."""
    corner = rgba[faces.ravel()].astype(np.int64)  # (3F, 4)
    lab = np.repeat(labels, 3)
    lo = np.full((n, 4), 255, dtype=np.int64)
    hi = np.zeros((n, 4), dtype=np.int64)
    np.minimum.at(lo, lab, corner)
    np.maximum.at(hi, lab, corner)
    counts = np.maximum(np.bincount(lab, minlength=n), 1)[:, None]
    mean = np.stack([np.bincount(lab, corner[:, c], minlength=n) for c in range(3)], axis=1) / counts
    colors = (mean / 255.0).astype(np.float32)
    if (lo == hi).all():
        return (lo[:, :3] / 255.0).astype(np.float32), None
    return colors, rgba


def crease_normals(verts: np.ndarray, faces: np.ndarray, groups: np.ndarray | None = None,
                   crease: float = CREASE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normals with sharp edges kept: ``(source, normals, faces)`` where vertex ``i`` of the result
    is ``verts[source[i]]`` with normal ``normals[i]`` and ``faces`` index the result.

    Corners of faces around one vertex that are joined, edge by edge, by faces meeting at less
    than ``crease`` degrees share a normal (the area-weighted sum of their faces'); a vertex whose
    corners fall into several such fans becomes one vertex per fan. ``groups`` (F,): faces of
    different groups are never adjacent (the file's meshes).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = len(faces)
    tri = verts[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # area-weighted (twice the area)
    length = np.linalg.norm(fn, axis=1)
    unit = fn / np.where(length > 0, length, 1.0)[:, None]
    topo = np.unique(verts, axis=0, return_inverse=True)[1].ravel()[faces]  # vertices by position
    # each face's three edges as (low, high) position ids, with the corners at each end
    a, b = topo, np.roll(topo, -1, axis=1)
    corner_a = np.arange(3 * F).reshape(F, 3)
    corner_b = np.roll(corner_a, -1, axis=1)
    swap = a > b
    lo, hi = np.where(swap, b, a).ravel(), np.where(swap, a, b).ravel()
    c_lo, c_hi = np.where(swap, corner_b, corner_a).ravel(), np.where(swap, corner_a, corner_b).ravel()
    face = np.repeat(np.arange(F), 3)
    group = np.zeros(F, dtype=np.int64) if groups is None else np.asarray(groups, dtype=np.int64)
    order = np.lexsort((hi, lo, group[face]))
    same = ((lo[order][1:] == lo[order][:-1]) & (hi[order][1:] == hi[order][:-1])
            & (group[face[order][1:]] == group[face[order][:-1]]))
    e1, e2 = order[:-1][same], order[1:][same]  # consecutive edges with one key: adjacent faces
    smooth = (unit[face[e1]] * unit[face[e2]]).sum(axis=1) >= np.cos(np.radians(crease))
    e1, e2 = e1[smooth], e2[smooth]
    src = np.concatenate([c_lo[e1], c_hi[e1]])
    dst = np.concatenate([c_lo[e2], c_hi[e2]])
    graph = coo_matrix((np.ones(src.size, dtype=np.int8), (src, dst)), shape=(3 * F, 3 * F))
    _, fan = connected_components(graph, directed=False)
    # a vertex of the result per (vertex of the file, fan): attributes stay with the file's vertex
    key = faces.ravel().astype(np.int64) * (3 * F) + fan
    uniq, inverse = np.unique(key, return_inverse=True)
    source = uniq // (3 * F)
    normals = np.zeros((uniq.size, 3))
    per_fan = np.zeros((fan.max() + 1, 3))
    np.add.at(per_fan, fan, np.repeat(fn, 3, axis=0))
    normals[inverse.ravel()] = per_fan[fan]
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(norm > 0, normals / np.where(norm > 0, norm, 1.0), [0.0, 0.0, 1.0])
    return source, normals, inverse.ravel().reshape(F, 3).astype(faces.dtype)
