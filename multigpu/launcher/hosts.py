"""Where the ranks run: ``--hosts a:2,b:2`` or ``--hostfile FILE``, one form for every MPI.

Pure parsing (no MPI): a list of (host, slots), ranks filling the hosts in order (the first
``slots`` ranks on the first host, and so on), as both MPICH's Hydra and Open MPI place them.
A hostfile holds one host per line as ``host``, ``host:N`` (MPICH's form) or ``host slots=N``
(Open MPI's), ``#`` starts a comment; so a user's existing hostfile of either MPI works with
either. The launcher (``mpirun.Launcher``) writes the list in its MPI's own syntax.
The ranks' side of placement (each rank's tile, whatever host it landed on) is ``rank/tiles.py``.
"""

from __future__ import annotations

import re
from pathlib import Path

from multigpu.errors import InputError

#: a host name or address as both launchers accept it (no spaces, commas or colons)
_NAME = re.compile(r"^[A-Za-z0-9_.\-\[\]]+$")


def _entry(text: str, where: str) -> tuple[str, int]:
    m = re.fullmatch(r"\s*(\S+?)(?::(\S+)|\s+slots\s*=\s*(\S+))?\s*", text)
    if not m or not _NAME.match(m.group(1)):
        raise InputError(f"{where}: '{text.strip()}' is not a host (want HOST, HOST:N or HOST slots=N)")
    raw = m.group(2) or m.group(3)
    if raw is None:
        return m.group(1), 1
    if not raw.isdigit() or int(raw) < 1:
        raise InputError(f"{where}: '{text.strip()}': the rank count must be a whole number >= 1")
    return m.group(1), int(raw)


def _merged(entries: list[tuple[str, int]]) -> list[tuple[str, int]]:
    """Repeated hosts add their slots (first appearance keeps its place)."""
    out: dict[str, int] = {}
    for h, n in entries:
        out[h] = out.get(h, 0) + n
    return list(out.items())


def parse_hosts(text: str) -> list[tuple[str, int]]:
    """``a:2,b:2`` (or ``a,b``: one rank each) as [(host, slots)]."""
    parts = text.split(",")
    if not text.strip() or any(not p.strip() for p in parts):
        raise InputError.of("hosts", f"'{text}' is not a host list (want e.g. a:2,b:2)")
    return _merged([_entry(p, "--hosts") for p in parts])


def read_hostfile(path: str) -> list[tuple[str, int]]:
    """The hosts of ``path`` (see the module doc)."""
    p = Path(path).expanduser()
    try:
        lines = p.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError.of("hostfile", f"{path}: cannot read it ({exc.__class__.__name__}: "
                         f"{getattr(exc, 'strerror', None) or exc})") from None
    entries = []
    for i, line in enumerate(lines, 1):
        line = line.split("#", 1)[0]
        if line.strip():
            entries.append(_entry(line, f"--hostfile {path}, line {i}"))
    if not entries:
        raise InputError.of("hostfile", f"{path}: no hosts in it")
    return _merged(entries)


def placement(hosts: list[tuple[str, int]], ranks: int, where: str = "--hosts") -> list[str]:
    """The host of each of ``ranks`` ranks; refused when the hosts have fewer slots."""
    slots = sum(n for _, n in hosts)
    if slots < ranks:
        raise InputError(f"{where}: {slots} rank slots on {len(hosts)} host(s), but the job needs {ranks} ranks")
    return [h for h, n in hosts for _ in range(n)][:ranks]


def spec(hosts: list[tuple[str, int]]) -> str:
    """``a:2,b:2``: the form both MPIs take on their command line."""
    return ",".join(f"{h}:{n}" for h, n in hosts)


#: seconds a host may take to answer the remote shell's probe (ssh's own connect included)
PROBE_TIMEOUT = 20.0


def is_this_machine(host: str) -> bool:
    """Whether ``host`` names this machine (its name, localhost, or one of its own addresses):
    the launchers start ranks there by a local fork, not through the remote shell."""
    import socket

    if host in ("localhost", socket.gethostname(), socket.getfqdn()):
        return True
    try:
        addr = socket.gethostbyname(host)
    except OSError:
        return False
    if addr == "127.0.0.1":
        return True
    try:
        mine = {a[4][0] for a in socket.getaddrinfo(socket.gethostname(), None)}
    except OSError:
        mine = set()
    return addr in mine


def remote_shell(env=None) -> str | None:
    """The remote shell every launcher step uses (the ranks' MPI launchers, host checks, the
    operator's view): ``$MULTIGPU_RSH`` as an executable's path, or None for ssh. A name that is
    no executable is one InputError, the same wherever it is asked."""
    import os
    import shutil

    name = (os.environ if env is None else env).get("MULTIGPU_RSH")
    if not name:
        return None
    found = shutil.which(name)
    if not found:
        raise InputError(f"MULTIGPU_RSH={name}: not an executable")
    return found


def shell_command(rsh: str | None, timeout: float | None = None) -> list[str]:
    """The command that runs something on another host: ``rsh``, or ssh in batch mode (never a
    password prompt), with a connect timeout where one is given."""
    if rsh:
        return [rsh]
    return ["ssh", "-o", "BatchMode=yes", *(["-o", f"ConnectTimeout={int(timeout)}"] if timeout else [])]


def probe(hosts: list[tuple[str, int]], rsh: str | None, timeout: float = PROBE_TIMEOUT) -> None:
    """Every host that is not this machine answers ``RSH HOST true`` (the remote shell the
    launchers will use: ``rsh``, or ssh in batch mode), all asked at once; the first that does
    not is one InputError naming the host, the shell and what it said, before any rank starts
    (the MPI launchers' own reports name neither)."""
    failed = unreachable(hosts, rsh, timeout)
    if failed:
        raise InputError(next(iter(failed.values())))


def unreachable(hosts: list[tuple[str, int]], rsh: str | None, timeout: float = PROBE_TIMEOUT) -> dict[str, str]:
    """The hosts (not this machine) that do not answer ``RSH HOST true``, all asked at once, each
    with one line saying what went wrong."""
    import shlex
    import subprocess

    shell = shell_command(rsh, timeout)
    remote = [h for h, _ in hosts if not is_this_machine(h)]
    running = []
    for h in remote:
        try:
            running.append((h, subprocess.Popen([*shell, h, "true"], stdin=subprocess.DEVNULL,
                                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                                start_new_session=True)))
        except OSError as exc:
            raise InputError(f"remote shell {shlex.join(shell)}: cannot run it ({exc.strerror or exc})") from None
    failed = {}
    for h, proc in running:  # hosts, not ranks
        try:
            _, err = proc.communicate(timeout=timeout)
            code = proc.returncode
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
            code = None
        if code != 0:
            said = (err or "").strip().splitlines()
            what = f"no answer within {timeout:g} s" if code is None else f"exit {code}"
            failed[h] = (f"host {h}: the remote shell '{shlex.join(shell)} {h} true' failed ({what}"
                         + (f": {said[-1]}" if said else "") + "); check that it reaches the host without a "
                         "password (MULTIGPU_RSH names another shell)")
    return failed


def survivors(hosts: list[tuple[str, int]], gone: set[str]) -> list[tuple[str, int]]:
    """The placement without the ``gone`` hosts: the others in order, the last of them also
    running the gone hosts' processes (they stand in for the dark tiles: ``rank.tiles.tile_comm``)."""
    kept = [(h, n) for h, n in hosts if h not in gone]
    if not kept:
        return []
    extra = sum(n for h, n in hosts if h in gone)
    return [*kept[:-1], (kept[-1][0], kept[-1][1] + extra)]
