"""Start ``multigpu`` under ``mpiexec``: the right flags for the MPI at hand, always bounded.

Which MPI: ``$MULTIGPU_MPIEXEC`` if set, else the ``mpiexec`` beside this interpreter (the
``mpich`` wheel's), else the first on ``PATH``. ``mpiexec --version`` tells MPICH (Hydra) from
Open MPI (OpenRTE / Open MPI). Open MPI gets what it needs on a workstation: ``--oversubscribe``
(more ranks than cores), its documented root opt-in when run as root, ``--quiet`` (its
multi-line banner after a non-zero exit), and ``MPI4PY_LIBMPI`` so mpi4py's wheel loads Open
MPI's library even where the ``mpich`` wheel is installed too.

Used by the launch scripts (``python -m multigpu.launcher.mpirun -n K ARGS``), the experiments and
the tests: a job started from Python runs in its own process group, which is killed whole
(launcher and every rank) when it outlives its timeout.
"""

from __future__ import annotations

import functools
import os
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

from multigpu import exits
from multigpu.errors import InputError
from multigpu.launcher.supervise import flag_value, out_dir, supervise

#: the soname of Open MPI's library (3.x to 5.x); mpi4py loads it by this name
OPENMPI_LIBMPI = "libmpi.so.40"


class JobTimeout(RuntimeError):
    """The job outlived its timeout and was killed; ``stdout``/``stderr`` hold what it wrote."""

    def __init__(self, message: str, stdout: str, stderr: str):
        super().__init__(message)
        self.stdout, self.stderr = stdout, stderr


@functools.lru_cache(maxsize=8)
def flavor(mpiexec: str) -> str:
    """'openmpi', 'mpich' or 'unknown', from ``mpiexec --version``."""
    try:
        out = subprocess.run([mpiexec, "--version"], capture_output=True, text=True, timeout=20)
        text = out.stdout + out.stderr
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    if "Open MPI" in text or "OpenRTE" in text:
        return "openmpi"
    if "HYDRA" in text or "MPICH" in text or "Intel(R) MPI" in text:
        return "mpich"
    return "unknown"


@dataclass(frozen=True)
class Launcher:
    """One ``mpiexec`` and what it needs to start ``n`` ranks of multigpu."""

    path: str
    flavor: str
    args: tuple[str, ...] = ()
    env: dict = field(default_factory=dict)

    def command(self, n: int, argv: list[str], python: str | None = None,
                hosts: list[tuple[str, int]] | None = None, env: dict | None = None) -> list[str]:
        """The ``mpiexec`` command line for ``n`` ranks of ``multigpu ARGV``, on ``hosts``
        [(host, slots)] when given (``hosts.py``), else on this machine; ``env`` is the job's
        environment (default: ``environ()``)."""
        placing = self.placing(hosts, self.environ() if env is None else env) if hosts else ()
        return [self.path, *self.args, *placing, "-n", str(n),
                python or sys.executable, "-m", "mpi4py", "-m", "multigpu", *argv]

    def placing(self, hosts: list[tuple[str, int]], env: dict) -> list[str]:
        """Flags that place the ranks on ``hosts`` in order, started through the remote shell
        ``$MULTIGPU_RSH`` (default: the MPI's own, ssh). Open MPI is told to pass on the
        environment the ranks need (Hydra passes all of it by default)."""
        from multigpu.launcher.hosts import remote_shell, spec

        rsh = remote_shell(env)
        if self.flavor == "openmpi":
            names = {*self.env, *(k for k in env if k.startswith(("MULTIGPU_", "LP_NUM_THREADS")) or k == "XAUTHORITY")}
            forward = [a for k in sorted(names) for a in ("-x", k)]
            return ["--host", spec(hosts), *(("--mca", "plm_rsh_agent", rsh) if rsh else ()), *forward]
        return ["-hosts", spec(hosts), *(("-launcher", "ssh", "-launcher-exec", rsh) if rsh else ())]

    def environ(self, extra: dict | None = None) -> dict:
        """The environment for the job: ours, the launcher's needs, then ``extra`` (llvmpipe's
        threads per rank are each rank's choice, ``gpu.render.raster_threads``, unless set)."""
        base = dict(os.environ)
        for k, v in self.env.items():
            base.setdefault(k, v)
        return {**base, **(extra or {})}


def launcher_for(mpiexec: str) -> Launcher:
    kind = flavor(mpiexec)
    if kind != "openmpi":
        return Launcher(mpiexec, kind)
    env = {"MPI4PY_LIBMPI": OPENMPI_LIBMPI}
    if hasattr(os, "geteuid") and os.geteuid() == 0:  # Open MPI's documented opt-in for root
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    # Open MPI binds each rank to one core by default (up to 2 ranks): llvmpipe's rasterizer thread then
    # shares its rank's core and the two take turns (the dragon at 1 rank: 1.6x the wall time); MPICH does not
    return Launcher(mpiexec, kind, ("--oversubscribe", "--quiet", "--bind-to", "none"), env)


def find_launcher() -> Launcher:
    """The launcher to use (see the module doc)."""
    explicit = os.environ.get("MULTIGPU_MPIEXEC")
    if explicit:
        found = shutil.which(explicit)
        if not found:
            raise InputError(f"MULTIGPU_MPIEXEC={explicit}: not an executable")
        return launcher_for(found)
    here = Path(sys.executable).parent
    found = shutil.which("mpiexec", path=f"{here}{os.pathsep}{os.environ.get('PATH', '')}")
    if not found:
        raise InputError("mpiexec not found: install MPI (pip install mpich) or put mpiexec on PATH")
    return launcher_for(found)


def mpiexec() -> str:
    """Path of the ``mpiexec`` ``find_launcher`` picks."""
    return find_launcher().path


