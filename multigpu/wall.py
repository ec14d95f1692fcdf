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

from multigpu.core.canvas import MOST_TILES
from multigpu.core.doors import Unfit, loads
from multigpu.errors import InputError

#: the wall file's JSON Schema (shipped beside the example walls: examples/walls/), which
#: ``load_wall`` checks a file against before reading it
SCHEMA = Path(__file__).resolve().parent / "data" / "wall.schema.json"
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
    gpus: dict[int, int] = field(default_factory=dict)  # rank -> GPU (EGL device, or X screen with windows)
    bezel: dict | None = None  # the file's bezel (millimetres), where it gives one instead of mullion pixels
    monitor: tuple[int, int] | None = None  # where --monitor opens the operator's view (rank 0's display or its own)
    monitor_on: dict = field(default_factory=dict)  # the view's own PC: "host", "display", "address" (the file's)
    compress: str | None = None  # how pixels cross between PCs (--compress), where the file says
    panel: str | None = None  # where the operator's page is served ([ADDRESS:]PORT, --panel), where the file says
    screen_m: tuple[float, float] | None = None  # the wall's width and height in metres (--screen-size)
    stereo: dict = field(default_factory=dict)  # the file's stereo and viewer (--stereo, --eye-separation, ...)
    corners: dict[int, tuple] = field(default_factory=dict)  # rank -> its display's room corners (metres)
    right_eye: dict[int, tuple[int, int]] = field(default_factory=dict)  # rank -> its passive right-eye output's place
    mpcdi: str | None = None  # the projector outputs' warps and blends (an MPCDI file, checked when read)


def rectangle_problem(corners) -> str | None:
    """Why a display's three room corners do not make one (``core.eyes``)."""
    from multigpu.core.eyes import rectangle_problem as why

    return why(corners)


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


def schema() -> dict:
    return json.loads(SCHEMA.read_text())


def _schema_error(doc, where: str) -> str | None:
    """The first thing (in document order) the file gets wrong by the schema, as one line naming
    the entry and the key, in the words of the schema's own descriptions; None where it is valid."""
    from jsonschema import Draft202012Validator

    sch = schema()
    errors = sorted(Draft202012Validator(sch).iter_errors(doc), key=lambda e: [str(p) for p in e.absolute_path])
    if not errors:
        return None
    e = errors[0]
    path = list(e.absolute_path)
    node = sch
    for step in path:  # the schema of the value at fault, for its description
        node = node.get("items", {}) if isinstance(step, int) else node.get("properties", {}).get(step, {})
    at = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".")
    entry = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path[:2]).lstrip(".") if path[:1] == [
        "displays"] and len(path) > 1 else ""
    prefix = f"{where}: {entry}: " if entry else f"{where}: "
    if e.validator == "additionalProperties":
        known = sorted(k for k in node.get("properties", {}) if k not in ("$schema", "comment"))
        extra = sorted(set(e.instance) - set(node.get("properties", {})))
        return f"{prefix}unknown key {extra[0][:40]!r} (known: {', '.join(known)})"
    if e.validator == "required":
        missing = next(k for k in e.validator_value if k not in e.instance)
        text = node.get("properties", {}).get(missing, {}).get("description", f"needs \"{missing}\"")
        return f"{prefix}{text}" if text.startswith("needs") else f"{prefix}needs \"{missing}\": {text}"
    text = node.get("description") or e.message
    got = f", got {json.dumps(e.instance)}" if len(json.dumps(e.instance)) < 80 else ""
    return f"{prefix}{text}{got}" if at else f"{prefix}{text}"


