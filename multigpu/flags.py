"""The flags of the scene and walkthrough commands, and the validated configuration built
from them (``walk_config``): argparse in, dataclasses out, no MPI (testable in one process)."""

from __future__ import annotations

import argparse
import re

from multigpu.errors import InputError


def defaults(cls) -> dict:
    """A configuration dataclass's field defaults: the one place every default lives."""
    import dataclasses

    return {f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}


def scene_args(p: argparse.ArgumentParser) -> None:
    """The scene's flags, as ``SceneSpec`` declares them (``options.py``)."""
    from multigpu.options import add_flags
    from multigpu.scene.models import SceneSpec

    add_flags(p, SceneSpec, ["scene"])


def _ranks(a) -> int:
    from multigpu.config import parse_pair

    rows, cols = parse_pair(getattr(a, "grid", None) or "2x2", "--grid")
    return rows * cols


def spec(a, **override):
    """The scene's flags as a validated ``SceneSpec`` (``override``: fields set by the caller)."""
    from multigpu.options import from_flags
    from multigpu.scene.models import SceneSpec

    return SceneSpec(**{**from_flags(SceneSpec, a), "ranks": _ranks(a), **override})


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Help with every flag's default shown (where it has one and its text does not already say
    it) and the epilog's examples kept as written."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        shown = "%(default)" in text or "default" in text.lower()
        empty = action.default is None or action.nargs == 0 or action.default is argparse.SUPPRESS  # a switch
        if not shown and action.option_strings and not empty:
            text += " (default: %(default)s)"
        return text


#: the walkthrough's examples, printed after its flags
EXAMPLES = """examples:
  launch/walkthrough                                 the plant on a 2x2 wall of 256x256 tiles, 4 ranks
  launch/walkthrough --grid 3x3 --tile 512x512 --balance strips --out out/strips
  launch/walkthrough --model models/pump.glb --split components --path-kind orbit
  launch/walkthrough --wall wall.json --present window --path interactive --record flight.json
  launch/walkthrough --path flight.json --out out/replay     replay a flight bit for bit
  launch/walkthrough --hosts a:2,b:2                 4 ranks on two PCs (remote shell: ssh or $MULTIGPU_RSH)
  mpiexec -n 4 python -m mpi4py -m multigpu walkthrough --grid 2x2   under your own mpiexec

Outputs in --out: timings.csv (a row per frame and rank), summary.json, mosaic/ (docs/USAGE.md)."""


#: the walkthrough parser's settings (the CLI's subcommand and docs/USAGE.md's synopsis alike)
WALKTHROUGH = {"description": "Render a camera path on a display wall: one MPI rank per tile, the work\n"
                              "balanced every frame, every rank composing and showing its own tile.",
               "formatter_class": HelpFormatter, "epilog": EXAMPLES}


def walkthrough_parser(prog: str = "multigpu walkthrough") -> argparse.ArgumentParser:
    """The walkthrough's parser on its own: what ``multigpu walkthrough --help`` prints."""
    p = argparse.ArgumentParser(prog=prog, **WALKTHROUGH)
    scene_args(p)
    walkthrough_args(p)
    return p


def walkthrough_args(w: argparse.ArgumentParser) -> None:
    """The walkthrough's own flags, as ``WalkConfig`` declares them (``options.py``), then the
    launcher's hosts flags (the scene's flags come from ``scene_args``)."""
    from multigpu.config import GROUPS, WalkConfig
    from multigpu.options import add_flags

    add_flags(w, WalkConfig, GROUPS)
    h = w.add_argument_group("hosts (the launcher's: launch/walkthrough, python -m multigpu.launcher.mpirun)")
    h.add_argument("--hosts", metavar="H:N,...", help="place the ranks on these hosts in order, N each (e.g. a:2,b:2)")
    h.add_argument("--hostfile", metavar="FILE", help="hosts one per line: HOST, HOST:N or HOST slots=N")


