"""One step of a simulation's ADIOS2 stream as a mesh: the variables a running code writes, checked
and named, as meshio's mesh (``scene/simulation.py`` then makes the surface the wall draws).

A step holds ``points`` (P, 3) or (P, 2) floats, one or more cell arrays named after their kind
(``triangle`` (n, 3), ``quad`` (n, 4), ``tetra`` (n, 4), ``hexahedron`` (n, 8), ``wedge`` (n, 6),
``pyramid`` (n, 5): integer point indices), optionally a scalar ``time``, and fields: an array of P
rows is a point field, one of as many rows as the cells (a single cell kind) a cell field. A step
without points or cells (or whose cell variables hold none), with indices outside its points or
with non-finite or out-of-range values where indices belong is refused in one line; a variable
that fits neither the points nor the cells (or of no column) is named and left out. Pure: no ADIOS2, no MPI, no GL.
"""

from __future__ import annotations

import numpy as np

from multigpu.errors import InputError

#: ``--model``'s prefix of a stream (``rank/spool.py`` reads it)
PREFIX = "adios2:"
#: the cell kinds a stream may hold, by the variable's name: corners a cell
CELLS = {"triangle": 3, "quad": 4, "tetra": 4, "hexahedron": 8, "wedge": 6, "pyramid": 5}
#: the most points or cells one step may hold (a bound on what a door reads)
MOST = 1 << 28


def step_mesh(values: dict[str, np.ndarray], step: int, source: str):
    """``(mesh, time, notes)`` of one stream step's variables (``values``: name -> array): meshio's
    mesh, the step's ``time`` (None where it has none) and a line for each variable left out."""
    import meshio

    where = f"{source}: step {step}"
    have = ", ".join(sorted(values)) or "none"
    if "points" not in values:
        raise InputError.of("model", f"{where}: no 'points' variable (the step has: {have})")
    points = np.asarray(values["points"])
    if points.ndim != 2 or points.shape[1] not in (2, 3) or points.dtype.kind not in "fiu" or not \
            0 < len(points) <= MOST:
        raise InputError.of("model", f"{where}: 'points' must be (P, 3) or (P, 2) numbers, got shape "
                                     f"{points.shape} of {points.dtype}")
    cells = []
    for kind, k in CELLS.items():
        if kind not in values:
            continue
        c = np.asarray(values[kind])
        if c.ndim != 2 or c.shape[1] != k or c.dtype.kind not in "iu" or len(c) > MOST:
            raise InputError.of("model", f"{where}: '{kind}' must be (n, {k}) integer point indices, got shape "
                                         f"{c.shape} of {c.dtype}")
        if len(c) and (int(c.min()) < 0 or int(c.max()) >= len(points)):
            bad = int(c.max()) if c.max() >= len(points) else int(c.min())
            raise InputError.of("model", f"{where}: '{kind}' uses point {bad}, but the step has {len(points)} points")
        cells.append((kind, c.astype(np.int64)))
    if not cells:
        raise InputError.of("model", f"{where}: no cell variable ({', '.join(CELLS)}; the step has: {have})")
    n_cells = sum(len(c) for _, c in cells)
    if not n_cells:
        raise InputError.of("model", f"{where}: its cell variables hold no cell "
                                     f"({', '.join(f'{k} {c.shape}' for k, c in cells)})")
    point_data, cell_data, notes = {}, {}, []
    time = None
    for name, v in values.items():
        if name == "points" or name in CELLS:
            continue
        a = np.asarray(v)
        if name == "time":
            if a.size == 1 and a.dtype.kind in "fiu" and np.isfinite(a).all():
                time = float(a.reshape(-1)[0])
                continue
        if a.dtype.kind not in "fiu" or a.ndim not in (1, 2) or (a.ndim == 2 and a.shape[1] == 0):
            notes.append(f"{where}: variable '{name}' ({a.dtype}, shape {a.shape}) is no field: left out")
        elif len(a) == len(points):
            point_data[name] = a
        elif len(cells) == 1 and len(a) == n_cells:
            cell_data[name] = [a]
        else:
            notes.append(f"{where}: variable '{name}' of {len(a) if a.ndim else 0} rows fits neither the "
                         f"{len(points)} points nor the {n_cells} cells: left out")
    return meshio.Mesh(points, cells, point_data=point_data, cell_data=cell_data), time, notes
