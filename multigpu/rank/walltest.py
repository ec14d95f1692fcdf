"""``multigpu wall test WALL.json``: the calibration pattern on the wall, one rank per tile,
launched like the walkthrough (``launch/wall-test``, or the launcher with ``-n K``).

Every rank opens its window where the wall file says and shows its part of one pattern across
the canvas (``display/pattern.py``): lines that run straight across the bezels when the mullion
values are right, each tile's rank, host, display and size, and a moving bar and a frame counter
that show the swap lock (at most ``PACE`` frames a second). A stereo wall file's tiles show each
eye its own picture, named and marked for that eye, with a depth test, packed as in a run.
Rank 0's window takes the arrow keys: Left/Right take one pixel from or add one to the mullion between columns, Down/Up
between rows, every rank redraws with the new value at the same frame, and rank 0 prints the
line to put in the wall file. Escape or a closed window on any rank ends it (or
``--frames N``). Every wait is bounded, as in the frame loop.

A projector wall (the wall file's ``mpcdi``) shows the pattern through each output's warp, blend
and colour (``rank/outputs.py``) in the output's window, as a run shows its pictures: the tiles
overlap as the regions do, each names its output, and a grey ramp runs across the canvas, so
the grid and the ramp must run on through the overlaps when the calibration is right
(``blend=False``: each projector's whole picture, for aligning by eye). Its overlaps come from
the file, so the arrow keys move nothing there.
"""

from __future__ import annotations

import itertools
import socket
import sys
import time

import numpy as np

from multigpu import exits
from multigpu.errors import InputError
from multigpu.rank.exchange import agree, barrier, wait_all

PACE = 60.0  # frames a second at most: the bar moves at one speed a person can follow on any machine


def run(path: str, comm, frames: int | None = None, timeout: float = 60.0,
        blend: bool = True) -> tuple[int, int] | None:
    """Show the pattern until Escape, a closed window or ``frames``; rank 0 returns the mullion
    values it ended with."""
    from mpi4py import MPI

    from multigpu.config import WalkConfig
    from multigpu.core.canvas import Canvas
    from multigpu.core.stereo import Stereo
    from multigpu.display.pattern import nudge, stereo_tile_pattern, tile_pattern
    from multigpu.wall import check_ranks, load_wall

    rank, k = comm.Get_rank(), comm.Get_size()
    wall = load_wall(path)
    grid, tile, mullion = wall.grid or WalkConfig.grid, wall.tile or WalkConfig.tile, wall.mullion or (0, 0)
    stereo = wall.stereo.get("mode", "mono")  # a stereo wall: each eye's mark and a depth test
    if wall.mpcdi_right is not None:
        raise InputError.of("wall", f"{path}: the pattern through a stereo projector wall's right eyes' warps is not "
                                    "shown yet: test each eye's projectors with a wall file of its own mpcdi")
    if k != grid[0] * grid[1]:
        raise InputError.of("wall", f"{path}: a {grid[0]}x{grid[1]} wall needs {grid[0] * grid[1]} ranks but the job "
                            f"has {k} (launch/wall-test {path} starts the right number)")
    check_ranks(wall, k)
    host = socket.gethostname()
    shown, error = [None, None, tile, [f"rank {rank}", f"host {host}"]], None
    try:
        _open(wall, path, rank, (grid, tile, mullion), stereo, blend, shown)
    except InputError as exc:
        error = str(exc)
    presenter, projector, size, label = shown
    error = agree(comm, error, timeout, "setup")
    if error:
        if projector is not None:
            projector.release()
        if presenter is not None:
            presenter.close()
        raise InputError(error)
    nudges = None
    if rank == 0 and projector is None:
        from multigpu.display import take_arrows

        nudges = take_arrows(presenter)
    label += [presenter.display, f"{size[0]}x{size[1]}"]
    state = np.array([*mullion, 0], dtype=np.int64)  # rank 0's mullions and stop flag, for everyone
    stop = np.zeros(1, dtype=np.int64)
    start = time.monotonic()
    try:
        for f in itertools.count() if frames is None else range(frames):  # frames, not objects
            if rank == 0:  # the pace (the broadcast below holds every rank to it)
                time.sleep(max(0.0, start + f / PACE - time.monotonic()))
            if nudges is not None:
                for key in nudges.take():
                    state[:2] = nudge((int(state[0]), int(state[1])), key)
                    print(f"mullion {state[0]}x{state[1]}: put \"mullion\": \"{state[0]}x{state[1]}\" in {path}",
                          flush=True)
            wait_all([comm.Ibcast(state, root=0)], timeout, "wall test")
            c = Canvas(grid, tile, (int(state[0]), int(state[1])))
            if stereo != "mono":  # each eye its own picture, packed as the display shows them
                presenter.show(stereo_tile_pattern(Stereo(stereo, c), rank, f, label))
            else:
                x0, _, _, y1 = (int(v) for v in c.tiles()[rank])
                img = tile_pattern(c.size, (x0, c.size[1] - y1), tile, f, label, ramp=projector is not None)
                shown = np.ascontiguousarray(img[::-1])  # bottom row first
                presenter.show(shown if projector is None else projector.run(shown))
            barrier(comm, timeout)  # every tile drawn before any swaps: the swap lock
            presenter.swap()
            mine = np.array([1 if presenter.poll() else 0], dtype=np.int64)
            wait_all([comm.Iallreduce(mine, stop, op=MPI.MAX)], timeout, "wall test")
            if stop[0]:
                break
    finally:
        if projector is not None:
            projector.release()
        presenter.close()
    return (int(state[0]), int(state[1])) if rank == 0 and projector is None else None