def walk_config(a):
    """The walkthrough's flags as a validated configuration (no MPI: testable in one process):
    each flag's value as its field declares it; the wall file's grid, tile, mullions, displays,
    monitor, compression and panel where the flags leave them out."""
    from multigpu.config import MONITOR_BESIDE, WalkConfig
    from multigpu.options import from_flags
    from multigpu.wall import Wall, bezel_mullion, check_ranks, load_wall

    for name in ("hosts", "hostfile"):
        if getattr(a, name, None) is not None:
            raise InputError(f"--{name} places the ranks when the job starts: give it to launch/walkthrough or "
                             "python -m multigpu.launcher.mpirun, or place them with your mpiexec's own flags")
    wall = load_wall(a.wall) if a.wall else Wall("")
    given = from_flags(WalkConfig, a)
    if wall.mpcdi is not None:  # a projector wall: its tiles are the regions of its MPCDI file
        for name in ("grid", "tile", "mullion"):  # (the same as the file's: launch/walkthrough passes the grid)
            if given.get(name) is not None and tuple(given[name]) != tuple(getattr(wall, name)):
                raise InputError.of(name, f"a projector wall's tiles are its wall file's grid of its mpcdi file's "
                                          f"regions ({wall.file}): leave it out")
    grid = given.pop("grid", None) or wall.grid or WalkConfig.grid
    check_ranks(wall, grid[0] * grid[1])
    ranks = range(grid[0] * grid[1])
    tile = given.pop("tile", None) or wall.tile or WalkConfig.tile
    mullion = given.pop("mullion", None) or wall.mullion or bezel_mullion(wall, tile) or WalkConfig.mullion
    if given.get("monitor") == MONITOR_BESIDE and wall.monitor:
        given["monitor"] = wall.monitor
    if given.get("compress") is None and wall.compress:
        given["compress"] = wall.compress
    if given.get("panel") is None and wall.panel is not None:
        from multigpu.config import read_panel

        try:
            given["panel"] = read_panel(wall.panel)
        except InputError as exc:
            raise InputError(f"{wall.file}: panel {exc}") from None
    stereo_keys = {"mode": "stereo", "eye_separation_m": "eye_separation", "swap_eyes": "swap_eyes",
                   "head_m": "head", "world_per_metre": "world_per_metre"}
    unset = defaults(WalkConfig)
    for key, name in stereo_keys.items():  # the file's stereo where the flags leave it at its default
        if key in wall.stereo and given.get(name) in (None, unset[name]):
            given[name] = tuple(wall.stereo[key]) if key == "head_m" else wall.stereo[key]
    if "tracker" in wall.stereo and given.get("head_tracker") is None:
        from multigpu.viewing import read_tracker

        try:
            given["head_tracker"] = read_tracker(wall.stereo["tracker"])
        except InputError as exc:
            raise InputError(f"{wall.file}: stereo.tracker {exc}") from None
    if given.get("screen_m") is None:
        given["screen_m"] = wall.screen_m or screen_of_bezel(wall, grid, tile, mullion)
    return WalkConfig(scene=spec(a), grid=grid, tile=tile, mullion=mullion, **given,
                      displays=tuple(wall.displays.get(r) for r in ranks) if wall.displays else (),
                      positions=tuple(wall.positions.get(r) for r in ranks) if wall.positions else (),
                      fullscreen=tuple(r in wall.fullscreen for r in ranks) if wall.fullscreen else (),
                      gpus=tuple(wall.gpus.get(r) for r in ranks) if wall.gpus else (),
                      corners=tuple(wall.corners.get(r) for r in ranks) if wall.corners else (),
                      right_eye=tuple(wall.right_eye.get(r) for r in ranks) if wall.right_eye else (),
                      mpcdi=wall.mpcdi, output_colors=wall.outputs, mpcdi_right=wall.mpcdi_right)


def screen_of_bezel(wall, grid, tile, mullion) -> tuple[float, float] | None:
    """The wall's size in metres from its bezel's pixel pitch (None: the file gives none)."""
    b = wall.bezel
    if not b:
        return None
    two = lambda v: (float(v), float(v)) if not isinstance(v, list) else (float(v[0]), float(v[1]))  # noqa: E731
    pitch = two(b["pixel_pitch_mm"]) if "pixel_pitch_mm" in b else (b["panel_mm"][0] / tile[0],
                                                                     b["panel_mm"][1] / tile[1])
    (rows, cols), (tw, th), (mx, my) = grid, tile, mullion
    return ((cols * tw + (cols - 1) * mx) * pitch[0] / 1000.0, (rows * th + (rows - 1) * my) * pitch[1] / 1000.0)


def dark_tiles(a) -> tuple[int, ...]:
    """``--dark-tiles`` as tile labels, () where unreadable (the configuration's check says so)."""
    from multigpu.config import read_labels

    try:
        return read_labels(getattr(a, "dark", "") or "")
    except InputError:
        return ()


def joined_negatives(argv: list[str]) -> list[str]:
    """``--flag -1,2`` as ``--flag=-1,2``: argparse takes a value that starts with a minus sign
    and holds more than one number (``--range -1,1``, ``--offset -5,0,0``) for a flag of its own."""
    out: list[str] = []
    for a in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and re.match(r"-[\d.]", a) and "," in a:
            out[-1] = f"{out[-1]}={a}"
        else:
            out.append(a)
    return out