def load_wall(path: str) -> Wall:
    """Read and check a wall file (its JSON Schema, then what a schema cannot say); every error is
    one line naming the file, the entry and the key."""
    where = f"--wall {path}"
    try:
        doc = loads(Path(path).read_text())  # NaN, Infinity and numbers out of range refused here
    except Unfit as exc:
        raise InputError(f"{where}: {exc} (every number must be finite)") from None
    except RecursionError:
        raise InputError(f"{where}: nested too deeply") from None
    except FileNotFoundError:
        raise InputError(f"{where}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{where}: cannot read it ({exc.__class__.__name__}: {exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{where}: not JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{where}: the top level must be a JSON object with grid, tile, mullion, displays")
    wrong = _schema_error(doc, where)
    if wrong:
        raise InputError(wrong)
    try:
        grid = _pair(doc["grid"], "grid") if "grid" in doc else None
        tile = _pair(doc["tile"], "tile") if "tile" in doc else None
        mullion = _pair(doc["mullion"], "mullion", zero=True) if "mullion" in doc else None
    except ValueError as exc:
        raise InputError(f"{where}: {exc}") from None
    if "mullion" in doc and "bezel" in doc:
        raise InputError(f"{where}: give mullion (pixels) or bezel (millimetres), not both")
    displays, positions, hosts, full, gpus, corners, right_eye = {}, {}, {}, set(), {}, {}, {}
    for i, e in enumerate(doc.get("displays", [])):  # one entry per display, at most a few dozen
        r = e["rank"]
        if r in displays:
            raise InputError(f"{where}: displays[{i}]: rank {r} appears twice")
        displays[r] = e.get("display")
        if e.get("fullscreen"):
            full.add(r)
        if "host" in e:
            hosts[r] = e["host"]
        if "position" in e:
            positions[r] = tuple(e["position"])
        if "gpu" in e:
            gpus[r] = e["gpu"]
        if "right_eye_position" in e:
            right_eye[r] = tuple(e["right_eye_position"])
        if "corners_m" in e:
            why = rectangle_problem(e["corners_m"])
            if why:
                raise InputError(f"{where}: displays[{i}]: corners_m: {why}")
            corners[r] = tuple(tuple(float(v) for v in p) for p in e["corners_m"])
    if corners and len(corners) != len(displays):
        raise InputError(f"{where}: corners_m: give every display's corners or none (ranks "
                         f"{', '.join(str(r) for r in sorted(set(displays) - set(corners)))} have none)")
    monitor = tuple(doc["monitor"]["position"]) if "monitor" in doc else None
    on = {k: v for k, v in doc.get("monitor", {}).items() if k in ("host", "display", "address")}
    return Wall(path, grid, tile, mullion, displays, positions, hosts, frozenset(full), gpus, doc.get("bezel"), monitor,
                on, doc.get("compress"), None if doc.get("panel") is None else str(doc["panel"]),
                None if "screen_m" not in doc else tuple(float(v) for v in doc["screen_m"]), doc.get("stereo", {}),
                corners, right_eye, _mpcdi(doc, path, where))


def _mpcdi(doc: dict, path: str, where: str) -> str | None:
    """The wall file's MPCDI file (relative to the wall file), read once here: a bad one ends the
    job at the door, in one line."""
    if "mpcdi" not in doc:
        return None
    from multigpu.warp import mpcdi

    file = Path(path).parent / doc["mpcdi"]
    if not file.is_file():
        raise InputError(f"{where}: mpcdi: {file}: no such file")
    try:
        mpcdi.read(file)
    except InputError as exc:
        raise InputError(f"{where}: mpcdi: {exc}") from None
    return str(file)


def bezel_mullion(wall: Wall, tile: tuple[int, int]) -> tuple[int, int] | None:
    """The mullion in pixels a wall file's ``bezel`` gives for ``tile``-pixel monitors: the
    millimetres between two monitors' pixels over the pixel pitch (the data sheet's, or the
    active area over the tile), rounded; None where the file gives no bezel."""
    b = wall.bezel
    if not b:
        return None
    two = lambda v: (float(v), float(v)) if isinstance(v, (int, float)) else (float(v[0]), float(v[1]))
    gap = two(b["bezel_to_bezel_mm"])
    pitch = two(b["pixel_pitch_mm"]) if "pixel_pitch_mm" in b else (b["panel_mm"][0] / tile[0],
                                                                     b["panel_mm"][1] / tile[1])
    if min(pitch) <= 0:
        raise InputError.of("wall", f"{wall.file}: bezel: the pixel pitch must be > 0 mm")
    return round(gap[0] / pitch[0]), round(gap[1] / pitch[1])


