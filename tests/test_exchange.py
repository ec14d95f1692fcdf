"""The shared-segment exchange in one process: K ranks' slices as plain arrays, so the layout
of published parts (only what peers need, in ``transfers`` order) and the compose that reads it
are checked without MPI; ``room``, the check made before making a segment; and ``reserve`` and
``attach``, which make and map it."""

import os
import subprocess
import sys

import numpy as np
import pytest
from threadcomm import World

from multigpu.core.work import Work, transfers
from multigpu.rank.composite import Messages
from multigpu.rank.shared import SharedPieces, attach, reserve, room


def _cuts(n: int, size: int, rng) -> list[int]:
    return [0, *sorted(rng.choice(np.arange(1, size), n - 1, replace=False).tolist()), size]


@pytest.mark.parametrize("backend", ["shared", "messages"])
@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("with_depth", [False, True])
def test_every_tile_composes_from_own_and_published_parts(seed, with_depth, backend):
    """Random pieces on a 2x2 wall (colour: a rank's pieces are cells of a random grid; depth:
    overlapping rects): every rank's tile equals the tile painted straight from every piece,
    each rank's three calls (start, wait, finish) made in turn: a shared segment's parts, or
    messages (``threadcomm``, one thread)."""
    rng = np.random.default_rng(seed)
    W, H, K = 64, 48, 4
    tiles = np.array([[0, 0, 32, 24], [32, 0, 64, 24], [0, 24, 32, 48], [32, 24, 64, 48]])
    if with_depth:
        rects = []
        for _ in range(K):
            x0, y0 = int(rng.integers(0, W - 1)), int(rng.integers(0, H - 1))
            rects.append(np.array([[x0, y0, int(rng.integers(x0 + 1, W + 1)), int(rng.integers(y0 + 1, H + 1))]]))
    else:
        xs, ys = _cuts(4, W, rng), _cuts(3, H, rng)
        cells = [[xs[i], ys[j], xs[i + 1], ys[j + 1]] for i in range(4) for j in range(3)]
        owner = rng.integers(0, K, len(cells))
        rects = [np.array([c for c, o in zip(cells, owner) if o == k], dtype=np.int64).reshape(-1, 4)
                 for k in range(K)]
    work = Work(tuple(rects), tuple(np.ones((len(r), 1), bool) for r in rects), np.zeros(K, np.int64), with_depth)
    plan = transfers(work, tiles)
    rendered = [[(rng.integers(0, 256, (r[3] - r[1], r[2] - r[0], 3), dtype=np.uint8),
                  rng.random((r[3] - r[1], r[2] - r[0]), dtype=np.float32) if with_depth else None) for r in rs]
                for rs in rects]
    per_half = W * H * (7 if with_depth else 3)
    segments = [np.zeros(2 * per_half, np.uint8) for _ in range(K)]
    comms = World(K).comms()
    ranks = [SharedPieces(comms[k], 1.0, dict(enumerate(segments)), per_half, with_depth) if backend == "shared"
             else Messages(comms[k], 1.0) for k in range(K)]
    frame = 3
    started = [ranks[k].start(frame, k, work.rects, rendered[k], plan, with_depth) for k in range(K)]
    for k in range(K):
        ranks[k].wait(started[k])
    # straight from every piece: ascending rank, nearer replaces (ties keep the lower rank)
    want = np.zeros((H, W, 3), np.uint8)
    wantz = np.ones((H, W), np.float32)
    for k in range(K):
        for (x0, y0, x1, y1), (rgb, z) in zip(rects[k], rendered[k]):
            if with_depth:
                near = z < wantz[y0:y1, x0:x1]
                want[y0:y1, x0:x1][near] = rgb[near]
                wantz[y0:y1, x0:x1][near] = z[near]
            else:
                want[y0:y1, x0:x1] = rgb
    read = 0
    for k in range(K):
        x0, y0, x1, y1 = tiles[k]
        color = np.zeros((y1 - y0, x1 - x0, 3), np.uint8)
        depth = np.ones((y1 - y0, x1 - x0), np.float32) if with_depth else None
        sent, zbytes = ranks[k].finish(started[k], tiles[k], color, depth)[:2]
        assert (color == want[y0:y1, x0:x1]).all()
        away = sum(p.pixels for p in plan if p.sender == k and p.receiver != k)
        assert sent == away * (7 if with_depth else 3) and zbytes == (4 * away if with_depth else 0)
        read += away
    assert read == sum(p.pixels for p in plan if p.sender != p.receiver)
    assert not segments[0][:per_half].any()  # frame 3 wrote the second half only
    assert segments[0][per_half:].any() == (backend == "shared")
    # one host sends no messages, so nothing here started MPI: an Open MPI singleton in the test
    # process would put its environment into every job a later test launches (they then fail)
    assert "mpi4py.MPI" not in sys.modules


