"""A series step whose cells are its first step's: the first step's layout with this step's points,
normals and colours, no rebuild.

A simulation that deforms its mesh, or only changes its fields, writes the same cells every step
(a fixed-mesh solver, the example heat plate). Building each such step as a model of its own
(``scene/models.py``: meshio's read, crease normals, clusters, parts, levels of detail) costs
~100 ms for 18k triangles and seconds for millions, and cuts the objects the balancer learns
about anew each step. A step whose cells are the first step's (``simulation.cells_key``) takes the
first step's scene instead:

- each vertex from its point of this step (``Scene.sources``), relative to the centre of this
  step's bounds (as a build places it);
- smooth normals: the area-weighted sum of the faces at each vertex (the first step's sharp edges
  stay where they were: a vertex split there is split still);
- colours from this step's field over the series' range, at each vertex's point or cell;
- each object's and part's box and sphere from its triangles.

The index buffer, the objects, their parts and levels of detail are the first step's (the levels'
error bounds too, measured on the first step's shape). ``derive`` returns None where it cannot
(no sources, another field location, points that are not finite): the step is then built alone.
Pure numpy: no MPI, no GL.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.core.triangles import triangle_objects
from multigpu.scene.blocks import per_object
from multigpu.scene.layout import Scene
from multigpu.scene.simulation import Coloring, colours, describe, field, lookup


def derive(base: Scene, mesh, coloring: Coloring, path: Path) -> Scene | None:
    """Step ``mesh`` (read from ``path``, its cells those of ``base``'s file) in ``base``'s layout,
    coloured by ``coloring`` (its range fixed: the series'); None where it cannot be."""
    sim = base.meta.get("simulation")
    if base.sources is None or sim is None or sim.get("cells") is None:
        return None
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.shape[1] == 2:
        points = np.c_[points, np.zeros(len(points))]
    point, cell = base.sources[:, 0], base.sources[:, 1]
    pos = points[point]
    if not np.isfinite(pos).all():  # cells to drop: a build of its own says which
        return None
    meta = {**sim, "fields": describe(mesh)}
    rgba = base.vertex_colors
    if coloring.color_by is not None:
        values, where, label = field(mesh, coloring.color_by, path)
        if where != sim.get("color_by", {}).get("where") or (where == "cell" and (cell < 0).any()):
            return None
        vmin, vmax = sim["color_by"]["range"] if coloring.range is None else coloring.range
        rgba = colours(values[cell if where == "cell" else point], lookup(coloring.colormap), vmin, vmax)
        meta["color_by"] = {**sim["color_by"], "field": label, "range": [float(vmin), float(vmax)]}
    tri, obj, part = _triangles(base)
    origin = (pos.min(axis=0) + pos.max(axis=0)) / 2  # a build's: the centre of the step's bounds
    vertices = np.empty((len(pos), 6), dtype=np.float32)
    vertices[:, :3] = pos - origin
    corners = vertices[:, :3][tri].astype(np.float64) + origin  # (T, 3, 3) world, as drawn
    vertices[:, 3:] = vertex_normals(corners, tri, len(pos))
    n = base.n_objects
    bmin, bmax, far = np.full((n, 3), np.inf), np.full((n, 3), -np.inf), np.zeros(n)
    c0, c1, c2 = corners[:, 0], corners[:, 1], corners[:, 2]
    lo, hi = np.minimum(np.minimum(c0, c1), c2), np.maximum(np.maximum(c0, c1), c2)  # each triangle's box
    per_object(np.minimum, lo, obj, bmin)
    per_object(np.maximum, hi, obj, bmax)
    centers = (bmin + bmax) / 2
    at = centers[obj]
    square = lambda c: np.einsum("ij,ij->i", c - at, c - at)
    per_object(np.maximum, np.maximum(np.maximum(square(c0), square(c1)), square(c2)), obj, far)
    radii = np.sqrt(far)
    changed = {"vertices": vertices, "bmin": bmin, "bmax": bmax, "centers": centers, "radii": radii,
               "origin": origin, "vertex_colors": rgba}
    if part is not None:
        p = len(base.part_count)
        changed["part_bmin"], changed["part_bmax"] = np.full((p, 3), np.inf), np.full((p, 3), -np.inf)
        per_object(np.minimum, lo, part, changed["part_bmin"])
        per_object(np.maximum, hi, part, changed["part_bmax"])
    return Scene(**{**base._arrays(), **changed}, name=base.name,
                 meta={**base.meta, "simulation": meta, "source": str(path)})


#: the last first step's triangles (``triangle_objects``), kept with it: its later steps share them
_LAST: dict[int, tuple] = {}


def _triangles(base: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    got = _LAST.get(id(base))
    if got is None:  # (threads: a race computes them twice, never reads a half-made entry)
        got = (base, *triangle_objects(base), part_of_triangles(base))  # the scene held: its id is not reused
        _LAST.clear()
        _LAST[id(base)] = got
    return got[1:]


def vertex_normals(corners: np.ndarray, tri: np.ndarray, n: int) -> np.ndarray:
    """(n, 3) unit normals: at each vertex the area-weighted sum of its triangles' normals
    (``corners`` (T, 3, 3) of triangles ``tri``); +z where they cancel."""
    fn = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    at = tri.ravel()
    normals = np.stack([np.bincount(at, weights=np.repeat(fn[:, k], 3), minlength=n) for k in range(3)], axis=1)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 0, normals / np.where(length > 0, length, 1.0), [0.0, 0.0, 1.0])


def part_of_triangles(base: Scene) -> np.ndarray | None:
    """Each triangle's part (``triangle_objects``' order: objects by first index, each object's
    parts back to back from its first index); None: the scene has no parts."""
    if base.part_start is None:
        return None
    order = np.argsort(base.first_index, kind="stable")
    n_parts = np.diff(base.part_start)[order]
    rows = np.repeat(base.part_start[:-1][order] - np.concatenate([[0], np.cumsum(n_parts)[:-1]]), n_parts) \
        + np.arange(int(n_parts.sum()))
    return np.repeat(rows, base.part_count[rows] // 3)