def check_ranks(wall: Wall, ranks: int) -> None:
    """A wall of at most ``MOST_TILES`` tiles; every display entry names a rank of a
    ``ranks``-rank wall, and once ``displays`` is given every rank has one (a missing rank would
    silently take ``$DISPLAY``)."""
    if ranks > MOST_TILES:
        raise InputError.of("wall", f"{wall.file}: a grid of {ranks} tiles (at most {MOST_TILES})")
    for r in sorted(wall.displays):
        if r >= ranks:
            raise InputError.of("wall", f"{wall.file}: displays entry for rank {r}, but the wall has ranks "
                                f"0..{ranks - 1}")
    missing = [r for r in range(ranks) if wall.displays and r not in wall.displays]
    if missing:
        raise InputError.of("wall", f"{wall.file}: no displays entry for rank {', '.join(map(str, missing))} of the "
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
        raise InputError.of("wall", f"{wall.file}: rank {missing[0]} names no host, but others do (name every "
                            "rank's host)")
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
    file's position, or the tile's place on one screen holding the canvas. A passive stereo
    wall's right-eye windows follow, rank by rank (``right_eye_position``, else beside the wall:
    ``core.stereo.right_eye_place``)."""
    from multigpu.core.canvas import Canvas
    from multigpu.core.stereo import right_eye_place

    c = Canvas(grid, tile, mullion)
    H = c.size[1]
    out = []
    for k, (x0, _, _, y1) in enumerate(c.tiles()):  # K tiles
        x, y = (0, 0) if k in wall.fullscreen else wall.positions.get(k, (int(x0), int(H - y1)))
        out.append((wall.hosts.get(k, "this machine"), wall.displays.get(k) or "$DISPLAY", x, y, tile[0], tile[1]))
    if wall.stereo.get("mode") == "passive":
        out += [(h, d, *wall.right_eye.get(k, right_eye_place(c, (x, y))), w, ht)
                for k, (h, d, x, y, w, ht) in enumerate(list(out))]  # K tiles
    return out


def _whose(i: int, ranks: int) -> str:
    """Window ``i`` of ``windows``: a rank's, or on a passive wall a rank's right eye's."""
    return f"rank {i}" if i < ranks else f"rank {i - ranks}'s right-eye window"


def problems(wall: Wall, grid, tile, mullion, screens=None, resolve=None) -> list[str]:
    """What is wrong with the installation the file describes, one line each: windows that
    overlap on one display, windows off their screen (``screens(host, display)`` gives a
    screen's (width, height), or None where it cannot be asked), hosts that do not resolve
    (``resolve(host)`` raises OSError), a rank on another host without a display."""
    import socket

    resolve = resolve or socket.gethostbyname
    found = []
    wins = windows(wall, grid, tile, mullion)
    K = grid[0] * grid[1]
    for a in range(len(wins)):  # ranks, a few dozen
        ha, da, xa, ya, w, h = wins[a]
        for b in range(a + 1, len(wins)):
            hb, db, xb, yb, _, _ = wins[b]
            if (ha, da) == (hb, db) and xa < xb + w and xb < xa + w and ya < yb + h and yb < ya + h:
                pair = (f"ranks {a} and {b}: their windows" if b < K else f"{_whose(a, K)} and {_whose(b, K)}")
                found.append(f"{pair} overlap on {da} of {ha} (at {xa},{ya} and {xb},{yb}, "
                             f"{w}x{h} each): give each its own position or display")
    for host in sorted(set(wall.hosts.values())):
        try:
            resolve(host)
        except OSError:
            found.append(f"host {host}: its name does not resolve (check it, or give its address)")
    for k, (host, disp, x, y, w, h) in enumerate(wins):
        if k >= K:  # a passive tile's right-eye window: on its rank's display
            size = screens(host, disp) if screens is not None else None
            if size is not None and (x < 0 or y < 0 or x + w > size[0] or y + h > size[1]):
                found.append(f"{_whose(k, K)} {w}x{h} at {x},{y} is off the {size[0]}x{size[1]} screen {disp} of "
                             f"{host}: give its \"right_eye_position\", or a screen as wide as both eyes' walls")
            continue
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
             f"{'rank':>4} {'row':>3} {'col':>3}  {'host':<12} {'display':<10} {'gpu':>3}  {'window at':<12} "
             "canvas pixels [x0, y0) top-left"]
    for k, (x0, y0, x1, y1) in enumerate(c.tiles()):  # K tiles
        row, col = k % grid[0], k // grid[0]
        top = H - y1
        pos = wall.positions.get(k, (int(x0), int(top)))
        disp = wall.displays.get(k) or "$DISPLAY"
        host = wall.hosts.get(k, "-")
        gpu = wall.gpus.get(k, "-")
        right = ""
        if wall.stereo.get("mode") == "passive":  # its second output's window (``windows``)
            from multigpu.core.stereo import right_eye_place

            rx, ry = wall.right_eye.get(k, right_eye_place(c, pos))
            right = f", right eye's window at {rx},{ry}"
        lines.append(f"{k:>4} {row:>3} {col:>3}  {host:<12} {disp:<10} {gpu:>3}  {f'{pos[0]},{pos[1]}':<12} "
                     f"[{x0}, {top}){right}")
    if wall.monitor is not None:
        on = wall.monitor_on
        where = (f"on host {on['host']}, display {on.get('display', '$DISPLAY')} (reached at "
                 f"{on.get('address', on['host'])})" if "host" in on else "on rank 0's display")
        lines.append(f"--monitor: the operator's view at {wall.monitor[0]},{wall.monitor[1]} {where}")
    if wall.mpcdi is not None:
        from multigpu.warp import mpcdi

        size, outs = mpcdi.read(Path(wall.mpcdi))
        lines.append(f"mpcdi {wall.mpcdi}: {len(outs)} projector outputs ({', '.join(o.name for o in outs)}) on a "
                     f"{size[0]}x{size[1]} buffer: each one's picture in the mosaics (mosaic/outputs/NAME/)")
    return "\n".join(lines)


