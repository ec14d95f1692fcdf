"""Simulated hosts on this machine, for the tests and the network benchmark: Linux namespaces,
one per host name (DESIGN.md, "Hosts").

Each host is a UTS + mount namespace (``unshare --uts --mount``) with its own hostname and a
fresh ``/dev/shm``. With ``network`` it also has its own System V IPC and network namespaces, so
what its ranks send another host crosses a network device: a veth pair from the host's ``eth0``
to a bridge on this machine, a private /24 (the bridge .1, the hosts .2 up), each host's
``/etc/hosts`` naming every host and this machine, and ``tc`` shaping both ends of each link to
``rate`` (token bucket) and ``delay`` (netem, where the kernel has it; ``shaped`` says what was
shaped). ``wire()`` reads the bytes each host sent and received from the link's counters.
Without ``network`` the hosts share this machine's IPC and network, and MPI passes messages
between them through shared memory and the loopback.

A remote-shell script (``rsh``) enters a host with ``nsenter`` and runs the command there, as ssh
would; the launchers take it through ``MULTIGPU_RSH``, and ``env`` holds what keeps MPI on the
hosts' own links (Open MPI's and UCX's interfaces). On exit every process inside the namespaces is
killed by id, then the namespaces' holders, then the links and the bridge.
"""

from __future__ import annotations

import os
import secrets
import shlex
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

RSH = """#!/bin/sh
# remote shell onto a simulated host: rsh [-options] HOST COMMAND... (the command runs there in sh, as over ssh)
while [ "${1#-}" != "$1" ]; do shift; done
host=$1; shift
if [ -e "%(dir)s/$host.down" ]; then echo "ssh: connect to host $host port 22: No route to host" >&2; exit 255; fi
exec nsenter --target "$(cat "%(dir)s/$host.pid")" %(spaces)s -- sh -c "$*"
"""


class Unavailable(RuntimeError):
    """This machine cannot make the hosts (no namespaces, no iproute2): the reason."""


def _uts(pid: int) -> str | None:
    try:
        return os.readlink(f"/proc/{pid}/ns/uts")
    except OSError:
        return None


def _ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10)
    if done.returncode:
        raise Unavailable(f"ip {' '.join(args)}: {done.stderr.strip()}")


def _rate_bytes(rate: str) -> float:
    """``1gbit``, ``10gbit``, ``100mbit`` in bytes per second."""
    units = {"gbit": 1e9, "mbit": 1e6, "kbit": 1e3}
    for u, f in units.items():
        if rate.endswith(u):
            return float(rate[:-len(u)]) * f / 8
    raise ValueError(f"a link rate like 1gbit or 100mbit, got '{rate}'")


