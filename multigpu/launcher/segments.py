"""Shared-memory segments a failed job leaves behind, swept by the launcher.

The MPI runtimes back node-shared memory (``MPI_Win_allocate_shared``: the exchange's segment,
the shared projection; their own intranode channels) with files in ``/dev/shm`` that the ranks
remove as they finish. A rank killed outright never does: each failed job left ~2-4 MiB there,
and a wall that heals by restarting would fill the host's memory with them over the days. After
a job ends abnormally the launcher removes the segment files of the runtimes' naming
(``PATTERNS``) that were made since the job started, belong to this user, and that no process
maps any more (``/proc/*/maps``): another job's live segment is never touched.
"""

from __future__ import annotations

import glob
import os
from pathlib import Path

#: segment files of MPICH (its shm channel and windows) and Open MPI (vader, sm)
PATTERNS = ("mpich_shm_*", "vader_segment.*", "sm_segment.*")
SHM = Path("/dev/shm")


def _mapped(where: Path) -> set[str]:
    """Every file in ``where`` some process maps now."""
    out: set[str] = set()
    prefix = f"{where}/"
    for maps in glob.glob("/proc/[0-9]*/maps"):
        try:
            with open(maps) as fh:
                out.update(line.split(None, 5)[-1].strip() for line in fh if prefix in line)
        except OSError:
            continue
    return out


def sweep(since: float, where: Path = SHM) -> list[str]:
    """Remove the runtimes' segment files made at or after ``since`` (epoch seconds) that this
    user owns and no process maps; their names."""
    if not where.is_dir():
        return []
    candidates = []
    for pattern in PATTERNS:
        for p in where.glob(pattern):
            try:
                st = p.stat()
            except OSError:
                continue
            if st.st_uid == os.getuid() and st.st_mtime >= since - 1.0:
                candidates.append(p)
    if not candidates:
        return []
    busy = _mapped(where)
    gone = []
    for p in candidates:
        if str(p) not in busy:
            try:
                p.unlink()
                gone.append(p.name)
            except OSError:
                pass
    return gone
