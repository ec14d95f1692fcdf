"""Simulation results through meshio: a mesh of any cells as the surface the wall draws,
coloured by one of its fields.

meshio reads the formats simulation codes write (``FORMATS``: VTU, legacy VTK, XDMF, Exodus,
Gmsh, Abaqus, ...; VTP by way of ``scene/vtp.py``). Volume cells (tetrahedra, hexahedra, wedges,
pyramids; the corners of their quadratic kinds) are shown as their boundary: the faces no two
cells share, wound outwards (away from their cell's centre); triangles, quads and polygons are
kept. Every face is fanned into triangles. Lines and vertices are not drawn; other cell kinds are named in a warning.

``--color-by NAME`` colours the surface by a point field (per vertex, blended across faces) or a
cell field (per face: its vertices unshared, flat); a vector field by its magnitude, or one
component with ``NAME:x|y|z|K``. ``--colormap`` is any of matplotlib's maps, ``--range MIN,MAX``
fixes the values at its ends (default: the field's own range); NaN values are grey. Pure numpy
and meshio: no MPI, no GL.
"""

from __future__ import annotations

import contextlib
import functools
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multigpu.errors import InputError

#: the extensions read through meshio (the others trimesh reads: ``files.FORMATS``)
FORMATS = {".vtu", ".vtp", ".vtk", ".xdmf", ".xmf", ".exo", ".e", ".ex2", ".msh", ".inp", ".mesh", ".med", ".cgns",
           ".su2", ".ugrid", ".dat", ".f3grid", ".avs", ".vol"}