class SimHosts:
    """``with SimHosts(["a", "b"], tmp) as h``: hosts a and b; ``h.rsh`` is the remote shell,
    ``h.kill(name)`` kills every process on one host, ``h.down(name)`` also makes its remote
    shell fail until ``h.up(name)``. ``network``: each host on its own link of ``rate`` and
    ``delay`` (``wire()`` counts its bytes). ``private``: folders a host sees as its own, empty
    (what one PC writes there the other does not see)."""

    def __init__(self, names: list[str], where: Path, network: bool = False, rate: str = "1gbit",
                 delay: str = "0.1ms", private: dict[str, list[Path]] | None = None):
        self.names, self.dir = list(names), Path(where)
        self.private = dict(private or {})  # host -> folders it sees empty, its own (as on another PC's disk)
        self.network, self.rate, self.delay = network, rate, delay
        self.holders: dict[str, subprocess.Popen] = {}
        self.pids: dict[str, int] = {}
        self.links: dict[str, str] = {}  # host -> its link's end on this machine
        self.bridge = None
        self.shaped: dict[str, str] = {}  # what tc shaped: "rate", "delay" (or why not)
        self.subnet = self.gateway = None
        self.addresses: dict[str, str] = {}
        self.spaces = ["--uts", "--mount", "--ipc", "--net"] if network else ["--uts", "--mount"]

    def __enter__(self) -> "SimHosts":
        need = ["unshare", "nsenter"] + (["ip", "tc"] if self.network else [])
        missing = [t for t in need if not shutil.which(t)]
        if missing:
            raise Unavailable(f"no {', '.join(missing)} (Debian: util-linux, iproute2)")
        self.dir.mkdir(parents=True, exist_ok=True)
        try:
            if self.network:
                self._subnet()
            for name in self.names:
                self._host(name)
            if self.network:
                for i, name in enumerate(self.names):
                    self._link(i, name)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        self.rsh = self.dir / "rsh"
        self.rsh.write_text(RSH % {"dir": self.dir, "spaces": " ".join(self.spaces)})
        self.rsh.chmod(0o755)
        if self.network:  # MPI's traffic between the hosts on their links (each host's eth0)
            self.env = {"MULTIGPU_RSH": str(self.rsh), "UCX_NET_DEVICES": "eth0",
                        "OMPI_MCA_btl_tcp_if_include": self.subnet, "OMPI_MCA_oob_tcp_if_include": self.subnet}
        else:  # on the loopback (Open MPI's TCP would also use this machine's other interfaces)
            self.env = {"MULTIGPU_RSH": str(self.rsh), "UCX_NET_DEVICES": "lo",
                        "OMPI_MCA_btl_tcp_if_include": "lo", "OMPI_MCA_oob_tcp_if_include": "lo"}
        return self

    # -- making it
    def _subnet(self) -> None:
        """A /24 no interface of this machine is on, and names for the bridge and links."""
        taken = subprocess.run(["ip", "-o", "-4", "addr"], capture_output=True, text=True, timeout=10).stdout
        for _ in range(100):
            a, b = 200 + secrets.randbelow(50), secrets.randbelow(256)
            if f" 10.{a}.{b}." not in taken:
                break
        self.subnet, self.gateway = f"10.{a}.{b}.0/24", f"10.{a}.{b}.1"
        self.addresses = {n: f"10.{a}.{b}.{i + 2}" for i, n in enumerate(self.names)}
        self.tag = secrets.token_hex(3)
        self.bridge = f"mg{self.tag}br"
        _ip("link", "add", self.bridge, "type", "bridge")
        _ip("addr", "add", f"{self.gateway}/24", "dev", self.bridge)
        _ip("link", "set", self.bridge, "up")
        lines = ["127.0.0.1 localhost", f"{self.gateway} {socket.gethostname()}"]
        lines += [f"{addr} {n}" for n, addr in self.addresses.items()]
        (self.dir / "etc-hosts").write_text("\n".join(lines) + "\n")

    def _host(self, name: str) -> None:
        pidfile = self.dir / f"{name}.pid"
        pidfile.unlink(missing_ok=True)  # a directory used before: never a stale host's id
        hosts = f"mount --bind {self.dir / 'etc-hosts'} /etc/hosts && " if self.network else ""
        disks = "".join(f"mkdir -p {shlex.quote(str(d))} && mount -t tmpfs -o size=1g tmpfs {shlex.quote(str(d))} && "
                        for d in self.private.get(name, ()))  # a folder of its own disk there
        script = (f"hostname {name} && mount -t tmpfs -o size=2g tmpfs /dev/shm && {hosts}{disks}"
                  f"echo $$ > {pidfile}.part && mv {pidfile}.part {pidfile} && exec sleep 86400")
        flags = ["--uts", "--mount"] + (["--ipc", "--net"] if self.network else [])
        self.holders[name] = subprocess.Popen(
            ["unshare", *flags, "--fork", "--propagation", "private", "sh", "-c", script],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
        deadline = time.monotonic() + 10
        while not pidfile.exists():
            if self.holders[name].poll() is not None or time.monotonic() > deadline:
                err = self.holders[name].stderr.read().decode(errors="replace").strip()
                raise Unavailable(f"cannot make a namespace host here: {err or 'timed out'}")
            time.sleep(0.02)
        self.pids[name] = int(pidfile.read_text())

    def _link(self, i: int, name: str) -> None:
        """Host ``name``'s eth0, linked to the bridge and shaped at both ends."""
        outside, inside = f"mg{self.tag}h{i}", f"mg{self.tag}p{i}"
        _ip("link", "add", outside, "type", "veth", "peer", "name", inside)
        self.links[name] = outside
        _ip("link", "set", inside, "netns", str(self.pids[name]))
        _ip("link", "set", outside, "master", self.bridge, "up")
        pid = str(self.pids[name])
        for step in (["link", "set", inside, "name", "eth0"],
                     ["addr", "add", f"{self.addresses[name]}/24", "dev", "eth0"],
                     ["link", "set", "eth0", "up"], ["link", "set", "lo", "up"]):
            self._in(pid, "ip", *step)
        self._shape(None, outside)
        self._shape(pid, "eth0")

    def _in(self, pid: str, *cmd: str) -> subprocess.CompletedProcess:
        done = subprocess.run(["nsenter", "--target", pid, "--net", "--", *cmd], capture_output=True, text=True,
                              timeout=10)
        if done.returncode:
            raise Unavailable(f"{' '.join(cmd)} on a host: {done.stderr.strip()}")
        return done

    def _shape(self, pid: str | None, dev: str) -> None:
        """``rate`` and ``delay`` on ``dev`` (in host ``pid``'s namespace, or this machine's): netem
        where the kernel has it, else a token bucket for the rate alone (the delay unshaped)."""
        rate = _rate_bytes(self.rate)
        burst = f"{max(64_000, int(rate / 100))}b"  # >= rate/HZ, or the bucket cannot reach the rate
        pre = [] if pid is None else ["nsenter", "--target", pid, "--net", "--"]
        tries = [("rate and delay", ["tc", "qdisc", "add", "dev", dev, "root", "netem", "delay", self.delay,
                                     "rate", self.rate, "limit", "100000"]),
                 ("rate", ["tc", "qdisc", "add", "dev", dev, "root", "tbf", "rate", self.rate, "burst", burst,
                           "latency", "50ms"])]
        for what, cmd in tries:
            done = subprocess.run(pre + cmd, capture_output=True, text=True, timeout=10)
            if done.returncode == 0:
                self.shaped = {"rate": self.rate, "delay": self.delay if "delay" in what else
                               "not shaped (no netem in this kernel)"}
                return
        raise Unavailable(f"tc cannot shape {dev}: {done.stderr.strip()}")

    # -- using it
    def wire(self) -> dict[str, tuple[int, int]]:
        """Bytes each host has sent and received on its link so far (its link's counters)."""
        out = {}
        for name, dev in self.links.items():
            stats = Path("/sys/class/net") / dev / "statistics"
            # this machine's end of the link: what it received is what the host sent
            out[name] = (int((stats / "rx_bytes").read_text()), int((stats / "tx_bytes").read_text()))
        return out

    def run(self, name: str, *cmd: str, timeout: float = 30) -> subprocess.CompletedProcess:
        """``cmd`` on host ``name``."""
        return subprocess.run(["nsenter", "--target", str(self.pids[name]), *self.spaces, "--", *cmd],
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
        for dev in [*self.links.values(), *([self.bridge] if self.bridge else [])]:
            subprocess.run(["ip", "link", "del", dev], capture_output=True, timeout=10)  # gone with its host, or now
        self.links = {}
        self.bridge = None
