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

from multigpu.core import jit
from multigpu.core.triangles import triangle_objects
from multigpu.scene.blocks import per_object
from multigpu.scene.layout import Scene
from multigpu.scene.simulation import Coloring, colours, describe, field, lookup


def derive(base: Scene, mesh, coloring: Coloring, path: Path) -> Scene | None:
    """Step ``mesh`` (read from ``path``, its cells those of ``base``'s file) in ``base``'s layout,
    coloured by ``coloring`` (its range fixed: the series'); None where it cannot be."""
    got = changes(base, mesh, coloring, path)
    return None if got is None else with_changes(base, *got)


def with_changes(base: Scene, changed: dict[str, np.ndarray], meta: dict) -> Scene:
    """``base`` with a step's own arrays (``changes``) and meta: that step's scene."""
    return Scene(**{**base._arrays(), **changed}, name=base.name, meta=meta)


def changes(base: Scene, mesh, coloring: Coloring, path: Path,
            compiled: bool | None = None) -> tuple[dict, dict] | None:
    """What step ``mesh`` (its file ``path``) changes of ``base``'s scene, ``(arrays by name, its
    meta)``: its vertices, colours, origin and boxes (all that a live stream sends to every rank,
    ``rank/pushed.py``); None where it cannot be made so (``derive``). ``compiled``: the placing
    by ``same_cells_kernel.py`` (None: where numba is installed) or ``place_reference``."""
    sim = base.meta.get("simulation")
    if base.sources is None or sim is None or sim.get("cells") is None:
        return None
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.shape[1] == 2:
        points = np.c_[points, np.zeros(len(points))]
    point, cell = base.sources[:, 0], base.sources[:, 1]
    if not np.isfinite(points).all() and not np.isfinite(points[point]).all():  # cells to drop: a build says which
        return None
    meta = {**sim, "fields": describe(mesh)}
    rgba = base.vertex_colors
    if coloring.color_by is not None:
        values, where, label = field(mesh, coloring.color_by, path)
        if where != sim.get("color_by", {}).get("where") or (where == "cell" and (cell < 0).any()):
            return None
        vmin, vmax = sim["color_by"]["range"] if coloring.range is None else coloring.range
        # each point's (cell's) colour once, then each vertex's: the same colours, a quarter of the work on quads
        rgba = colours(values, lookup(coloring.colormap), vmin, vmax)[cell if where == "cell" else point]
        meta["color_by"] = {**sim["color_by"], "field": label, "range": [float(vmin), float(vmax)]}
    tri, obj, part = _triangles(base)
    n, p = base.n_objects, 0 if part is None else len(base.part_count)
    place = _place_compiled if jit.use(compiled) else place_reference
    vertices, origin, bmin, bmax, far, part_bmin, part_bmax = place(points, point, tri, obj, part, n, p)
    changed = {"vertices": vertices, "bmin": bmin, "bmax": bmax, "centers": (bmin + bmax) / 2, "radii": np.sqrt(far),
               "origin": origin, "vertex_colors": rgba}
    if part is not None:
        changed["part_bmin"], changed["part_bmax"] = part_bmin, part_bmax
    return changed, {**base.meta, "simulation": meta, "source": str(path)}


#: the last first step's triangles (``triangle_objects``), kept with it: its later steps share them
_LAST: dict[int, tuple] = {}


def _triangles(base: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    got = _LAST.get(id(base))
    if got is None:  # (threads: a race computes them twice, never reads a half-made entry)
        got = (base, *triangle_objects(base), part_of_triangles(base))  # the scene held: its id is not reused
        _LAST.clear()
        _LAST[id(base)] = got
    return got[1:]


def place_reference(points: np.ndarray, point: np.ndarray, tri: np.ndarray, obj: np.ndarray,
                    part: np.ndarray | None, n: int, p: int) -> tuple:
    """Vertex ``v`` at ``points[point[v]]``: ``(vertices (V, 6) float32 relative to the origin
    with smooth normals, origin (the centre of their bounds, a build's), bmin, bmax (n, 3) of the
    objects' triangles ``tri`` (their objects ``obj``) as drawn, each object's farthest corner's
    squared distance from its box's centre (n,), part_bmin, part_bmax (p, 3) of the parts
    ``part`` (None: none))``. The numpy reference of ``same_cells_kernel._place``."""
    pos = points[point]
    origin = (pos.min(axis=0) + pos.max(axis=0)) / 2
    vertices = np.empty((len(pos), 6), dtype=np.float32)
    vertices[:, :3] = pos - origin
    corners = vertices[:, :3][tri].astype(np.float64) + origin  # (T, 3, 3) world, as drawn
    vertices[:, 3:] = vertex_normals(corners, tri, len(pos))
    bmin, bmax, far = np.full((n, 3), np.inf), np.full((n, 3), -np.inf), np.zeros(n)
    c0, c1, c2 = corners[:, 0], corners[:, 1], corners[:, 2]
    lo, hi = np.minimum(np.minimum(c0, c1), c2), np.maximum(np.maximum(c0, c1), c2)  # each triangle's box
    per_object(np.minimum, lo, obj, bmin)
    per_object(np.maximum, hi, obj, bmax)
    at = ((bmin + bmax) / 2)[obj]
    square = lambda c: _squares(c - at)  # noqa: E731
    per_object(np.maximum, np.maximum(np.maximum(square(c0), square(c1)), square(c2)), obj, far)
    part_bmin, part_bmax = np.full((p, 3), np.inf), np.full((p, 3), -np.inf)
    if part is not None:
        per_object(np.minimum, lo, part, part_bmin)
        per_object(np.maximum, hi, part, part_bmax)
    return vertices, origin, bmin, bmax, far, part_bmin, part_bmax


def _place_compiled(points, point, tri, obj, part, n: int, p: int) -> tuple:
    from multigpu.scene.same_cells_kernel import _place

    vertices = np.empty((len(point), 6), dtype=np.float32)
    origin, far = np.empty(3), np.zeros(n)
    bmin, bmax = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
    part_bmin, part_bmax = np.full((p, 3), np.inf), np.full((p, 3), -np.inf)
    _place(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(point, dtype=np.int64),
           np.ascontiguousarray(tri, dtype=np.int64), np.ascontiguousarray(obj, dtype=np.int64),
           np.zeros(0, dtype=np.int64) if part is None else np.ascontiguousarray(part, dtype=np.int64),
           origin, vertices, bmin, bmax, far, part_bmin, part_bmax, np.zeros((len(point), 3)))
    return vertices, origin, bmin, bmax, far, part_bmin, part_bmax


def _squares(d: np.ndarray) -> np.ndarray:
    """Each row's sum of squares, left to right (as the kernel sums them)."""
    return (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2]


def vertex_normals(corners: np.ndarray, tri: np.ndarray, n: int) -> np.ndarray:
    """(n, 3) unit normals: at each vertex the area-weighted sum of its triangles' normals
    (``corners`` (T, 3, 3) of triangles ``tri``); +z where they cancel."""
    fn = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    at = tri.ravel()
    normals = np.stack([np.bincount(at, weights=np.repeat(fn[:, k], 3), minlength=n) for k in range(3)], axis=1)
    length = np.sqrt(_squares(normals))[:, None]
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
