"""A projector wall's tiles, from its MPCDI file: each region of the buffer is the content one
output shows, and the rank that drives the output composes exactly that region.

The regions must form a grid of equal tiles, a whole number of buffer pixels apart: neighbours
overlap (the blend zone, a negative mullion of ``core/canvas.py``) or touch, and the grid's
canvas is the buffer. ``warp make`` writes such files; a calibration tool's regions are laid out
so when it is told the wall's content areas. Each tile is a rank's (column-major labels, row 0 on
top, as every wall here), so every output has its rank; the overlap's pixels are rendered once
and the exchange delivers them to every tile that holds them. Pure: no MPI, no GL.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multigpu.errors import InputError

#: how far (buffer pixels) a region's edge may lie from a whole pixel and still be one
SNAP = 0.01


@dataclass(frozen=True)
class Layout:
    """The wall an MPCDI file's regions make: its ``grid`` (rows, cols) of tiles, ``tile`` (w, h)
    and ``mullion`` (mx, my: negative where tiles overlap); ``labels``: each output's tile (its
    rank) and ``offsets`` its region's top-left in that tile (pixels), in the file's order of
    regions; ``per`` (rows, cols): the regions a tile holds (a rank driving several projectors)."""

    grid: tuple[int, int]
    tile: tuple[int, int]
    mullion: tuple[int, int]
    labels: tuple[int, ...]
    offsets: tuple[tuple[int, int], ...] = ()
    per: tuple[int, int] = (1, 1)
    cells: tuple[tuple[int, int], ...] = ()  # each output's (row, col) in its tile's block
    region: tuple[int, int] = (0, 0)  # (w, h) of each region: of the content each output shows

    @property
    def overlap(self) -> tuple[int, int]:
        """(ox, oy): pixels neighbours share each way (0 where they touch)."""
        return max(-self.mullion[0], 0), max(-self.mullion[1], 0)


def _edges(where, name: str, lo: float, size: float, full: int, axis: str) -> tuple[int, int]:
    """A region's first and end pixel along ``axis`` of a ``full``-pixel buffer; refused where
    they are not whole pixels inside the buffer."""
    a, b = lo * full, (lo + size) * full
    ia, ib = int(round(a)), int(round(b))
    if abs(a - ia) > SNAP or abs(b - ib) > SNAP or ia < 0 or ib > full or ib <= ia:
        raise InputError(f"{where}: region '{name}' spans {a:.2f}..{b:.2f} of the buffer's {full} pixels in {axis}: "
                         "a projector wall's regions must lie on whole pixels inside the buffer")
    return ia, ib


def _axis(where, starts: np.ndarray, lengths: np.ndarray, full: int, names, axis: str) -> tuple[int, int, np.ndarray]:
    """(tiles, length, gap) along one axis and each region's index there: the regions' starts
    ``step`` pixels apart from 0, every length the same, the last ending at the buffer's edge."""
    firsts = np.unique(starts)
    n = len(firsts)
    length = int(lengths[0])
    odd = np.flatnonzero(lengths != length)
    if len(odd):
        k = int(odd[0])
        raise InputError(f"{where}: region '{names[k]}' is {int(lengths[k])} pixels in {axis}, '{names[0]}' {length}: "
                         "a projector wall's regions must form a grid of equal tiles")
    step = int(firsts[1] - firsts[0]) if n > 1 else length
    want = np.arange(n) * step
    if firsts[0] != 0 or not np.array_equal(firsts, want) or want[-1] + length != full:
        raise InputError(f"{where}: the regions start at {', '.join(str(int(v)) for v in firsts)} of {full} pixels in "
                         f"{axis}: a projector wall's regions must form a grid of equal tiles, evenly apart, "
                         "covering the buffer")
    if step > length:
        raise InputError(f"{where}: the regions leave {step - length} pixels between them in {axis}: a projector "
                         "wall's regions touch or overlap")
    return n, step - length, np.searchsorted(firsts, starts)


