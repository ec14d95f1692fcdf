"""The operator's view on a PC of its own: the launcher's part (``display/remote.py`` is the view).

Where the wall file's ``monitor`` names a ``host`` (the operator's desk PC) and the walkthrough
asks for ``--monitor``, the launcher starts ``multigpu monitor-view`` there through the remote
shell (as it starts the ranks; on this machine, directly) before the job, writes a random token on
its standard input (never on a command line), reads the port it listens on, and tells rank 0 where
to find it (``MULTIGPU_MONITOR``) and the token to bring (``remote.TOKEN_ENV``). The view outlives a
restart of the wall (``--recover``) and ends with the launcher.
"""

from __future__ import annotations

import os
import secrets
import select
import shlex
import subprocess
import sys

from multigpu.errors import InputError
from multigpu.launcher.supervise import flag_value

#: the environment variable that tells rank 0 where the view listens (HOST:PORT)
ENV = "MULTIGPU_MONITOR"
#: seconds the view has to start and say its port
START = 30.0
#: the operator's page's token (``rank/panel_link.py`` reads it; MULTIGPU_* reaches every rank)
PANEL_TOKEN_ENV = "MULTIGPU_PANEL_TOKEN"


def own_pc(argv: list[str]) -> dict | None:
    """The wall file's monitor entry where a walkthrough asks for ``--monitor`` and the file puts
    the view on a host of its own; else None."""
    if not argv or argv[0] != "walkthrough" or not any(a == "--monitor" or a.startswith("--monitor=") for a in argv):
        return None
    path = flag_value(argv, "--wall")
    if path is None:
        return None
    from multigpu.wall import load_wall

    wall = load_wall(path)
    if "host" not in wall.monitor_on:
        return None
    return {**wall.monitor_on, "position": wall.monitor or (0, 0)}


def start_view(on: dict) -> subprocess.Popen:
    """Start the view on its host; its process, once it listens (``ENV`` set to where)."""
    from multigpu.display.remote import TOKEN_ENV
    from multigpu.launcher.hosts import is_this_machine, remote_shell, shell_command

    x, y = on["position"]
    cmd = [sys.executable, "-m", "multigpu", "monitor-view", "--position", f"{x}x{y}",
           *(["--display", on["display"]] if on.get("display") else []),
           "--listen", on.get("address") or on["host"]]  # where rank 0 reaches it (never every interface)
    host = on["host"]
    if not is_this_machine(host):
        cmd = [*shell_command(remote_shell()), host, shlex.join(cmd)]
    token = secrets.token_urlsafe(24)
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        proc.stdin.write(token + "\n")
        proc.stdin.close()
    except OSError:  # the view ended at once: said below
        pass
    ready, _, _ = select.select([proc.stdout], [], [], START)
    line = proc.stdout.readline().split() if ready else []
    if len(line) != 2 or line[0] != "port":
        stop_view(proc)
        raise InputError.of("monitor", f"the operator's view on {host} did not start ({shlex.join(cmd)})")
    os.environ[ENV] = f"{on.get('address', host)}:{line[1]}"
    os.environ[TOKEN_ENV] = token
    return proc


def panel_token() -> None:
    """The operator's page (``--panel``) token for every run of this job, restarts included (rank
    0 takes it from ``PANEL_TOKEN_ENV``), unless the user gave one."""
    os.environ.setdefault(PANEL_TOKEN_ENV, secrets.token_urlsafe(24))


def stop_view(proc: subprocess.Popen | None) -> None:
    """End the view (its whole session, the remote shell's with it)."""
    if proc is not None and proc.poll() is None:
        try:
            os.killpg(proc.pid, 9)
        except ProcessLookupError:
            pass
        proc.wait(10)
