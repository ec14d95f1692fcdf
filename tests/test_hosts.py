"""Host placement without MPI: the host list and hostfile forms, their refusals, and the flags
each MPI's launcher gets for them."""

import os
import subprocess
import sys

import pytest
from mpirun import ROOT

from multigpu.errors import InputError
from multigpu.launcher.hosts import parse_hosts, placement, read_hostfile, spec
from multigpu.launcher.mpirun import Launcher


def test_host_lists_and_files_of_either_mpi_give_one_placement(tmp_path):
    assert parse_hosts("a:2,b:2") == [("a", 2), ("b", 2)]
    assert parse_hosts("node1,node2,node1") == [("node1", 2), ("node2", 1)]  # repeats add up, first place kept
    f = tmp_path / "hosts"
    f.write_text("# the wall's machines\nwall-a slots=2\n\nwall-b:1   # MPICH's form\nwall-c\n")
    hosts = read_hostfile(str(f))
    assert hosts == [("wall-a", 2), ("wall-b", 1), ("wall-c", 1)] and spec(hosts) == "wall-a:2,wall-b:1,wall-c:1"
    assert placement(hosts, 3) == ["wall-a", "wall-a", "wall-b"]
    assert placement(hosts, 4) == ["wall-a", "wall-a", "wall-b", "wall-c"]


@pytest.mark.parametrize("text, want", [("", "not a host list"), ("a:2,,b", "not a host list"),
                                        ("a:0", "whole number >= 1"), ("a:x", "whole number >= 1"),
                                        ("a b", "not a host"), ("a:2:3", "whole number")])
def test_bad_host_lists_are_refused_in_one_line(text, want):
    with pytest.raises(InputError, match=want) as exc:
        parse_hosts(text)
    assert "\n" not in str(exc.value) and "--hosts" in str(exc.value)


def test_bad_hostfiles_and_too_few_slots_name_the_file_and_line(tmp_path):
    with pytest.raises(InputError, match=r"--hostfile .*missing: cannot read it"):
        read_hostfile(str(tmp_path / "missing"))
    f = tmp_path / "hosts"
    f.write_text("# nothing\n")
    with pytest.raises(InputError, match="no hosts in it"):
        read_hostfile(str(f))
    f.write_text("a slots=2\nb slots=two\n")
    with pytest.raises(InputError, match="line 2"):
        read_hostfile(str(f))
    with pytest.raises(InputError, match="3 rank slots on 2 host.*needs 4 ranks"):
        placement([("a", 2), ("b", 1)], 4)


def test_each_mpi_gets_its_own_placement_flags(tmp_path):
    rsh = tmp_path / "rsh"
    rsh.write_text("#!/bin/sh\n")
    rsh.chmod(0o755)
    hosts = [("a", 2), ("b", 2)]
    mpich = Launcher("/x/mpiexec", "mpich").command(4, ["walkthrough"], hosts=hosts, env={"MULTIGPU_RSH": str(rsh)})
    assert mpich[1:7] == ["-hosts", "a:2,b:2", "-launcher", "ssh", "-launcher-exec", str(rsh)]
    assert Launcher("/x/mpiexec", "mpich").command(4, [], hosts=hosts, env={})[1:4] == ["-hosts", "a:2,b:2", "-n"]
    ompi = Launcher("/x/mpiexec", "openmpi", ("--oversubscribe",), {"MPI4PY_LIBMPI": "libmpi.so.40"})
    cmd = ompi.command(4, [], hosts=hosts, env={"MULTIGPU_RSH": str(rsh), "MULTIGPU_CACHE": "/c",
                                                "LP_NUM_THREADS": "2"})
    assert cmd[1:6] == ["--oversubscribe", "--host", "a:2,b:2", "--mca", "plm_rsh_agent"]
    for name in ("LP_NUM_THREADS", "MPI4PY_LIBMPI", "MULTIGPU_CACHE", "MULTIGPU_RSH"):
        assert cmd[cmd.index(name) - 1] == "-x"  # Open MPI passes on only what it is told to
    unset = ompi.command(4, [], hosts=hosts, env={"MULTIGPU_CACHE": "/c"})
    assert "LP_NUM_THREADS" not in unset  # unset: each rank chooses (gpu.render.raster_threads)
    with pytest.raises(InputError, match="MULTIGPU_RSH=no-such-shell: not an executable"):
        Launcher("/x/mpiexec", "mpich").command(4, [], hosts=hosts, env={"MULTIGPU_RSH": "no-such-shell"})


