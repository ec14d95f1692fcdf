"""Each rank's tile, whatever host MPI placed it on: the job's communicator renumbered by the
wall file (a host's tiles in any order), the one MPI step of placement. The launcher's side (the
hosts, their order, who stands in for a PC that is gone) is ``launcher/hosts.py``."""

from __future__ import annotations

#: seconds every process has to read the wall file and say so (``tile_comm``), before any split
AGREE_S = 120.0


def tile_comm(world, wall_path: str | None, dark: tuple[int, ...] = ()):
    """The job's communicator with each process's rank the tile it drives: where a wall file puts
    a host's tiles apart (a PC per row), MPI's processes, filled into the hosts in order, are
    renumbered by ``wall.tile_order`` (one split at start; every process reads the same file).
    Without a PC that is gone (``dark``: its tiles), the launcher starts its processes last, on
    the last host that answers (``survivors``): they take the dark tiles. The world itself
    where nothing is renumbered. Every process says whether it could read the file before any
    splits (a bounded agreement): a file missing or bad on one host is an InputError on every
    rank, naming that host, where that host once skipped the split the others blocked in."""
    import socket

    from multigpu.errors import InputError
    from multigpu.rank.exchange import allgather_text
    from multigpu.wall import load_wall, tile_order

    order, why = None, ""
    try:
        order = tile_order(load_wall(wall_path), world.Get_size()) if wall_path else None
    except InputError as exc:
        why = str(exc)
    if wall_path:
        said = allgather_text(world, f"{socket.gethostname()}\t{why}", AGREE_S, "wall file")
        every = [t.split("\t", 1) for t in said]
        bad = [(r, host, e) for r, (host, e) in enumerate(every) if e]
        if len(bad) == len(every) and len({e for _, _, e in bad}) == 1:
            raise InputError(bad[0][2])
        if bad:
            r, host, e = bad[0]
            raise InputError(f"{e} (on host {host}, rank {r}; the wall file must be at the same path on every host)")
    if dark:
        base = order or list(range(world.Get_size()))
        order = [t for t in base if t not in dark] + [t for t in base if t in dark]
    if order is None or order == sorted(order):
        return world
    return world.Split(0, order[world.Get_rank()])
