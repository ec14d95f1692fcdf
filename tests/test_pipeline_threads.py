"""The in-process oracle: the whole pipeline (setup, balancing, rendering, exchange, composing,
records) for K = 2 to 4 ranks as threads of this process (``threadcomm``), each rank with its
own GL context, composes bit for bit what one rank renders. It needs no ``mpiexec`` and starts
no MPI, so it belongs to the quick test loop; the ``_mpi`` tests remain the end-to-end check."""

import json
import sys
import threading

import numpy as np
import pytest
from mpirun import read_png
from threadcomm import run_ranks

from multigpu.config import WalkConfig
from multigpu.rank import walkthrough
from multigpu.scene.models import SceneSpec

FRAMES = 4
HELD = 10  # frames of the held-back runs: enough that a slot's frames differ where they collide
CASES = {  # name: (config fields, grids that run it)
    "screen": ({"balance": "strips"}, [(1, 2), (2, 2)]),
    "cross": ({"balance": "cross"}, [(1, 3), (2, 2)]),
    "db": ({"decomposition": "db"}, [(1, 2), (2, 2)]),
}


class _Job:
    """What the frame loop asks of the rank's job (``rank/job.py``): no heartbeats here."""

    signum = None
    in_frames = False
    thread_cpu = 0.0


def _walk(out, grid, tile, exchange_as="messages", frames=FRAMES, **fields) -> list[np.ndarray]:
    cfg = WalkConfig(scene=SceneSpec(triangles=20_000), frames=frames, grid=grid, tile=tile, mosaic_every=1,
                     overlay=False, progress=False, exchange=exchange_as, out=str(out), timeout=60.0, **fields)
    summaries = run_ranks(grid[0] * grid[1], lambda comm: walkthrough.run(cfg, comm, _Job()))
    assert summaries[0]["frames"] == frames and all(s is None for s in summaries[1:])  # rank 0's summary only
    assert json.loads((out / "summary.json").read_text())["frames_written"] == frames
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(frames)]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """One rank's frames of the 120x96 display (and of the 1x3 wall's 120x32)."""
    base = tmp_path_factory.mktemp("one")
    return {(120, 96): _walk(base / "a", (1, 1), (120, 96)), (120, 32): _walk(base / "b", (1, 1), (120, 32)),
            "held": _walk(base / "c", (1, 1), (120, 96), frames=HELD)}


@pytest.mark.parametrize("latency", [0, 1, 2])
@pytest.mark.parametrize("name,grid", [(n, g) for n, (_, grids) in CASES.items() for g in grids],
                         ids=lambda v: v if isinstance(v, str) else f"{v[0]}x{v[1]}")