def _open(wall, path: str, rank: int, shape: tuple, stereo: str, blend: bool, shown: list) -> None:
    """Rank ``rank``'s window into ``shown`` = [presenter, projector, size, label] as each is made
    (what was made is closed if a later step fails): at its tile's place, or its projector output's
    (``shape``: the wall's grid, tile and mullion)."""
    from multigpu.core.canvas import Canvas
    from multigpu.display import make_presenter

    grid, tile, mullion = shape
    x0, _, _, y1 = (int(v) for v in Canvas(grid, tile, mullion).tiles()[rank])
    place = (x0, Canvas(grid, tile, mullion).size[1] - y1)
    if wall.mpcdi is not None:  # a projector's window: its output, the outputs side by side
        from multigpu.warp.layout import outputs_by_tile, picture_size, places

        outs = outputs_by_tile(wall.mpcdi, grid)
        place, shown[2] = places(grid, outs)[rank], picture_size(outs, rank)
        names = [o.name for o in outs if o.tile == rank]
        shown[3].insert(1, f"output{'s' if len(names) > 1 else ''} {', '.join(names)}")
    place = wall.positions.get(rank, place)
    where = f"wall file {path}, rank {rank} on host {socket.gethostname()}"
    right = None
    if stereo == "passive":  # a window per eye (display/passive.py)
        from multigpu.core.stereo import right_eye_place

        right = wall.right_eye.get(rank, right_eye_place(Canvas(grid, tile, mullion), place))
    shown[0] = make_presenter("window", rank, shown[2], place, wall.displays.get(rank), where,
                              rank in wall.fullscreen, right)
    if wall.mpcdi is not None:
        from multigpu.rank.outputs import Projector

        shown[1] = Projector(shown[0].context, wall.mpcdi, rank, grid, tile, wall.outputs, blend)


def main(path: str, frames: int | None, blend: bool = True) -> int:
    """The CLI's ``wall test`` under MPI: one line and exit 2 for bad input on every rank."""
    from mpi4py import MPI

    from multigpu.rank.job import collective_exit
    from multigpu.rank.tiles import tile_comm

    try:
        comm = tile_comm(MPI.COMM_WORLD, path)
        got = run(path, comm, frames, blend=blend)
    except InputError as exc:
        if MPI.COMM_WORLD.Get_rank() == 0:
            print(f"multigpu: error: {exc}", file=sys.stderr, flush=True)
        collective_exit(exits.BAD_INPUT)
        return exits.BAD_INPUT
    if got is not None:
        print(f"wall test ended with mullion {got[0]}x{got[1]}", flush=True)
    return 0