def layout(where, buffer: tuple[int, int], outputs, grid: tuple[int, int] | None = None) -> Layout:
    """The wall of an MPCDI file's ``outputs`` (``mpcdi.Output``) on a ``buffer`` (w, h): a tile
    a region, or on a ``grid`` of ranks that divides the regions' each tile a block of them (its
    outputs side by side, overlapping as the regions do). InputError naming ``where`` (the file)
    and the region or grid that does not fit."""
    W, H = buffer
    names = [o.name for o in outputs]
    xs = np.array([_edges(where, o.name, o.area[0], o.area[2], W, "x") for o in outputs], dtype=np.int64)
    ys = np.array([_edges(where, o.name, o.area[1], o.area[3], H, "y") for o in outputs], dtype=np.int64)
    cols, mx, col = _axis(where, xs[:, 0], xs[:, 1] - xs[:, 0], W, names, "x")
    rows, my, row = _axis(where, ys[:, 0], ys[:, 1] - ys[:, 0], H, names, "y")
    if len(set((row * cols + col).tolist())) != len(names) or len(names) != rows * cols:
        raise InputError(f"{where}: {len(names)} regions on a {rows}x{cols} grid of tiles: a projector wall has "
                         "one region for every tile")
    grid = (rows, cols) if grid is None else tuple(int(v) for v in grid)
    if rows % grid[0] or cols % grid[1]:
        raise InputError(f"{where}: its regions make a {rows}x{cols} grid: a wall of {grid[0]}x{grid[1]} ranks must "
                         "divide it (each rank a block of regions)")
    a, b = rows // grid[0], cols // grid[1]
    w, h = int(xs[0, 1] - xs[0, 0]), int(ys[0, 1] - ys[0, 0])
    labels = (col // b) * grid[0] + row // a  # column-major, row 0 on top
    offsets = tuple(((int(c) % b) * (w + mx), (int(r) % a) * (h + my)) for r, c in zip(row, col))
    return Layout(grid, (b * w + (b - 1) * mx, a * h + (a - 1) * my), (mx, my), tuple(int(v) for v in labels),
                  offsets, (a, b), tuple((int(r) % a, int(c) % b) for r, c in zip(row, col)), (w, h))


@dataclass(frozen=True)
class Projected:
    """What an output is: its ``name`` (the MPCDI region's), ``size`` (w, h) in pixels, ``tile``
    (the rank that drives it), ``offset``: its region's top-left in that tile (content pixels),
    ``at``: its picture's top-left in the rank's picture (the rank's outputs side by side as their
    regions are, as one window, or one X screen spanning the rank's projectors, shows them)."""

    name: str
    size: tuple[int, int]
    tile: int = 0
    offset: tuple[int, int] = (0, 0)
    at: tuple[int, int] = (0, 0)


def outputs_by_tile(path: str, grid: tuple[int, int] | None = None) -> list[Projected]:
    """Every output of the MPCDI file at ``path`` on a wall of ``grid`` ranks (None: a rank a
    region), in the order of the tiles (ranks) that drive them, a tile's by their offsets."""
    from multigpu.warp import mpcdi

    buffer, outs = mpcdi.read(Path(path))
    lay = layout(path, buffer, outs, grid)
    cell = {(t, rc): o.size for o, t, rc in zip(outs, lay.labels, lay.cells)}  # a tile's block of outputs
    at = [(sum(cell[t, (r, c)][0] for c in range(cc)), sum(cell[t, (rr, cc)][1] for rr in range(r)))
          for t, (r, cc) in zip(lay.labels, lay.cells)]
    got = [Projected(o.name, o.size, t, off, xy) for o, t, off, xy in zip(outs, lay.labels, lay.offsets, at)]
    return sorted(got, key=lambda o: (o.tile, o.at[1], o.at[0]))


def eye_outputs(path: str, grid: tuple[int, int], right: str | None = None) -> list[Projected]:
    """``outputs_by_tile``; on a stereo projector wall (the right eyes' file ``right``) the left
    eyes' outputs named ``left/NAME`` and the right eyes' ``right/NAME``, their tiles ranks K.."""
    if right is None:
        return outputs_by_tile(path, grid)
    import dataclasses

    K = grid[0] * grid[1]
    return [dataclasses.replace(o, name=f"{eye}/{o.name}", tile=o.tile + e * K)
            for e, (eye, file) in enumerate((("left", path), ("right", right))) for o in outputs_by_tile(file, grid)]


def picture_size(outputs: list[Projected], tile: int) -> tuple[int, int]:
    """(w, h) of rank ``tile``'s picture: its outputs side by side (their offsets and sizes)."""
    mine = [o for o in outputs if o.tile == tile]
    return max(o.at[0] + o.size[0] for o in mine), max(o.at[1] + o.size[1] for o in mine)


def places(grid: tuple[int, int], outputs: list[Projected]) -> list[tuple[int, int]]:
    """Each tile's output window's top-left on one X screen spanning the projectors, by default:
    the ranks' pictures side by side as their tiles are (a row's widths to its left, a column's
    heights above it)."""
    rows = grid[0]
    sizes = [picture_size(outputs, k) for k in range(grid[0] * grid[1])]
    out = []
    for k in range(len(sizes)):  # tiles, a few dozen
        row, col = k % rows, k // rows
        x = sum(sizes[c * rows + row][0] for c in range(col))
        y = sum(sizes[col * rows + r][1] for r in range(row))
        out.append((x, y))
    return out