def test_threads_compose_what_one_rank_renders(tmp_path, reference, name, grid, latency):
    tile = (120 // grid[1], (96 if grid[0] > 1 or name != "cross" else 32) // grid[0])
    got = _walk(tmp_path / name, grid, tile, latency=latency, **CASES[name][0])
    want = reference[(tile[0] * grid[1], tile[1] * grid[0])]
    for f, (a, b) in enumerate(zip(got, want)):
        assert a.shape == b.shape and (a == b).all(), f"frame {f}: {(a != b).any(axis=2).sum()} pixels differ"
    s = json.loads((tmp_path / name / "summary.json").read_text())
    assert s["config"]["exchange"] == "messages" and s["config"]["latency"] == latency
    assert "mpi4py.MPI" not in sys.modules  # nothing here started MPI (see test_exchange.py)


@pytest.fixture
def shared_in_memory(monkeypatch):
    """The shared-segment backend with the threads' memory as the host's segment: every rank
    one host, each its slice of ``slots`` slots, as ``frame_setup.make_exchange`` asks."""
    from multigpu.rank.shared import SharedPieces

    lock, memory = threading.Lock(), {}

    def make(comm, size, with_depth, timeout, asked=True, slots=2, layers=1):
        per_slot, K = SharedPieces.slot_bytes(size, with_depth, layers), comm.Get_size()
        with lock:
            host = memory.setdefault(id(comm.world), np.zeros(K * slots * per_slot, dtype=np.uint8))
        return SharedPieces.over(comm, timeout, host, {r: r for r in range(K)}, per_slot, with_depth, slots), None

    monkeypatch.setattr(SharedPieces, "make", staticmethod(make))


@pytest.mark.parametrize("latency", [0, 1, 2, 3])
@pytest.mark.parametrize("name", ["screen", "db"])
def test_a_held_back_rank_on_the_shared_segment_composes_one_ranks_render(tmp_path, reference, shared_in_memory,
                                                                         monkeypatch, name, latency):
    """The shared-segment backend at every latency, rank 1 held back in every frame before it
    reads its peers' parts (the others run ahead as far as the loop's waits allow): each mosaic
    is one rank's render bit for bit (at --latency 3 a ring of three slots let a peer overwrite a
    frame still being read)."""
    from multigpu.rank import fault, frames

    for module in (fault, frames):
        monkeypatch.setattr(module, "FAULT_SPEC", "1:compose:sleep=0.1")
    got = _walk(tmp_path / name, (2, 2), (60, 48), latency=latency, exchange_as="shared", frames=HELD,
                **CASES[name][0])
    for f, (a, b) in enumerate(zip(got, reference["held"])):
        assert (a == b).all(), f"frame {f}: {(a != b).any(axis=2).sum()} pixels differ"
    s = json.loads((tmp_path / name / "summary.json").read_text())
    assert s["config"]["exchange"] == "shared" and s["config"]["latency"] == latency


def test_a_timeline_that_cannot_be_written_fails_the_run(tmp_path):
    """``--timeline`` with timeline.json taken by a folder: every rank ends with the failed
    write (exit 2 at the door), where it once ended in success with no timeline."""
    from multigpu.errors import WriteFailed

    out = tmp_path / "o"
    (out / "timeline.json").mkdir(parents=True)
    with pytest.raises(WriteFailed, match="timeline.json"):
        _walk(out, (1, 2), (60, 96), timeline=True)
    s = json.loads((out / "summary.json").read_text())
    assert s["frames_written"] == FRAMES and s["frames"] == FRAMES


def test_a_models_warnings_reach_the_console_once(tmp_path, capsys):
    """An OBJ whose map_Kd names a missing image: the walkthrough says so once on the console
    (it ran silently, the warning only in summary.json)."""
    (tmp_path / "m.mtl").write_text("newmtl gone\nKd 0.5 0.1 0.1\nmap_Kd missing.png\n")
    (tmp_path / "m.obj").write_text("mtllib m.mtl\no a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\n"
                                    "vt 1 1\nvt 0 1\nusemtl gone\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    cfg = WalkConfig(scene=SceneSpec(model=str(tmp_path / "m.obj")), frames=2, grid=(1, 2), tile=(40, 40),
                     mosaic_every=0, progress=False, out=str(tmp_path / "o"), timeout=60.0, exchange="messages")
    run_ranks(2, lambda comm: walkthrough.run(cfg, comm, _Job()))
    warned = [ln for ln in capsys.readouterr().err.splitlines() if "missing.png" in ln]
    assert len(warned) == 1 and warned[0].startswith(f"multigpu: warning: {tmp_path / 'm.obj'}: "), warned
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert any("missing.png" in w for w in s["config"]["scene"]["warnings"])


def test_a_setup_that_fails_after_the_exchange_lets_it_go(tmp_path, monkeypatch):
    """``frame_setup.build``: a failure after the exchange backend is made (here the bounds'
    projection) releases it, so no host segment outlives a failed setup."""
    from multigpu.rank import frame_setup

    closed = []
    made = frame_setup.make_exchange

    def exchange(cfg, comm, planner, hosts):
        backend, why = made(cfg, comm, planner, hosts)
        monkeypatch.setattr(backend, "close", lambda collective=True: closed.append(collective), raising=False)
        return backend, why

    def projection(*args):
        raise RuntimeError("no projection")

    monkeypatch.setattr(frame_setup, "make_exchange", exchange)
    monkeypatch.setattr(frame_setup, "make_projection", projection)
    with pytest.raises(RuntimeError, match="no projection"):
        _walk(tmp_path / "o", (1, 1), (40, 40))
    assert closed == [False]


def test_a_wall_file_one_host_cannot_read_is_every_ranks_error(tmp_path, monkeypatch):
    """``tile_comm``: the wall file missing on one host (here rank 1's) is one InputError on every
    rank naming that host, agreed before any split (that host once skipped the split the others
    blocked in). The stand-in communicator has no Split: reaching it fails the test."""
    from multigpu import wall
    from multigpu.errors import InputError
    from multigpu.rank.tiles import tile_comm

    path = tmp_path / "wall.json"
    path.write_text(json.dumps({"grid": "1x2", "tile": "40x40", "displays": [
        {"rank": 0, "host": "a"}, {"rank": 1, "host": "a"}]}))
    load = wall.load_wall

    def on_host(p):
        if threading.current_thread().name == "rank-1":
            raise InputError(f"--wall: cannot read {p}: No such file or directory")
        return load(p)

    monkeypatch.setattr(wall, "load_wall", on_host)
    with pytest.raises(InputError) as err:
        run_ranks(2, lambda comm: tile_comm(comm, str(path)))
    assert str(err.value).startswith(f"--wall: cannot read {path}: No such file or directory (on host ")
    assert "rank 1; the wall file must be at the same path on every host" in str(err.value)
    monkeypatch.setattr(wall, "load_wall", load)
    got = run_ranks(2, lambda comm: tile_comm(comm, str(path)) is comm)  # read everywhere, no renumbering
    assert got == [True, True]


@pytest.mark.parametrize("latency", [0, 2])
@pytest.mark.parametrize("name", ["screen", "cross", "db", "hybrid"])
def test_compressed_messages_compose_one_ranks_render(tmp_path, reference, monkeypatch, name, latency):
    """Every message framed and compressed (``--compress zstd``, no piece too small for it): the
    composite is one rank's render bit for bit, and the messages took fewer bytes than the pixels."""
    from multigpu.core import wire

    monkeypatch.setattr(wire, "LEAST", 0)
    fields = {"hybrid": {"decomposition": "hybrid"}}.get(name, CASES.get(name, ({},))[0])
    got = _walk(tmp_path / name, (2, 2), (60, 48), latency=latency, compress="zstd", **fields)
    for f, (a, b) in enumerate(zip(got, reference[(120, 96)])):
        assert (a == b).all(), f"frame {f}: {(a != b).any(axis=2).sum()} pixels differ"
    s = json.loads((tmp_path / name / "summary.json").read_text())
    assert s["config"]["compress"] == "zstd:1 on every message"
    assert 0 < s["wire"]["bytes_per_frame"] < s["bytes_sent_per_frame"]
    assert s["wire"]["lossy_frames"] == 0


def test_a_lossy_wire_while_moving_is_marked_and_exact_once_the_camera_stops(tmp_path, reference, monkeypatch):
    """``--compress-moving 3``: frames whose camera moved drop three colour bits on the wire (marked
    in lossy_bits, each pixel within 4 of the exact one); a frame whose camera stopped is exact."""
    from multigpu.core import wire
    from multigpu.records.report import COLUMNS, read_timings

    monkeypatch.setattr(wire, "LEAST", 0)
    from dataclasses import asdict

    from multigpu.scene.models import load_scene
    from multigpu.scene.paths import walkthrough as walk_path

    walked = walk_path(load_scene(SceneSpec(triangles=20_000))[0], frames=40)
    cams = [asdict(walked.camera(f)) for f in (10, 20, 20, 20)]
    path = tmp_path / "path.json"
    path.write_text(json.dumps({"version": 1, "cameras": [{k: list(v) if isinstance(v, tuple) else v
                                                           for k, v in c.items()} for c in cams]}))
    one = _walk(tmp_path / "one", (1, 1), (120, 96), path=str(path))
    got = _walk(tmp_path / "lossy", (2, 2), (60, 48), path=str(path), compress="zstd", compress_moving=3)
    rows = read_timings(tmp_path / "lossy" / "timings.csv")
    bits = rows[:, COLUMNS.index("lossy_bits")].reshape(FRAMES, 4).max(axis=1)
    assert list(bits) == [0, 3, 0, 0]  # frame 1 moved; the first (moved from nothing), 2 and 3 stood still
    from multigpu.records.report import COMPONENTS, WAITED

    for c in COMPONENTS:  # a phase's wait is part of its own span (the input broadcast was once counted in)
        assert (rows[:, COLUMNS.index(WAITED[c])] <= rows[:, COLUMNS.index(c)] + 1e-6).all(), c
    diff = np.abs(got[1].astype(int) - one[1].astype(int))
    assert diff.max() <= 4 and (diff > 0).any()
    for f in (0, 2, 3):
        assert (got[f] == one[f]).all(), f"frame {f}: {(got[f] != one[f]).any(axis=2).sum()} pixels differ"
    s = json.loads((tmp_path / "lossy" / "summary.json").read_text())
    assert s["wire"]["lossy_frames"] == 1 and "3 colour bits dropped while moving" in s["config"]["compress"]
    _walk(tmp_path / "plain", (1, 2), (60, 48), path=str(path), compress="none", compress_moving=3)
    s = json.loads((tmp_path / "plain" / "summary.json").read_text())
    assert s["wire"]["lossy_frames"] == 0 and "dropped while moving" not in s["config"]["compress"]


@pytest.mark.parametrize("exchange_as,latency", [("messages", 0), ("messages", 2), ("shared", 1), ("shared", 3)])
def test_the_panel_switches_decomposition_mid_run_exactly(tmp_path, reference, shared_in_memory, monkeypatch,
                                                         exchange_as, latency):
    """The operator's page switches the strategy and the decomposition every other frame
    (screen, db, hybrid, bins, cross), pauses and changes nothing else: every rank switches at
    the same frame (the CSV's balance column), and every mosaic is one rank's render bit for bit,
    whatever backend and frames in flight. A shared segment has the room of the decomposition a
    run starts with, so those runs start as hybrid (the page offers only what fits)."""
    from multigpu.panel.protocol import Command
    from multigpu.rank.panel_link import PanelLink
    from multigpu.records.report import BALANCE_NAMES, COLUMNS, read_timings

    script = {0: [("balance", {"name": "strips"})], 2: [("balance", {"name": "db"})],
              4: [("balance", {"name": "hybrid"}), ("pause", {})],
              5: [("resume", {})], 7: [("balance", {"name": "bins"})], 9: [("balance", {"name": "cross"})]}
    calls = []  # the page's commands are read once a frame, and once a tick while paused (frame 4: twice)
    read = PanelLink.read

    def scripted(self):
        for do, args in script.get(len(calls), []):
            self.state.commands.put(Command(do, args))
        calls.append(1)
        read(self)

    monkeypatch.setattr(PanelLink, "read", scripted)
    # a shared segment has the room of the decomposition the run starts with: a hybrid's holds them all
    start = {"decomposition": "hybrid"} if exchange_as == "shared" else {}
    got = _walk(tmp_path / "p", (2, 2), (60, 48), latency=latency, exchange_as=exchange_as, frames=HELD,
                balance="strips", panel=("127.0.0.1", 0), bin_size=16, **start)
    for f, (a, b) in enumerate(zip(got, reference["held"])):
        assert (a == b).all(), f"frame {f}: {(a != b).any(axis=2).sum()} pixels differ"
    rows = read_timings(tmp_path / "p" / "timings.csv")
    balance = rows[:, COLUMNS.index("balance")].reshape(HELD, 4)
    assert (balance == balance[:, :1]).all()  # every rank the same at every frame
    names = [BALANCE_NAMES[int(b)] for b in balance[:, 0]]
    assert names == ["strips"] * 2 + ["db"] * 2 + ["hybrid"] * 2 + ["bins"] * 2 + ["cross"] * 2
    from multigpu.records.report import COMPONENTS, WAITED

    for c in COMPONENTS:  # defect 18: the input phase's wait (and a pause's) once counted in load balancing's
        assert (rows[:, COLUMNS.index(WAITED[c])] <= rows[:, COLUMNS.index(c)] + 1e-6).all(), c
