"""Simulated hosts for the tests: Linux namespaces on this machine, one per host name.

Each host is a UTS + mount namespace (``unshare --uts --mount``) with its own hostname and a
fresh ``/dev/shm``; the network namespace stays this machine's, so every connection stays on
its loopback and local addresses (``SimHosts.env`` keeps MPI's traffic on the loopback
interface). A remote-shell script (``rsh``) enters a host with ``nsenter`` and runs the
command there, as ssh would; the launchers take it through ``MULTIGPU_RSH``. On exit every
process inside the namespaces is killed by id, then the namespaces' own holders. Tests skip
with a reason where namespaces are not permitted.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

RSH = """#!/bin/sh
# remote shell onto a simulated host: rsh [-options] HOST COMMAND... (the command runs there in sh, as over ssh)
while [ "${1#-}" != "$1" ]; do shift; done
host=$1; shift
if [ -e "%s/$host.down" ]; then echo "ssh: connect to host $host port 22: No route to host" >&2; exit 255; fi
exec nsenter --target "$(cat "%s/$host.pid")" --uts --mount -- sh -c "$*"
"""


def _uts(pid: int) -> str | None:
    try:
        return os.readlink(f"/proc/{pid}/ns/uts")
    except OSError:
        return None


class SimHosts:
    """``with SimHosts(["a", "b"], tmp) as h``: hosts a and b; ``h.rsh`` is the remote shell,
    ``h.kill(name)`` kills every process on one host, ``h.down(name)`` also makes its remote
    shell fail until ``h.up(name)``."""

    def __init__(self, names: list[str], where: Path):
        self.names, self.dir = list(names), Path(where)
        self.holders: dict[str, subprocess.Popen] = {}
        self.pids: dict[str, int] = {}

    def __enter__(self) -> "SimHosts":
        if not (shutil.which("unshare") and shutil.which("nsenter")):
            pytest.skip("no unshare/nsenter (Debian: util-linux)")
        self.dir.mkdir(parents=True, exist_ok=True)
        try:
            for name in self.names:
                pidfile = self.dir / f"{name}.pid"
                pidfile.unlink(missing_ok=True)  # a directory used before: never a stale host's id
                script = (f"hostname {name} && mount -t tmpfs -o size=2g tmpfs /dev/shm && "
                          f"echo $$ > {pidfile}.part && mv {pidfile}.part {pidfile} && exec sleep 3600")
                self.holders[name] = subprocess.Popen(
                    ["unshare", "--uts", "--mount", "--fork", "--propagation", "private", "sh", "-c", script],
                    stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
                deadline = time.monotonic() + 10
                while not pidfile.exists():
                    if self.holders[name].poll() is not None or time.monotonic() > deadline:
                        err = self.holders[name].stderr.read().decode(errors="replace").strip()
                        self.__exit__(None, None, None)
                        pytest.skip(f"cannot make a namespace host here: {err or 'timed out'}")
                    time.sleep(0.02)
                self.pids[name] = int(pidfile.read_text())
        except BaseException:
            self.__exit__(None, None, None)
            raise
        #: MPI's traffic between the hosts on the loopback addresses only (Open MPI's TCP would
        #: also use this machine's other interfaces; UCX is told the same)
        self.env = {"MULTIGPU_RSH": str(self.dir / "rsh"), "UCX_NET_DEVICES": "lo",
                    "OMPI_MCA_btl_tcp_if_include": "lo", "OMPI_MCA_oob_tcp_if_include": "lo"}
        self.rsh = self.dir / "rsh"
        self.rsh.write_text(RSH % (self.dir, self.dir))
        self.rsh.chmod(0o755)
        return self

    def run(self, name: str, *cmd: str, timeout: float = 30) -> subprocess.CompletedProcess:
        """``cmd`` on host ``name``."""
        return subprocess.run(["nsenter", "--target", str(self.pids[name]), "--uts", "--mount", "--", *cmd],
                              capture_output=True, text=True, timeout=timeout)

    def processes(self, name: str) -> list[int]:
        """Every process on host ``name`` but the namespace's holder (and ``unshare`` above it)."""
        ns = _uts(self.pids[name])
        holders = {self.pids[name], self.holders[name].pid}
        mine = []
        for d in os.listdir("/proc"):
            if d.isdigit() and int(d) not in holders and _uts(int(d)) == ns:
                mine.append(int(d))
        return mine

    def kill(self, name: str) -> None:
        """SIGKILL every process on host ``name`` (the host fails, its namespace stays)."""
        for pid in self.processes(name):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def down(self, name: str) -> None:
        """Host ``name`` fails and stays down: its processes killed, its remote shell refused."""
        (self.dir / f"{name}.down").touch()
        self.kill(name)

    def up(self, name: str) -> None:
        """Host ``name`` answers its remote shell again."""
        (self.dir / f"{name}.down").unlink(missing_ok=True)

    def __exit__(self, *exc) -> None:
        for name in self.pids:
            self.kill(name)
        for p in self.holders.values():
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            p.wait(timeout=10)
            if p.stderr:
                p.stderr.close()