def check_command(path: str, grid_only: bool = False, hosts_only: bool = False,
                  offline: bool = False) -> str:
    """``multigpu wall check``: the file checked with a run's own limits and for what people get
    wrong (an InputError naming the first problem, and the others), then its layout and picture
    (or only ROWSxCOLS, or only the hosts as H:N,..., for launch scripts). ``offline``: no host
    look-up and no X screen asked (a file written for another site, or checked in CI)."""
    from multigpu.config import WalkConfig

    wall = load_wall(path)
    grid, tile = wall.grid or WalkConfig.grid, wall.tile or WalkConfig.tile
    derived = bezel_mullion(wall, tile)
    mullion = wall.mullion or derived or (0, 0)
    check_ranks(wall, grid[0] * grid[1])
    hosts = hosts_of(wall, grid[0] * grid[1])
    st = wall.stereo
    try:  # the run's own checks of its stereo and viewer (a mode the presenters show, a head in front)
        cfg = WalkConfig(grid=grid, tile=tile, mullion=mullion, screen_m=wall.screen_m, stereo=st.get("mode", "mono"),
                         eye_separation=st.get("eye_separation_m", WalkConfig.eye_separation),
                         swap_eyes=st.get("swap_eyes", False),
                         head=None if "head_m" not in st else tuple(st["head_m"]),
                         world_per_metre=st.get("world_per_metre", 1.0),
                         corners=tuple(wall.corners.get(r) for r in range(grid[0] * grid[1])) if wall.corners else ())
    except InputError as exc:
        raise InputError(f"--wall {path}: stereo: {exc}") from None
    if grid_only:
        return f"{grid[0]}x{grid[1]}"
    if hosts_only:
        return ",".join(f"{h}:{n}" for h, n in hosts)
    found = problems(wall, grid, tile, mullion, None if offline else screen_size,
                     (lambda host: None) if offline else None)
    if found:
        more = f" (and {len(found) - 1} more: {'; '.join(found[1:])})" if len(found) > 1 else ""
        raise InputError.of("wall", f"{path}: {found[0]}{more}")
    bezel = ([f"mullion {mullion[0]}x{mullion[1]} pixels from the bezel: {json.dumps(wall.bezel)}"]
             if derived else [])
    viewer = cfg.viewer
    size = (f"{len(viewer.screens)} screen(s) in the room (tiles "
            f"{' | '.join(','.join(map(str, sc.tiles)) for sc in viewer.screens)})" if viewer is not None
            and viewer.screens else f"a {cfg.screen_m[0]:g} x {cfg.screen_m[1]:g} m wall")
    seen = [] if viewer is None else [
        f"{cfg.stereo}: {size}, eyes {viewer.separation:g} m apart"
        + ("" if cfg.head is None else f", the head at {', '.join(f'{v:g}' for v in cfg.head)} m")
        + (", eyes swapped" if viewer.swap else "")]
    return "\n".join([describe(wall, grid, tile, mullion), *bezel, *seen, *picture(wall, grid)])