def openmpi_on_path() -> str | None:
    """An Open MPI ``mpiexec`` on this machine besides the default one, if any (for tests)."""
    dirs = os.environ.get("PATH", "").split(os.pathsep) + ["/usr/bin", "/usr/local/bin"]
    for name in ("mpiexec.openmpi", "mpiexec", "mpirun.openmpi"):
        for d in dirs:
            p = Path(d) / name
            if p.is_file() and os.access(p, os.X_OK) and flavor(str(p.resolve())) == "openmpi":
                return str(p)
    return None


def run_multigpu(n: int, args: list[str], timeout: float, env: dict | None = None, cwd=None,
                 merge_stderr: bool = False, launcher: Launcher | None = None,
                 hosts: list[tuple[str, int]] | None = None) -> subprocess.CompletedProcess:
    """``mpiexec -n n python -m mpi4py -m multigpu ARGS`` (on ``hosts`` when given), killed
    whole after ``timeout`` s."""
    launcher = launcher or find_launcher()
    job_env = launcher.environ(env)
    cmd = launcher.command(n, args, hosts=hosts, env=job_env)
    proc = subprocess.Popen(cmd, cwd=cwd, env=job_env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT if merge_stderr else subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        raise JobTimeout(f"mpiexec timed out after {timeout} s: {' '.join(cmd)}", out or "", err or "") from None
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err or "")


def hosts_from(flag: str, value: str, ranks: int) -> list[tuple[str, int]]:
    """The hosts of ``--hosts LIST`` or ``--hostfile FILE``, checked to hold ``ranks`` ranks."""
    from multigpu.launcher.hosts import parse_hosts, placement, read_hostfile

    hosts = parse_hosts(value) if flag == "--hosts" else read_hostfile(value)
    placement(hosts, ranks, f"{flag} {value}")
    return hosts


def wall_hosts(argv: list[str], ranks: int, hosts: list[tuple[str, int]] | None) -> list[tuple[str, int]] | None:
    """The hosts a walkthrough's ``--wall FILE`` names, where it names any (the one description
    of the installation: no other flag needed); with ``--hosts`` too, they must agree."""
    from multigpu.wall import check_ranks, hosts_of, load_wall

    path = flag_value(argv, "--wall") if argv and argv[0] == "walkthrough" else None
    if argv[:2] == ["wall", "test"] and len(argv) > 2:  # the calibration pattern: the file is its argument
        path = argv[2]
    if path is None:
        return hosts
    wall = load_wall(path)
    check_ranks(wall, ranks)
    named = hosts_of(wall, ranks)
    if not named:
        return hosts
    if hosts is not None and hosts != named:
        from multigpu.launcher.hosts import spec

        raise InputError.of("wall", f"{path} places the ranks on {spec(named)}, but --hosts/--hostfile says "
                         f"{spec(hosts)}: give one of them")
    return named


def help_only(argv: list[str]) -> bool:
    """Whether a command line only asks for help (nothing is started on the hosts)."""
    return any(a in ("-h", "--help") for a in argv)


def main(argv: list[str] | None = None) -> int:
    """``python -m multigpu.launcher.mpirun -n K [--hosts a:2,b:2 | --hostfile FILE] ARGS...``:
    run the right mpiexec for K ranks, on those hosts when given (``supervise``)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    usage = "usage: python -m multigpu.launcher.mpirun -n RANKS [--hosts H:N,... | --hostfile FILE] MULTIGPU_ARGS..."
    if len(argv) < 2 or argv[0] != "-n" or not argv[1].isdigit() or int(argv[1]) < 1:
        print(usage, file=sys.stderr)
        return exits.BAD_INPUT
    ranks, rest, hosts = int(argv[1]), argv[2:], None
    try:
        if rest and rest[0] in ("--hosts", "--hostfile"):
            if len(rest) < 2:
                raise InputError(f"{rest[0]} needs a value")
            hosts, rest = hosts_from(rest[0], rest[1], ranks), rest[2:]
        hosts = wall_hosts(rest, ranks, hosts)
        launcher = find_launcher()
        cmd = launcher.command(ranks, rest, hosts=hosts)
        bound = restart_bound(rest)
        if hosts and not help_only(rest):
            from multigpu.launcher.hosts import probe, remote_shell

            probe(hosts, remote_shell())
    except InputError as exc:
        print(f"multigpu: error: {exc}", file=sys.stderr)
        return exits.BAD_INPUT
    from multigpu.launcher import operator

    view = None
    try:
        on = None if help_only(rest) else operator.own_pc(rest)
        view = operator.start_view(on) if on else None  # the operator's view on a PC of its own
        operator.panel_token()  # the page's token outlives a restart of the wall
        if bound and not help_only(rest):
            from multigpu.launcher.relaunch import recovering

            return recovering(launcher, ranks, rest, hosts, bound)
        return supervise(cmd, launcher.environ(), out_dir(rest), Path(launcher.path).name)
    except InputError as exc:
        print(f"multigpu: error: {exc}", file=sys.stderr)
        return exits.BAD_INPUT
    finally:
        operator.stop_view(view)


def restart_bound(argv: list[str]) -> int:
    """The restarts a walkthrough's command line allows (``--recover``; by default 3 with
    ``--present window``, 0 headless: ``WalkConfig.recover``); 0 for other commands."""
    if not argv or argv[0] != "walkthrough":
        return 0
    from multigpu.config import default_recover

    value = flag_value(argv, "--recover")
    if value is None:
        return default_recover(flag_value(argv, "--present") or "headless")
    try:
        return max(0, int(value))
    except ValueError:
        return 0  # the walkthrough refuses it in one line


if __name__ == "__main__":
    sys.exit(main())
