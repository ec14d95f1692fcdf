"""A wall file: one JSON file that describes a real display wall (``--wall FILE``).

```json
{"grid": "2x2", "tile": "1920x1080", "mullion": "40x40",
 "displays": [{"rank": 0, "display": ":0.0", "position": [0, 0]}, ...]}
```

``grid`` (ROWSxCOLS), ``tile`` (WxH pixels) and ``mullion`` (MXxMY pixels hidden between
adjacent tiles) set the canvas; ``displays`` (optional, one entry per rank label) gives each
rank its X display (``:0.1``, or absent for ``$DISPLAY``) and its window's position on that
display (absent: the tile's place on one big screen holding the canvas). Flags given on the
command line override the file. Every error names the file and the entry. Pure: no X, no MPI.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

from multigpu.errors import InputError

KEYS = {"grid", "tile", "mullion", "displays", "comment"}
DISPLAY_KEYS = {"rank", "display", "position"}


@dataclass(frozen=True)
class Wall:
    """What a wall file says; ``None`` where it is silent."""

    file: str
    grid: tuple[int, int] | None = None
    tile: tuple[int, int] | None = None
    mullion: tuple[int, int] | None = None
    displays: dict[int, str | None] = field(default_factory=dict)
    positions: dict[int, tuple[int, int]] = field(default_factory=dict)


def _pair(value, what: str, zero: bool = False) -> tuple[int, int]:
    if isinstance(value, str):
        m = re.fullmatch(r"\s*(\d+)\s*x\s*(\d+)\s*", value)
        got = (int(m.group(1)), int(m.group(2))) if m else None
    elif isinstance(value, list) and len(value) == 2 and all(type(v) is int for v in value):
        got = (value[0], value[1])
    else:
        got = None
    if got is None or min(got) < (0 if zero else 1):
        kind = ">= 0" if zero else ">= 1"
        raise ValueError(f"{what} must be 'AxB' or [A, B] with integers {kind}, got {json.dumps(value)}")
    return got


def load_wall(path: str) -> Wall:
    """Read and check a wall file; every error is one line naming the file and the entry."""
    where = f"--wall {path}"
    try:
        doc = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise InputError(f"{where}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{where}: cannot read it ({exc.__class__.__name__}: {exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{where}: not JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{where}: the top level must be a JSON object with grid, tile, mullion, displays")
    unknown = sorted(set(doc) - KEYS)
    if unknown:
        raise InputError(f"{where}: unknown key '{unknown[0]}' (known: {', '.join(sorted(KEYS - {'comment'}))})")
    try:
        grid = _pair(doc["grid"], "grid") if "grid" in doc else None
        tile = _pair(doc["tile"], "tile") if "tile" in doc else None
        mullion = _pair(doc["mullion"], "mullion", zero=True) if "mullion" in doc else None
    except ValueError as exc:
        raise InputError(f"{where}: {exc}") from None
    displays, positions = {}, {}
    entries = doc.get("displays", [])
    if not isinstance(entries, list):
        raise InputError(f"{where}: displays must be a list of {{rank, display, position}} entries")
    for i, e in enumerate(entries):  # one entry per display, at most a few dozen
        at = f"{where}: displays[{i}]"
        if not isinstance(e, dict) or type(e.get("rank")) is not int or e["rank"] < 0:
            raise InputError(f"{at}: needs \"rank\": a rank label >= 0")
        bad = sorted(set(e) - DISPLAY_KEYS)
        if bad:
            raise InputError(f"{at}: unknown key '{bad[0]}' (known: rank, display, position)")
        r = e["rank"]
        if r in displays:
            raise InputError(f"{at}: rank {r} appears twice")
        d = e.get("display")
        if d is not None and (not isinstance(d, str) or not re.fullmatch(r"[\w.\-]*:\d+(\.\d+)?", d)):
            raise InputError(f"{at}: display must be an X display name like ':0' or ':0.1', got {json.dumps(d)}")
        displays[r] = d
        if "position" in e:
            p = e["position"]
            if not (isinstance(p, list) and len(p) == 2 and all(type(v) is int for v in p)):
                raise InputError(f"{at}: position must be [x, y] in pixels, got {json.dumps(p)}")
            positions[r] = (p[0], p[1])
    return Wall(path, grid, tile, mullion, displays, positions)


def check_ranks(wall: Wall, ranks: int) -> None:
    """Every display entry names a rank of a ``ranks``-rank wall."""
    for r in sorted(wall.displays):
        if r >= ranks:
            raise InputError(f"--wall {wall.file}: displays entry for rank {r}, but the wall has ranks 0..{ranks - 1}")


def describe(wall: Wall, grid, tile, mullion) -> str:
    """The layout a wall file gives, as lines for ``multigpu wall check``."""
    from multigpu.core.canvas import Canvas

    c = Canvas(grid, tile, mullion)
    W, H = c.size
    lines = [f"{wall.file}: {grid[0]}x{grid[1]} wall of {tile[0]}x{tile[1]} tiles, mullions {mullion[0]}x{mullion[1]}",
             f"canvas {W}x{H} pixels ({c.visible[0]}x{c.visible[1]} visible)",
             f"{'rank':>4} {'row':>3} {'col':>3}  {'display':<10} {'window at':<12} canvas pixels [x0, y0) top-left"]
    for k, (x0, y0, x1, y1) in enumerate(c.tiles()):  # K tiles
        row, col = k % grid[0], k // grid[0]
        top = H - y1
        pos = wall.positions.get(k, (int(x0), int(top)))
        disp = wall.displays.get(k) or "$DISPLAY"
        lines.append(f"{k:>4} {row:>3} {col:>3}  {disp:<10} {f'{pos[0]},{pos[1]}':<12} [{x0}, {top})")
    return "\n".join(lines)


def check_command(path: str, grid_only: bool = False) -> str:
    """``multigpu wall check``: the file checked with a run's own limits, then its layout (or
    only ROWSxCOLS, for launch scripts)."""
    from multigpu.config import WalkConfig

    wall = load_wall(path)
    grid, tile, mullion = wall.grid or WalkConfig.grid, wall.tile or WalkConfig.tile, wall.mullion or (0, 0)
    check_ranks(wall, grid[0] * grid[1])
    WalkConfig(grid=grid, tile=tile, mullion=mullion)
    return f"{grid[0]}x{grid[1]}" if grid_only else describe(wall, grid, tile, mullion)
