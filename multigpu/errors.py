"""User-facing errors: one clear line naming the flag or file and the problem."""


class InputError(ValueError):
    """Bad user input (a flag, a model file, a path file). Printed as one line, exit code 2."""


def check_file(path, flag: str, what: str = "file"):
    """``path`` as a ``Path`` if it is a readable regular file, else an InputError that says
    what it is instead (missing, a directory, a symlink loop, a device or pipe, unreadable)."""
    import errno
    import os
    import stat
    from pathlib import Path

    p = Path(path)
    where = f"{flag} {p}" if flag else str(p)
    try:
        st = p.stat()
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InputError(f"{where}: a symbolic link loop, not a {what}") from None
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            raise InputError(f"{where}: {what} not found") from None
        raise InputError(f"{where}: cannot read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{where}: is a directory, not a {what}")
    if not stat.S_ISREG(st.st_mode):
        kind = ("a character device" if stat.S_ISCHR(st.st_mode) else "a block device" if stat.S_ISBLK(st.st_mode)
                else "a named pipe" if stat.S_ISFIFO(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode)
                else "not a regular file")
        raise InputError(f"{where}: is {kind}, not a {what}")
    if not os.access(p, os.R_OK):
        raise InputError(f"{where}: not readable (permission denied)")
    return p
