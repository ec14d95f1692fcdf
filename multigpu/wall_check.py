"""``multigpu wall check``: what is wrong with the installation a wall file describes, and a
picture of it. Windows that overlap on one display or lie off their screen, hosts that do not
resolve, a rank on another host without a display (``problems``); every rank's window
(``windows``), the canvas drawn in text (``picture``) and the whole report (``describe``,
``check_command``). Pure but for the name lookups and the optional screen query: no MPI.
"""

from __future__ import annotations

import json
from pathlib import Path

from multigpu.errors import InputError
from multigpu.wall import Wall, bezel_mullion, check_ranks, hosts_of, load_wall, tile_order


def windows(wall: Wall, grid, tile, mullion) -> list[tuple[str, str, int, int, int, int]]:
    """Every rank's window as (host, display, x, y, width, height), top-left on its display: the
    file's position, or the tile's place on one screen holding the canvas (a projector wall's:
    its output's size, the outputs side by side, ``warp.layout.places``). A passive stereo
    wall's right-eye windows follow, rank by rank (``right_eye_position``, else beside the wall:
    ``core.stereo.right_eye_place``)."""
    from multigpu.core.canvas import Canvas
    from multigpu.core.stereo import right_eye_place

    c = Canvas(grid, tile, mullion)
    H = c.size[1]
    sizes, at = [tile] * (grid[0] * grid[1]), [(int(x0), int(H - y1)) for x0, _, _, y1 in c.tiles()]
    if wall.mpcdi is not None:  # a projector's window: its output's size, the outputs side by side
        from multigpu.warp.layout import outputs_by_tile, picture_size, places

        outs = outputs_by_tile(wall.mpcdi, grid)
        sizes, at = [picture_size(outs, k) for k in range(grid[0] * grid[1])], places(grid, outs)
    out = []
    for k, (w, h) in enumerate(sizes):  # K tiles
        x, y = (0, 0) if k in wall.fullscreen else wall.positions.get(k, at[k])
        out.append((wall.hosts.get(k, "this machine"), wall.displays.get(k) or "$DISPLAY", x, y, w, h))
    if wall.mpcdi_right is not None:  # the right eyes' projectors: their pictures right of the left eyes'
        from multigpu.warp.layout import outputs_by_tile, picture_size, places

        right = outputs_by_tile(wall.mpcdi_right, grid)
        span = max(x + w for _, _, x, _, w, _ in out)
        out += [(h, d, *wall.right_eye.get(k, (span + x, y)), *picture_size(right, k))
                for k, ((h, d, _, _, _, _), (x, y)) in enumerate(zip(list(out), places(grid, right)))]  # K tiles
    elif wall.stereo.get("mode") == "passive":
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
    seams = (f"overlapping {-mullion[0]}x{-mullion[1]}" if min(mullion) < 0 else f"mullions {mullion[0]}x{mullion[1]}")
    lines = [f"{wall.file}: {grid[0]}x{grid[1]} wall of {tile[0]}x{tile[1]} tiles, {seams}",
             f"canvas {W}x{H} pixels ({c.visible[0]}x{c.visible[1]} visible)",
             *([f"MPI processes drive the tiles {', '.join(map(str, order))} in turn (each host's tiles together)"]
               if order != sorted(order) else []),
             f"{'rank':>4} {'row':>3} {'col':>3}  {'host':<12} {'display':<10} {'gpu':>3}  {'window at':<12} "
             "canvas pixels [x0, y0) top-left"]
    wins = windows(wall, grid, tile, mullion)  # where each window opens (a projector's: its picture's place)
    K = grid[0] * grid[1]
    for k, (x0, y0, x1, y1) in enumerate(c.tiles()):  # K tiles
        row, col = k % grid[0], k // grid[0]
        top = H - y1
        pos = wall.positions.get(k, wins[k][2:4] if wall.mpcdi is not None else (int(x0), int(top)))
        disp = wall.displays.get(k) or "$DISPLAY"
        host = wall.hosts.get(k, "-")
        gpu = wall.gpus.get(k, "-")
        right = ""
        if len(wins) > K:  # its second output's window (a passive wall's right eye: ``windows``)
            rx, ry = wins[K + k][2:4]
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
        from multigpu.warp.layout import eye_outputs

        size, outs = mpcdi.read(Path(wall.mpcdi))
        each = ", ".join(f"rank {o.tile} {o.name} {o.size[0]}x{o.size[1]}"
                         for o in eye_outputs(wall.mpcdi, grid, wall.mpcdi_right))
        lines.append(f"mpcdi {wall.mpcdi}: {len(outs)} projector outputs on a {size[0]}x{size[1]} buffer, each "
                     f"driven by the rank of its region's tile, its picture in mosaic/outputs/NAME/: {each}")
        for name, c in wall.outputs.items():  # a few outputs
            how = [*(["a colour matrix"] if "matrix" in c else []), *([f"the LUT {Path(c['lut']).name}"]
                                                                        if "lut" in c else [])]
            lines.append(f"output {name}: {' and '.join(how) or 'as the content is'}")
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
