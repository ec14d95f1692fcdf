"""Where a rank shows its tile: headless, or a window at its tile's place on its display (the
wall file's place and display where it gives them; a projector's output window; a passive
tile's two eyes, or one eye's window where each eye has a rank of its own). The walkthrough's
setup calls ``rank_presenter`` once per rank."""

from __future__ import annotations

import socket

from multigpu.config import WalkConfig


def rank_presenter(cfg: WalkConfig, rank: int):
    """This rank's presenter: headless, or a window at its tile's place (or the wall file's);
    headless where its tile is dark (it stands in for a PC that is gone). With a rank for each eye
    of each tile (``--eyes own``), ranks K.. show the right eyes' outputs, one window each."""
    from multigpu.display import make_presenter

    if cfg.eyes == "own":
        return _eye_presenter(cfg, rank)
    x0, _, x1, y1 = (int(v) for v in cfg.canvas.tiles()[rank])
    place, size = (x0, cfg.canvas.size[1] - y1), cfg.tile  # top-left of the tile on a screen holding the canvas
    if cfg.mpcdi is not None:  # a projector's window: its output's picture, the outputs side by side
        from multigpu.warp.layout import outputs_by_tile, picture_size, places

        outs = outputs_by_tile(cfg.mpcdi, cfg.grid)
        place, size = places(cfg.grid, outs)[rank], picture_size(outs, rank)
    pos = cfg.positions[rank] if cfg.positions and cfg.positions[rank] is not None else place
    display = screen_of(cfg.displays[rank] if cfg.displays else None, cfg.gpus[rank] if cfg.gpus else None)
    where = f"wall file {cfg.wall}, rank {rank} on host {socket.gethostname()}" if cfg.wall and display else "$DISPLAY"
    full = bool(cfg.fullscreen and cfg.fullscreen[rank])
    right = None
    if cfg.stereo == "passive":  # a window per eye: the right eye's where the wall file says, else beside the wall
        from multigpu.core.stereo import right_eye_place

        right = cfg.right_eye[rank] if cfg.right_eye and cfg.right_eye[rank] is not None else right_eye_place(
            cfg.canvas, place if pos is None else pos)
    return make_presenter("headless" if rank in cfg.dark else cfg.present, rank, size, pos, display, where, full,
                          right)


def _eye_presenter(cfg: WalkConfig, rank: int):
    """A passive wall's output of one eye of one tile (``--eyes own``): rank k < K the left eye of
    tile k, at the tile's place; rank K + k its right eye, where the wall file says, else beside
    the wall (``core.stereo.right_eye_place``). Both on tile k's display."""
    from multigpu.core.stereo import right_eye_place
    from multigpu.display import make_presenter

    K = cfg.ranks
    tile, eye = rank % K, rank // K
    x0, _, _, y1 = (int(v) for v in cfg.canvas.tiles()[tile])
    place, size, beside = (x0, cfg.canvas.size[1] - y1), cfg.tile, None
    if cfg.mpcdi is not None:  # an eye's projectors: the rank's picture, the left eyes' side by side
        from multigpu.warp.layout import outputs_by_tile, picture_size, places

        walls = [outputs_by_tile(f, cfg.grid) for f in (cfg.mpcdi, cfg.mpcdi_right)]  # the left eyes', the right's
        at, sizes = places(cfg.grid, walls[eye]), [picture_size(walls[eye], k) for k in range(K)]
        place, size = at[tile], sizes[tile]
        left = zip(places(cfg.grid, walls[0]), (picture_size(walls[0], k) for k in range(K)))
        beside = (place[0] + max(x + w for (x, _), (w, _) in left), place[1])  # right of the left eyes' pictures
    pos = cfg.positions[tile] if cfg.positions and cfg.positions[tile] is not None else place
    if eye:
        pos = cfg.right_eye[tile] if cfg.right_eye and cfg.right_eye[tile] is not None else \
            beside if beside is not None and not cfg.positions else right_eye_place(cfg.canvas, pos)
    display = screen_of(cfg.displays[tile] if cfg.displays else None, cfg.gpus[tile] if cfg.gpus else None)
    where = f"wall file {cfg.wall}, rank {rank} on host {socket.gethostname()}" if cfg.wall and display else "$DISPLAY"
    return make_presenter(cfg.present, rank, size, pos, display, where,
                          bool(cfg.fullscreen and cfg.fullscreen[tile]) and not eye)  # the right eye: at its place


def screen_of(display: str | None, gpu: int | None) -> str | None:
    """The X display a window opens on: a wall file's ``gpu`` picks the screen (``:0`` with gpu 1:
    ``:0.1``) where the display names none; a display naming its screen keeps it."""
    import os
    import re

    if gpu is None:
        return display
    base = display if display is not None else os.environ.get("DISPLAY", ":0")
    return base if re.search(r":\d+\.\d+$", base) else f"{base}.{gpu}"
