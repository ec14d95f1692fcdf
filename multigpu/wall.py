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
and the entry. ``wall_check.py`` finds what people get wrong (windows on top of each other or off
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
    outputs: dict = field(default_factory=dict)  # output name -> {"matrix": (3, 3), "lut": .cube path}: its colour
    mpcdi_right: str | None = None  # a passive projector wall's right eyes' projectors (``mpcdi`` the left eyes')


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
        if isinstance(step, int):
            node = node.get("items", {})
        else:
            more = node.get("additionalProperties")
            node = node.get("properties", {}).get(step, more if isinstance(more, dict) else {})
    at = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".")
    entry = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path[:2]).lstrip(".") if path[:1] in (
        ["displays"], ["outputs"]) and len(path) > 1 else ""
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
    mpcdi_file, grid, tile, mullion = _projectors(doc, path, where, grid, tile, mullion)
    monitor = tuple(doc["monitor"]["position"]) if "monitor" in doc else None
    on = {k: v for k, v in doc.get("monitor", {}).items() if k in ("host", "display", "address")}
    return Wall(path, grid, tile, mullion, displays, positions, hosts, frozenset(full), gpus, doc.get("bezel"), monitor,
                on, doc.get("compress"), None if doc.get("panel") is None else str(doc["panel"]),
                None if "screen_m" not in doc else tuple(float(v) for v in doc["screen_m"]), doc.get("stereo", {}),
                corners, right_eye, mpcdi_file, _outputs(doc, path, where), _right_eyes(doc, path, where, grid))


def _projectors(doc: dict, path: str, where: str, grid, tile, mullion) -> tuple:
    """The wall file's MPCDI file (relative to the wall file), read once here, and the wall its
    regions make (``warp/layout.py``): (file, grid, tile, mullion), the file None and the rest as
    given without one. The file's ``grid`` of ranks may be coarser than its regions' (a rank a
    block of them: a PC driving several projectors). A bad file, a grid that does not divide the
    regions', or a tile that is not the one they make, ends the job at the door, in one line."""
    if "mpcdi" not in doc:
        return None, grid, tile, mullion
    from multigpu.warp import mpcdi
    from multigpu.warp.layout import layout

    file = Path(path).parent / doc["mpcdi"]
    if not file.is_file():
        raise InputError(f"{where}: mpcdi: {file}: no such file")
    if "mullion" in doc or "bezel" in doc:
        raise InputError(f"{where}: a projector wall's tiles overlap as its mpcdi file's regions do: give no "
                         "mullion or bezel")
    try:
        lay = layout(file, *mpcdi.read(file), grid)
    except InputError as exc:
        raise InputError(f"{where}: mpcdi: {exc}") from None
    for name, given, made in (("tile", tile, lay.tile),):
        if given is not None and tuple(given) != made:
            raise InputError(f"{where}: {name} {given[0]}x{given[1]}: the mpcdi file's regions make a "
                             f"{made[0]}x{made[1]} {name} (leave {name} out)")
    return str(file), lay.grid, lay.tile, lay.mullion


def _right_eyes(doc: dict, path: str, where: str, grid) -> str | None:
    """A passive projector wall's right eyes' MPCDI file (``mpcdi_right``, beside ``mpcdi``, the left
    eyes'): its regions must make the left eyes' wall, tile for tile."""
    if "mpcdi_right" not in doc:
        return None
    from multigpu.warp import mpcdi
    from multigpu.warp.layout import layout

    if "mpcdi" not in doc:
        raise InputError(f"{where}: mpcdi_right: give mpcdi too (the left eyes' projectors)")
    left, right = Path(path).parent / doc["mpcdi"], Path(path).parent / doc["mpcdi_right"]
    if not right.is_file():
        raise InputError(f"{where}: mpcdi_right: {right}: no such file")
    try:
        a, b = layout(left, *mpcdi.read(left), grid), layout(right, *mpcdi.read(right), grid)
    except InputError as exc:
        raise InputError(f"{where}: mpcdi_right: {exc}") from None
    if (a.grid, a.tile, a.mullion) != (b.grid, b.tile, b.mullion):
        raise InputError(f"{where}: mpcdi_right: {right.name}'s regions make a {b.grid[0]}x{b.grid[1]} wall of "
                         f"{b.tile[0]}x{b.tile[1]} tiles overlapping {-b.mullion[0]}x{-b.mullion[1]}, "
                         f"{left.name}'s {a.grid[0]}x{a.grid[1]} of {a.tile[0]}x{a.tile[1]} overlapping "
                         f"{-a.mullion[0]}x{-a.mullion[1]}: the eyes' walls must be the same")
    return str(right)


def _outputs(doc: dict, path: str, where: str) -> dict:
    """Each projector output's colour (``warp/colour.py``), its LUT read once here: an output the
    MPCDI file does not name, a bad matrix or LUT ends the job at the door, in one line."""
    if not doc.get("outputs"):
        return {}
    from multigpu.warp import colour, mpcdi

    if "mpcdi" not in doc:
        raise InputError(f"{where}: outputs: give the mpcdi file whose regions they name")
    names = [o.name for key in ("mpcdi", "mpcdi_right") if key in doc
             for o in mpcdi.read(Path(path).parent / doc[key])[1]]  # both eyes' (a stereo wall's), by name
    out = {}
    for name, e in doc["outputs"].items():  # a few outputs
        if name not in names:
            raise InputError(f"{where}: outputs: {name}: no such region in the mpcdi file ({', '.join(names)})")
        got = {}
        if "color_matrix" in e:
            got["matrix"] = colour.read_matrix(e["color_matrix"], f"{where}: outputs: {name}: color_matrix").tolist()
        if "lut" in e:
            lut = Path(path).parent / e["lut"]
            try:
                colour.read_cube(lut)
            except InputError as exc:
                raise InputError(f"{where}: outputs: {name}: lut: {exc.message}") from None
            got["lut"] = str(lut)
        out[name] = got
    return out


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