@pytest.mark.parametrize("argv, want", [(["--hosts", "a:1", "walkthrough"], "1 rank slots on 1 host(s), but the job"),
                                        (["--hostfile", "/no/such/file", "walkthrough"], "cannot read it"),
                                        (["--hosts"], "--hosts needs a value")])
def test_the_launcher_refuses_bad_placement_before_starting_anything(argv, want):
    res = subprocess.run([sys.executable, "-m", "multigpu.launcher.mpirun", "-n", "2", *argv],
                         capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and want in res.stderr, res.stderr


@pytest.mark.parametrize("host_ranks, cores, want", [(1, 2, "1"), (2, 2, "0"), (4, 2, "0"), (3, 16, "1"), (1, 1, "0")])
def test_llvmpipe_gets_a_raster_thread_only_where_a_core_is_spare(monkeypatch, host_ranks, cores, want):
    from multigpu.gpu.render import raster_threads

    monkeypatch.delenv("LP_NUM_THREADS", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(cores)), raising=False)
    assert raster_threads(host_ranks) == want == os.environ["LP_NUM_THREADS"]
    monkeypatch.setenv("LP_NUM_THREADS", "3")  # the user's setting wins
    assert raster_threads(host_ranks) == "3"


def test_a_remote_shell_that_fails_is_one_line_naming_host_and_shell(tmp_path, capsys, monkeypatch):
    """``MULTIGPU_RSH=/bin/false ... --hosts a:2,b:2``: refused before any rank starts, exit 2,
    one line naming the first host and the shell (not the MPI launcher's internal errors)."""
    from multigpu.launcher import mpirun

    monkeypatch.setenv("MULTIGPU_RSH", "/bin/false")
    code = mpirun.main(["-n", "4", "--hosts", "a:2,b:2", "walkthrough", "--grid", "2x2", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("multigpu: error: host a: the remote shell '/bin/false a true' failed (exit 1")
    assert not (tmp_path / "o").exists()


def test_the_probe_passes_hosts_that_answer_and_skips_this_machine(tmp_path):
    import socket

    from multigpu.errors import InputError
    from multigpu.launcher.hosts import is_this_machine, probe

    said = tmp_path / "said"
    shell = tmp_path / "rsh"
    shell.write_text(f"#!/bin/sh\necho \"$@\" >> {said}\n[ \"$1\" != slow ] || sleep 5\n")
    shell.chmod(0o755)
    assert is_this_machine("localhost") and is_this_machine(socket.gethostname())
    probe([("localhost", 2), ("far", 1)], str(shell))
    assert said.read_text().split("\n")[:-1] == ["far true"]  # this machine: a local fork, not the shell
    with pytest.raises(InputError, match=r"host slow: .* \(no answer within 0.5 s\)"):
        probe([("slow", 1)], str(shell), timeout=0.5)


def test_one_remote_shell_for_every_launcher_step():
    """``remote_shell``/``shell_command``: the ranks' launchers, the host checks, recovery and
    the operator's view all start a remote command the same way."""
    import shutil

    from multigpu.launcher.hosts import remote_shell, shell_command

    assert remote_shell({}) is None and remote_shell({"MULTIGPU_RSH": ""}) is None
    assert remote_shell({"MULTIGPU_RSH": "true"}) == shutil.which("true")
    with pytest.raises(InputError, match="MULTIGPU_RSH=no-such-shell: not an executable"):
        remote_shell({"MULTIGPU_RSH": "no-such-shell"})
    assert shell_command("/bin/rsh") == ["/bin/rsh"]
    assert shell_command(None) == ["ssh", "-o", "BatchMode=yes"]
    assert shell_command(None, 5) == ["ssh", "-o", "BatchMode=yes", "-o", "ConnectTimeout=5"]
