"""User-facing errors: one clear line naming the setting or file and the problem.

Library code names the *field* a bad value came from (``InputError.of("seed", "must be >= 0")``),
and the error reads as the command line says it: "--seed must be >= 0". Fields and flags follow
one convention (``merge_below`` is ``--merge-below``; a flag named otherwise is declared with its
field, ``options.py``, and registered here), so the mapping lives here, once.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad user input (a setting, a model file, a path file). One line; the CLI exits 2."""

    def __init__(self, message: str, field: str | None = None):
        super().__init__(message)
        self.message, self.field = message, field

    @classmethod
    def of(cls, field: str, message: str) -> "InputError":
        """An error about the value of ``field`` (a SceneSpec/WalkConfig field name)."""
        return cls(message, field)

    def __str__(self) -> str:
        return f"{flag(self.field)} {self.message}" if self.field else self.message


class WriteFailed(RuntimeError):
    """An output could not be written (disk full, a path that takes no files): one line naming
    the path, exit 2; what was written before it stays (rows whole, files whole or absent)."""

    @classmethod
    def of(cls, path, exc: OSError, kept: str = "") -> "WriteFailed":
        """The failure of writing ``path`` with ``exc``; ``kept``: what of it stays."""
        return cls(f"cannot write {path}: {exc.strerror or exc}" + (f"; {kept}" if kept else ""))


#: fields whose flag is not ``--field-name`` (``options.register``: ``overlay`` is ``--no-overlay``)
RENAMED: dict[str, str] = {}


def flag(field: str) -> str:
    """The command-line flag of a configuration field."""
    return RENAMED.get(field) or "--" + field.replace("_", "-")


def check_file(path, field: str | None, what: str = "file"):
    """``path`` as a ``Path`` if it is a readable regular file, else an InputError that says
    what it is instead (missing, a directory, a symlink loop, a device or pipe, unreadable)."""
    import errno
    import os
    import stat
    from pathlib import Path

    p = Path(path)
    where = str(p)
    error = (lambda text: InputError.of(field, text)) if field else InputError
    try:
        st = p.stat()
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise error(f"{where}: a symbolic link loop, not a {what}") from None
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            raise error(f"{where}: {what} not found") from None
        raise error(f"{where}: cannot read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        raise error(f"{where}: is a directory, not a {what}")
    if not stat.S_ISREG(st.st_mode):
        kind = ("a character device" if stat.S_ISCHR(st.st_mode) else "a block device" if stat.S_ISBLK(st.st_mode)
                else "a named pipe" if stat.S_ISFIFO(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode)
                else "not a regular file")
        raise error(f"{where}: is {kind}, not a {what}")
    if not os.access(p, os.R_OK):
        raise error(f"{where}: not readable (permission denied)")
    return p
