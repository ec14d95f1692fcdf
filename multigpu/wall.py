"""A wall file: one JSON file that describes a real display wall (``--wall FILE``).

```json
{"grid": "2x2", "tile": "1920x1080", "mullion": "40x40",
 "displays": [{"rank": 0, "host": "pc1", "display": ":0", "position": [0, 0]}, ...]}
```

``grid`` (ROWSxCOLS), ``tile`` (WxH pixels) and ``mullion`` (MXxMY pixels hidden between
adjacent tiles) set the canvas; ``displays`` (optional; once given, one entry per rank label)
gives each rank its host (absent: this machine), its X display (``:0.1``, or absent for
``$DISPLAY``) and its window's position on that display (absent: the tile's place on one big
screen holding the canvas). The launchers place the ranks on the hosts the file names
(``hosts_of``). Flags given on the command line override the file. Every error names the file
and the entry. ``problems`` finds what people get wrong (windows on top of each other or off
their screen, hosts that do not resolve) for ``multigpu wall check``. Pure but for the name
lookups and the optional screen query there: no MPI.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

from multigpu.errors import InputError

KEYS = {"grid", "tile", "mullion", "displays", "comment"}
DISPLAY_KEYS = {"rank", "host", "display", "position", "fullscreen"}
#: a host name as both MPI launchers take it
HOST = re.compile(r"^[A-Za-z0-9_.\-\[\]]+$")


@dataclass(frozen=True)
class Wall:
    """What a wall file says; ``None`` where it is silent."""

    file: str
    grid: tuple[int, int] | None = None
    tile: tuple[int, int] | None = None
    mullion: tuple[int, int] | None = None
    displays: dict[int, str | None] = field(default_factory=dict)
    positions: dict[int, tuple[int, int]] = field(default_factory=dict)
    hosts: dict[int, str] = field(default_factory=dict)
    fullscreen: frozenset = frozenset()  # ranks whose window fills its display's monitor


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
    displays, positions, hosts, full = {}, {}, {}, set()
    entries = doc.get("displays", [])
    if not isinstance(entries, list):
        raise InputError(f"{where}: displays must be a list of {{rank, display, position}} entries")
    for i, e in enumerate(entries):  # one entry per display, at most a few dozen
        at = f"{where}: displays[{i}]"
        if not isinstance(e, dict) or type(e.get("rank")) is not int or e["rank"] < 0:
            raise InputError(f"{at}: needs \"rank\": a rank label >= 0")
        bad = sorted(set(e) - DISPLAY_KEYS)
        if bad:
            raise InputError(f"{at}: unknown key '{bad[0]}' (known: rank, host, display, position, fullscreen)")
        r = e["rank"]
        if r in displays:
            raise InputError(f"{at}: rank {r} appears twice")
        d = e.get("display")
        if d is not None and (not isinstance(d, str) or not re.fullmatch(r"[\w.\-]*:\d+(\.\d+)?", d)):
            raise InputError(f"{at}: display must be an X display name like ':0' or ':0.1', got {json.dumps(d)}")
        displays[r] = d
        if "fullscreen" in e:
            if not isinstance(e["fullscreen"], bool):
                raise InputError(f"{at}: fullscreen must be true or false, got {json.dumps(e['fullscreen'])}")
            if e["fullscreen"]:
                full.add(r)
        if "host" in e:
            h = e["host"]
            if not isinstance(h, str) or not HOST.match(h):
                raise InputError(f"{at}: host must be a host name or address, got {json.dumps(h)}")
            hosts[r] = h
        if "position" in e:
            p = e["position"]
            if not (isinstance(p, list) and len(p) == 2 and all(type(v) is int for v in p)):
                raise InputError(f"{at}: position must be [x, y] in pixels, got {json.dumps(p)}")
            positions[r] = (p[0], p[1])
    return Wall(path, grid, tile, mullion, displays, positions, hosts, frozenset(full))


def check_ranks(wall: Wall, ranks: int) -> None:
    """Every display entry names a rank of a ``ranks``-rank wall, and once ``displays`` is given
    every rank has one (a missing rank would silently take ``$DISPLAY``)."""
    for r in sorted(wall.displays):
        if r >= ranks:
            raise InputError(f"--wall {wall.file}: displays entry for rank {r}, but the wall has ranks 0..{ranks - 1}")
    missing = [r for r in range(ranks) if wall.displays and r not in wall.displays]
    if missing:
        raise InputError(f"--wall {wall.file}: no displays entry for rank {', '.join(map(str, missing))} of the "
                         f"{ranks}-rank wall (once displays is given, every rank needs one; "
                         "{\"rank\": R} alone means $DISPLAY)")


def hosts_of(wall: Wall, ranks: int) -> list[tuple[str, int]]:
    """The hosts the file places the ranks on, as [(host, processes)], hosts in the order the
    file first names them; empty where it names none. Any tile may be on any host: MPI fills the
    hosts with processes in order, and ``tile_order`` says which tile each process drives. Once
    one entry names a host every entry does."""
    if not wall.hosts:
        return []
    missing = [r for r in range(ranks) if r not in wall.hosts]
    if missing:
        raise InputError(f"--wall {wall.file}: rank {missing[0]} names no host, but others do (name every rank's host)")
    order = list(dict.fromkeys(wall.hosts[r] for r in range(ranks)))
    return [(h, sum(wall.hosts[r] == h for r in range(ranks))) for h in order]


def tile_order(wall: Wall, ranks: int) -> list[int]:
    """The tile (rank label) each MPI process drives, in process order: each host's tiles
    together, hosts in ``hosts_of``'s order, a host's tiles in label order. The identity where
    every host's tiles are consecutive (or the file names no hosts): a PC per row of a 2x2 wall
    (tiles 0 and 2 on one, 1 and 3 on the other) gives [0, 2, 1, 3]."""
    if not wall.hosts:
        return list(range(ranks))
    first = {h: i for i, (h, _) in enumerate(hosts_of(wall, ranks))}
    return sorted(range(ranks), key=lambda r: (first[wall.hosts[r]], r))


def windows(wall: Wall, grid, tile, mullion) -> list[tuple[str, str, int, int, int, int]]:
    """Every rank's window as (host, display, x, y, width, height), top-left on its display: the
    file's position, or the tile's place on one screen holding the canvas."""
    from multigpu.core.canvas import Canvas

    c = Canvas(grid, tile, mullion)
    H = c.size[1]
    out = []
    for k, (x0, _, _, y1) in enumerate(c.tiles()):  # K tiles
        x, y = (0, 0) if k in wall.fullscreen else wall.positions.get(k, (int(x0), int(H - y1)))
        out.append((wall.hosts.get(k, "this machine"), wall.displays.get(k) or "$DISPLAY", x, y, tile[0], tile[1]))
    return out


def problems(wall: Wall, grid, tile, mullion, screens=None, resolve=None) -> list[str]:
    """What is wrong with the installation the file describes, one line each: windows that
    overlap on one display, windows off their screen (``screens(host, display)`` gives a
    screen's (width, height), or None where it cannot be asked), hosts that do not resolve
    (``resolve(host)`` raises OSError), a rank on another host without a display."""
    import socket

    resolve = resolve or socket.gethostbyname
    found = []
    wins = windows(wall, grid, tile, mullion)
    for a in range(len(wins)):  # ranks, a few dozen
        ha, da, xa, ya, w, h = wins[a]
        for b in range(a + 1, len(wins)):
            hb, db, xb, yb, _, _ = wins[b]
            if (ha, da) == (hb, db) and xa < xb + w and xb < xa + w and ya < yb + h and yb < ya + h:
                found.append(f"ranks {a} and {b}: their windows overlap on {da} of {ha} (at {xa},{ya} and {xb},{yb}, "
                             f"{w}x{h} each): give each its own position or display")
    for host in sorted(set(wall.hosts.values())):
        try:
            resolve(host)
        except OSError:
            found.append(f"host {host}: its name does not resolve (check it, or give its address)")
    for k, (host, disp, x, y, w, h) in enumerate(wins):
        if k in wall.hosts and disp == "$DISPLAY" and host != "this machine":
            found.append(f"rank {k} on host {host} has no display: name it (\"display\": \":0\"); a rank started on "
                         "another host gets no $DISPLAY")
        size = screens(host, disp) if screens is not None else None
        if size is not None and k in wall.fullscreen and size != (w, h):
            found.append(f"rank {k}: full screen on the {size[0]}x{size[1]} screen {disp} of {host}, but the tile is "
                         f"{w}x{h}: make the tile the monitor's size")
        elif size is not None and (x < 0 or y < 0 or x + w > size[0] or y + h > size[1]):
            found.append(f"rank {k}: its window {w}x{h} at {x},{y} is off the {size[0]}x{size[1]} screen {disp} of "
                         f"{host}" + ("" if k in wall.positions else " (no position: it went to the tile's place on "
                                      "the canvas; give \"position\": [0, 0] for a screen of its own)"))
    return found


def screen_size(host: str, display: str) -> tuple[int, int] | None:
    """The size of ``display`` on this machine, asked with ``xdpyinfo`` (None where it is another
    host's, or where the screen cannot be asked)."""
    import os
    import re as _re
    import shutil
    import subprocess

    if host != "this machine" or shutil.which("xdpyinfo") is None:
        return None
    name = os.environ.get("DISPLAY", "") if display == "$DISPLAY" else display
    if not name:
        return None
    try:
        got = subprocess.run(["xdpyinfo", "-display", name], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return None
    screen = name.rsplit(".", 1)[1] if _re.search(r":\d+\.\d+$", name) else "0"
    block = got.stdout.split(f"screen #{screen}:", 1)
    m = _re.search(r"dimensions:\s+(\d+)x(\d+) pixels", block[1]) if len(block) == 2 else None
    return (int(m.group(1)), int(m.group(2))) if got.returncode == 0 and m else None


def picture(wall: Wall, grid) -> list[str]:
    """The wall as the people in front of it see it: a box per tile, top row first, with its
    rank, host and display; ranks count down each column (column-major), row 0 at the top."""
    rows, cols = grid
    width = 14
    cell = lambda k, i: [f"rank {k}", wall.hosts.get(k, ""), wall.displays.get(k) or "$DISPLAY"][i]
    line = "+" + "+".join("-" * width for _ in range(cols)) + "+"
    out = [line]
    for r in range(rows):  # tiles, a few dozen
        for i in range(3):
            out.append("|" + "|".join(f"{cell(c * rows + r, i)[:width]:^{width}}" for c in range(cols)) + "|")
        out.append(line)
    out.append(f"{rows} row(s) top to bottom, {cols} column(s) left to right (grid ROWSxCOLS = {rows}x{cols}); "
               "ranks count down each column")
    return out


def describe(wall: Wall, grid, tile, mullion) -> str:
    """The layout a wall file gives, as lines for ``multigpu wall check``."""
    from multigpu.core.canvas import Canvas

    c = Canvas(grid, tile, mullion)
    W, H = c.size
    order = tile_order(wall, grid[0] * grid[1])
    lines = [f"{wall.file}: {grid[0]}x{grid[1]} wall of {tile[0]}x{tile[1]} tiles, mullions {mullion[0]}x{mullion[1]}",
             f"canvas {W}x{H} pixels ({c.visible[0]}x{c.visible[1]} visible)",
             *([f"MPI processes drive the tiles {', '.join(map(str, order))} in turn (each host's tiles together)"]
               if order != sorted(order) else []),
             f"{'rank':>4} {'row':>3} {'col':>3}  {'host':<12} {'display':<10} {'window at':<12} "
             "canvas pixels [x0, y0) top-left"]
    for k, (x0, y0, x1, y1) in enumerate(c.tiles()):  # K tiles
        row, col = k % grid[0], k // grid[0]
        top = H - y1
        pos = wall.positions.get(k, (int(x0), int(top)))
        disp = wall.displays.get(k) or "$DISPLAY"
        host = wall.hosts.get(k, "-")
        lines.append(f"{k:>4} {row:>3} {col:>3}  {host:<12} {disp:<10} {f'{pos[0]},{pos[1]}':<12} [{x0}, {top})")
    return "\n".join(lines)


def check_command(path: str, grid_only: bool = False, hosts_only: bool = False) -> str:
    """``multigpu wall check``: the file checked with a run's own limits and for what people get
    wrong (an InputError naming the first problem, and the others), then its layout and picture
    (or only ROWSxCOLS, or only the hosts as H:N,..., for launch scripts)."""
    from multigpu.config import WalkConfig

    wall = load_wall(path)
    grid, tile, mullion = wall.grid or WalkConfig.grid, wall.tile or WalkConfig.tile, wall.mullion or (0, 0)
    check_ranks(wall, grid[0] * grid[1])
    hosts = hosts_of(wall, grid[0] * grid[1])
    WalkConfig(grid=grid, tile=tile, mullion=mullion)
    if grid_only:
        return f"{grid[0]}x{grid[1]}"
    if hosts_only:
        return ",".join(f"{h}:{n}" for h, n in hosts)
    found = problems(wall, grid, tile, mullion, screen_size)
    if found:
        more = f" (and {len(found) - 1} more: {'; '.join(found[1:])})" if len(found) > 1 else ""
        raise InputError(f"--wall {path}: {found[0]}{more}")
    return "\n".join([describe(wall, grid, tile, mullion), *picture(wall, grid)])