def test_room_sees_the_file_size_limit_and_free_space():
    assert room(1) is None
    huge = 1 << 62
    got = room(huge)
    assert got is not None and ("/dev/shm" in got or "file-size limit" in got)
    code = ("import resource; resource.setrlimit(resource.RLIMIT_FSIZE, (20000, 20000)); "
            "from multigpu.rank.shared import room; print(room(30000)); print(room(10000))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout.split("\n")
    assert "file-size limit (20000 bytes)" in out[0] and "30000-byte segment" in out[0] and out[1] == "None"


def test_reserve_makes_a_file_two_mappings_share_and_fails_cleanly(tmp_path):
    """``reserve`` makes the segment whole (its blocks allocated, not a sparse file), two
    ``attach`` mappings see each other's stores after the name is gone, and a segment the
    system refuses (a file-size limit, a missing directory) gives the reason and leaves no file."""
    path, why = reserve(1 << 20, str(tmp_path))
    assert why is None and os.path.getsize(path) == 1 << 20
    assert os.stat(path).st_blocks * 512 >= 1 << 20  # reserved now: no SIGBUS at a page touched later
    a, b = attach(path, 1 << 20), attach(path, 1 << 20)
    os.unlink(path)
    a[12345:12348] = (7, 8, 9)
    assert b.flags.writeable and b[12345:12348].tolist() == [7, 8, 9]
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_FSIZE, (20000, 20000)); "
            "from multigpu.rank.shared import reserve; print(reserve(30000, sys.argv[1])[1])")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == f"cannot reserve 30000 bytes in {tmp_path}: File too large", out.stderr
    assert not list(tmp_path.iterdir())
    path, why = reserve(4096, str(tmp_path / "missing"))
    assert path == "" and why == f"cannot create a segment in {tmp_path / 'missing'}: No such file or directory"


@pytest.mark.mpi
def test_exchange_bench_runs_both_backends(egl):
    """``bench exchange --quick``: every (scene, balance) with both backends; ``none`` keeps
    every tile at home, so it sends nothing either way, while ``cross`` sends pieces."""
    from multigpu.studies.exchange_bench import bench_exchange

    rows = bench_exchange(quick=True)
    assert [(r["scene"], r["balance"], r["exchange"]) for r in rows] == [
        (s, b, x) for s in ("city", "plant") for b in ("cross", "none") for x in ("messages", "shared")]
    for r in rows:
        assert r["emulated_ms"] > 0 and r["wall_ms"] >= r["exchange_ms"] > 0 and r["exchange_cpu_ms"] > 0
        assert (r["bytes_sent"] == 0) == (r["balance"] == "none"), r


def test_a_jobs_checks_watch_its_own_threads_waits_only():
    """``exchange.watch``: a job's check runs in the bounded waits of the thread that set it
    (ranks as threads each have their own), and ``unwatch`` ends it."""
    import threading

    from multigpu.rank.exchange import PeerTimeout, unwatch, wait_all, watch

    class Never:
        @classmethod
        def Testall(cls, requests):  # noqa: N802
            return False

    class Stop(Exception):
        pass

    def check():
        raise Stop

    token = watch(check)
    with pytest.raises(Stop):
        wait_all([Never()], 5.0, "test")
    other = []

    def elsewhere():
        try:
            wait_all([Never()], 0.05, "test")
        except Exception as exc:  # noqa: BLE001
            other.append(type(exc))

    t = threading.Thread(target=elsewhere)
    t.start()
    t.join()
    assert other == [PeerTimeout]  # not this thread's check
    unwatch(token)
    with pytest.raises(PeerTimeout):
        wait_all([Never()], 0.05, "test")