#: a volume cell's faces, by its corners (any winding: ``surface`` turns them outwards)
VOLUME = {"tetra": (4, [[0, 1, 2], [0, 1, 3], [1, 2, 3], [0, 2, 3]]),
          "hexahedron": (8, [[0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]),
          "wedge": (6, [[0, 1, 2], [3, 4, 5], [0, 1, 4, 3], [1, 2, 5, 4], [2, 0, 3, 5]]),
          "pyramid": (5, [[0, 1, 2, 3], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])}
#: quadratic and other higher-order kinds, drawn by their corners
CORNERS = {"tetra10": "tetra", "hexahedron20": "hexahedron", "hexahedron24": "hexahedron",
           "hexahedron27": "hexahedron", "wedge12": "wedge", "wedge15": "wedge", "wedge18": "wedge",
           "pyramid13": "pyramid", "pyramid14": "pyramid", "triangle6": "triangle", "triangle7": "triangle",
           "quad8": "quad", "quad9": "quad"}
#: surface cells by their corner counts
SURFACE = {"triangle": 3, "quad": 4}
#: cells with nothing to draw as a surface
SKIPPED = {"vertex", "line", "line3", "line4"}
#: the colour of a NaN value (RGBA8)
NAN_RGBA = (128, 128, 128, 255)


@dataclass(frozen=True)
class Coloring:
    """How a simulation's surface is coloured (``load``): the field (None: no colours), matplotlib's
    map, and the values at its ends (None: the field's own range)."""

    color_by: str | None = None
    colormap: str = "viridis"
    range: tuple[float, float] | None = None


def read(path: Path):
    """``path`` through meshio, or one line naming why not; a ``.vtp`` (which meshio does not
    read) as the UnstructuredGrid it is rewritten to (``scene/vtp.py``)."""
    import meshio

    if Path(path).suffix.lower() == ".vtp":
        return _read_vtp(Path(path))
    said = io.StringIO()
    try:  # meshio prints a reader's ReadError and exits: its words kept, the exit caught
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            return meshio.read(str(path))
    except (Exception, SystemExit) as exc:  # meshio raises many kinds: each reader its own
        lines = [ln.strip() for ln in said.getvalue().splitlines() if ln.strip()]
        why = (lines[0] if lines else str(exc).splitlines()[0] if isinstance(exc, Exception) and str(exc)
               else exc.__class__.__name__)
        raise InputError.of("model", f"{path}: cannot read as {path.suffix.lstrip('.').upper()} (meshio: {why})") \
            from None


def _read_vtp(path: Path):
    """A VTK XML PolyData file through meshio, by way of a rewritten ``.vtu`` (what it leaves out:
    ``mesh.info["notes"]``)."""
    import os
    import tempfile

    from multigpu.scene.vtp import as_unstructured

    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError.of("model", f"{path}: cannot read it ({exc.__class__.__name__})") from None
    text, notes = as_unstructured(data, str(path))
    fd, tmp = tempfile.mkstemp(suffix=".vtu", prefix="multigpu-vtp-")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(text)
        try:
            mesh = read(Path(tmp))
        except InputError as exc:
            raise InputError.of("model", f"{path}: cannot read as VTP (meshio: "
                                         f"{exc.message.split('(meshio: ', 1)[-1]}") from None
    finally:
        os.unlink(tmp)
    mesh.info = {"notes": notes}
    return mesh


def _kind(cell_type: str) -> str:
    """A cell kind as drawn: its linear kind, ``polygon`` for meshio's polygons."""
    kind = CORNERS.get(cell_type, cell_type)
    return "polygon" if kind.startswith("polygon") else kind


def surface(mesh, path: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(faces (F, 3) int64 point indices, owner (F,) each triangle's cell as the file numbers its
    cells, block after block) and warnings: the boundary of the volume cells and every surface
    cell, fanned into triangles, wound outwards."""
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise InputError.of("model", f"{path}: points must be 2-D or 3-D, got shape {points.shape}")
    vol: dict[int, list] = {3: [], 4: []}  # face arity: [(faces, owners, cell centres)]
    surf: list = []
    skipped, unknown = 0, {}
    offset = 0
    for block in mesh.cells:
        data = np.asarray(block.data, dtype=np.int64)
        kind, n = _kind(block.type), len(data)
        owners = offset + np.arange(n, dtype=np.int64)
        offset += n
        if n == 0:
            continue
        if kind in VOLUME:
            k, faces = VOLUME[kind]
            corners = data[:, :k]
            centre = _pad3(points)[corners].mean(axis=1)
            for f in faces:
                vol[len(f)].append((corners[:, f], owners, centre))
        elif kind in SURFACE or kind == "polygon":
            surf.append((data[:, :SURFACE.get(kind, data.shape[1])], owners))
        elif kind in SKIPPED:
            skipped += n
        else:
            unknown[block.type] = unknown.get(block.type, 0) + n
    warnings = []
    if skipped:
        warnings.append(f"{skipped} line and vertex cells not drawn")
    if unknown:
        warnings.append("cells of unsupported kinds not drawn: " + ", ".join(f"{v} {k}" for k, v in unknown.items()))
    p3 = _pad3(points)
    tris, owner, known = [], [], {}
    for arity, got in vol.items():
        if not got:
            continue
        faces = np.concatenate([g[0] for g in got])
        own = np.concatenate([g[1] for g in got])
        centre = np.concatenate([g[2] for g in got])
        keys = np.sort(faces, axis=1)
        _, first, count = np.unique(keys, axis=0, return_index=True, return_counts=True)
        outer = np.sort(first[count == 1])  # faces of one cell only: the boundary
        tris.append(_fan(_outwards(p3, faces[outer], centre[outer])))
        owner.append(np.repeat(own[outer], arity - 2))
        known[arity] = keys[first]  # every volume face, to drop surface cells lying on one
    for faces, own in surf:
        shared = _on_volume(faces, known.get(faces.shape[1]))
        faces, own = faces[~shared], own[~shared]
        tris.append(_fan(faces))
        owner.append(np.repeat(own, faces.shape[1] - 2))
    if not tris or not sum(len(t) for t in tris):
        kinds = ", ".join(sorted({b.type for b in mesh.cells})) or "none"
        raise InputError.of("model", f"{path}: no cells to draw as a surface (cell kinds: {kinds})")
    return np.concatenate(tris), np.concatenate(owner), warnings


def _pad3(points: np.ndarray) -> np.ndarray:
    """(P, 3): 2-D points on z = 0."""
    return points if points.shape[1] == 3 else np.c_[points, np.zeros(len(points))]


def _outwards(points: np.ndarray, faces: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``faces`` (n, k) reversed where their normal points into their cell (towards ``centre``)."""
    p = points[faces]
    normal = np.cross(p[:, 2] - p[:, 0], p[:, -1] - p[:, 1]) if faces.shape[1] == 4 else \
        np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    inward = np.einsum("ij,ij->i", normal, p.mean(axis=1) - centre) < 0
    faces = faces.copy()
    faces[inward] = faces[inward, ::-1]
    return faces


def _fan(faces: np.ndarray) -> np.ndarray:
    """(n, k) polygons as (n * (k - 2), 3) triangles, each a fan from its first corner."""
    k = faces.shape[1]
    fan = np.stack([np.zeros(k - 2, dtype=np.int64), np.arange(1, k - 1), np.arange(2, k)], axis=1)
    return faces[:, fan].reshape(-1, 3)


def _on_volume(faces: np.ndarray, volume_keys) -> np.ndarray:
    """(n,) bool: the surface cells that are a volume cell's face (drawn once, as the boundary)."""
    if volume_keys is None or not len(volume_keys):
        return np.zeros(len(faces), dtype=bool)
    keys = np.ascontiguousarray(np.sort(faces, axis=1))
    row = np.dtype((np.void, keys.dtype.itemsize * keys.shape[1]))
    known = np.ascontiguousarray(volume_keys).view(row).ravel()
    return np.isin(keys.view(row).ravel(), known)


def field_names(mesh) -> list[str]:
    """The point and cell fields of ``mesh``, as ``--color-by`` names them."""
    return [*mesh.point_data, *(k for k in mesh.cell_data if k not in mesh.point_data)]


def field(mesh, name: str, path: Path) -> tuple[np.ndarray, str, str]:
    """(values, where, label) of ``--color-by NAME[:magnitude|:x|:y|:z|:K]``: (P,) per point or
    (C,) per cell (cells numbered as ``surface`` numbers them), ``point`` or ``cell``."""
    base, _, part = name.partition(":")
    if base in mesh.point_data:
        values, where = np.asarray(mesh.point_data[base]), "point"
    elif base in mesh.cell_data:
        values, where = np.concatenate([np.asarray(v) for v in mesh.cell_data[base]]), "cell"
    else:
        have = ", ".join(field_names(mesh)) or "none"
        raise InputError.of("color-by", f"{path}: no field '{base}' (the fields: {have})")
    n = len(mesh.points) if where == "point" else sum(len(b.data) for b in mesh.cells)
    if values.shape[0] != n:
        raise InputError.of("color-by", f"{path}: field '{base}' has {values.shape[0]} values for {n} "
                                         f"{where}s")
    values = values.reshape(n, -1).astype(np.float64)
    k = values.shape[1]
    if not part:
        return (values[:, 0] if k == 1 else np.linalg.norm(values, axis=1)), where, base if k == 1 else \
            f"{base} (magnitude)"
    if part == "magnitude":
        return np.linalg.norm(values, axis=1), where, f"{base} (magnitude)"
    index = "xyz".find(part) if part in ("x", "y", "z") else (int(part) if part.isdigit() else -1)
    if not 0 <= index < k:
        raise InputError.of("color-by", f"{path}: field '{base}' has {k} components: no component '{part}' "
                                         f"(use magnitude, x, y, z or 0..{k - 1})")
    return values[:, index], where, f"{base} ({part})"


@functools.lru_cache(maxsize=8)
def lookup(colormap: str) -> np.ndarray:
    """(256, 4) uint8: matplotlib's ``colormap`` sampled at 256 evenly spaced values."""
    import matplotlib

    try:
        cmap = matplotlib.colormaps[colormap]
    except KeyError:
        some = ", ".join(n for n in ("viridis", "plasma", "inferno", "magma", "cividis", "turbo", "coolwarm",
                                     "jet", "gray"))
        raise InputError.of("colormap", f"unknown colour map '{colormap}' (matplotlib's names: {some}, ...)") from None
    table = np.round(cmap(np.linspace(0.0, 1.0, 256)) * 255).astype(np.uint8)
    table.flags.writeable = False  # one table a map, shared by its callers
    return table


def colours(values: np.ndarray, table: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """(n, 4) uint8: each value's entry of ``table`` (``lo`` the first, ``hi`` the last; NaN grey)."""
    span = hi - lo
    x = (values - lo) / span if span > 0 else np.full(values.shape, 0.5)
    idx = np.clip(np.floor(np.nan_to_num(x, nan=0.0) * (len(table) - 1) + 0.5), 0, len(table) - 1).astype(np.int64)
    out = table[idx]
    out[~np.isfinite(values)] = NAN_RGBA
    return out


def value_range(values: np.ndarray, fixed: tuple[float, float] | None) -> tuple[float, float]:
    """``fixed``, else the finite values' least and greatest (0, 1 where none is finite)."""
    if fixed is not None:
        return float(fixed[0]), float(fixed[1])
    finite = values[np.isfinite(values)]
    return (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)


def load(path: Path, color_by: str | None = None, colormap: str = "viridis",
         fixed: tuple[float, float] | None = None):
    """``path`` as a trimesh mesh of its surface, coloured by ``color_by`` (None: no colours),
    and what ``scene info`` says of it (``meta``: the fields, the colouring, warnings)."""
    import trimesh

    mesh = read(path)
    faces, owner, warnings = surface(mesh, path)
    warnings = [*(mesh.info or {}).get("notes", []), *warnings] if isinstance(mesh.info, dict) else warnings
    points = _pad3(np.asarray(mesh.points, dtype=np.float64))
    meta = {"fields": describe(mesh), "warnings": warnings}
    meta["cells"] = cells_key(mesh)
    rgba = None
    table = lookup(colormap) if color_by is not None else None
    # each vertex's point and cell in the file (-1: a point's vertex, shared by its cells): a later
    # step with these cells fills the same layout from its own points (``scene/same_cells.py``)
    sources = np.stack([np.arange(len(points)), np.full(len(points), -1)], axis=1)
    if color_by is not None:
        values, where, label = field(mesh, color_by, path)
        lo, hi = value_range(values, fixed)
        meta["color_by"] = {"field": label, "where": where, "range": [lo, hi], "colormap": colormap}
        if where == "cell":  # flat per face: each triangle its own three vertices
            sources = np.stack([faces.ravel(), np.repeat(owner, 3)], axis=1)
            points, faces = points[faces].reshape(-1, 3), np.arange(3 * len(faces), dtype=np.int64).reshape(-1, 3)
            rgba = np.repeat(colours(values[owner], table, lo, hi), 3, axis=0)
        else:
            rgba = colours(values, table, lo, hi)
    used = np.unique(faces)
    if len(used) < len(points):  # only the points the surface uses
        remap = np.full(len(points), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        points, faces, sources = points[used], remap[faces], sources[used]
        rgba = None if rgba is None else rgba[used]
    out = trimesh.Trimesh(points, faces, vertex_colors=rgba, process=False)
    meta["sources"] = sources  # popped by ``files.load_model`` (an array, not for ``scene info``)
    return out, meta


def cells_key(mesh) -> str:
    """A digest of ``mesh``'s cells and point count: two steps with the same key have the same
    surface, vertex for vertex (``scene/same_cells.py``)."""
    import hashlib

    h = hashlib.sha1(str(len(mesh.points)).encode())
    for block in mesh.cells:
        data = np.ascontiguousarray(block.data, dtype=np.int64)
        h.update(f"{block.type}:{data.shape}".encode())
        h.update(data.tobytes())
    return h.hexdigest()


def describe(mesh) -> list[dict]:
    """Each field's name, where it lives, its components and its finite values' range."""
    out = []
    for where, data in (("point", mesh.point_data), ("cell", mesh.cell_data)):
        for name, values in data.items():
            v = np.asarray(values) if where == "point" else np.concatenate([np.asarray(x) for x in values])
            v = v.reshape(len(v), -1).astype(np.float64) if v.size else np.zeros((0, 1))
            mag = v[:, 0] if v.shape[1] == 1 else np.linalg.norm(v, axis=1)
            lo, hi = value_range(mag, None)
            out.append({"name": name, "where": where, "components": int(v.shape[1]), "range": [lo, hi]})
    return out
