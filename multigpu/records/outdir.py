"""A run's output directory: one job at a time, the run's own files only, nothing half-written.

Contract (``--out DIR``, README "Outputs"):

* One job writes a directory at a time: rank 0 holds an exclusive ``flock`` on
  ``DIR/.multigpu.lock`` (holder's pid and host inside) for the whole run; a second job is
  refused with one line naming the directory and the holder. The kernel drops the lock when
  the holder dies, so a killed run never leaves the directory locked.
* A run replaces the previous run's outputs in DIR: once its inputs are agreed valid (never
  for a run refused at the door), it removes exactly the files a run writes
  (``timings.csv``, ``summary.json``, ``mosaic.mp4`` and a restarted run's ``mosaic-rN.mp4``,
  ``mosaic/frame_*.png``, stray temp files)
  and leaves anything else in DIR alone. Old mosaics never mix with new ones.
* A run refused at the door leaves no directory behind that it created.
* Files are written whole or not at all: CSV rows frame by frame (``report.TimingWriter``),
  JSON and PNG through a temp file that is removed when the write fails (disk full).
"""

from __future__ import annotations

import errno
import fcntl
import os
import socket
from pathlib import Path

from multigpu.errors import InputError

LOCK = ".multigpu.lock"
RUN_FILES = ("timings.csv", "summary.json", "mosaic.mp4")
TEMP_GLOBS = (".*.tmp", ".*.tmp.png", ".write-test-*")


class OutputDir:
    """Rank 0's handle on ``--out``: created if needed, locked, proven writable."""

    def __init__(self, path: str | Path, flag: str = "--out"):
        self.path = Path(path)
        self.created = False
        self._fd: int | None = None
        where = f"{flag} {self.path}"
        if self.path.exists() and not self.path.is_dir():
            raise InputError(f"{where}: exists and is not a directory")
        try:
            if not self.path.exists():
                self.path.mkdir(parents=True)
                self.created = True
            fd = os.open(self.path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            self.abandon()
            raise InputError(f"{where}: not writable ({exc.strerror or exc})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "unknown"
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise InputError(f"{where}: in use by another multigpu job ({holder}); "
                                 "wait for it or choose another --out") from None
            raise InputError(f"{where}: cannot lock ({exc.strerror or exc})") from None
        self._fd = fd
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
        except OSError as exc:
            self.abandon()
            raise InputError(f"{where}: not writable ({exc.strerror or exc})") from None

    def clear_previous(self) -> None:
        """Remove the files an earlier run wrote here (see the module doc), nothing else."""
        victims = [self.path / f for f in RUN_FILES]
        victims += sorted((self.path / "mosaic").glob("frame_*.png")) + sorted(self.path.glob("mosaic-r*.mp4"))
        for pattern in TEMP_GLOBS:
            victims += sorted(self.path.glob(pattern)) + sorted((self.path / "mosaic").glob(pattern))
        for v in victims:
            v.unlink(missing_ok=True)
        (self.path / "mosaic").mkdir(exist_ok=True)

    def release(self) -> None:
        """Unlock and remove the lock file (the run is over)."""
        if self._fd is not None:
            try:
                (self.path / LOCK).unlink(missing_ok=True)
            except OSError:
                pass
            os.close(self._fd)
            self._fd = None

    def abandon(self) -> None:
        """The run was refused: release, and remove the directory if this run made it and
        nothing else is in it."""
        self.release()
        if self.created:
            try:
                self.path.rmdir()
            except OSError:
                pass
