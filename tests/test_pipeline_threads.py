"""The in-process oracle: the whole pipeline (setup, balancing, rendering, exchange, composing,
records) for K = 2 to 4 ranks as threads of this process (``threadcomm``), each rank with its
own GL context, composes bit for bit what one rank renders. It needs no ``mpiexec`` and starts
no MPI, so it belongs to the quick test loop; the ``_mpi`` tests remain the end-to-end check."""

import json
import sys

import numpy as np
import pytest
from mpirun import read_png
from threadcomm import run_ranks

from multigpu.config import WalkConfig
from multigpu.parallel import walkthrough
from multigpu.scene.models import SceneSpec

FRAMES = 4
CASES = {  # name: (config fields, grids that run it)
    "screen": ({"balance": "strips"}, [(1, 2), (2, 2)]),
    "cross": ({"balance": "cross"}, [(1, 3), (2, 2)]),
    "db": ({"decomposition": "db"}, [(1, 2), (2, 2)]),
}


class _Job:
    """What the frame loop asks of the rank's job (``parallel/job.py``): no heartbeats here."""

    signum = None
    in_frames = False
    thread_cpu = 0.0


def _walk(out, grid, tile, **fields) -> list[np.ndarray]:
    cfg = WalkConfig(scene=SceneSpec(triangles=20_000), frames=FRAMES, grid=grid, tile=tile, mosaic_every=1,
                     overlay=False, progress=False, exchange="messages", out=str(out), timeout=60.0, **fields)
    summaries = run_ranks(grid[0] * grid[1], lambda comm: walkthrough.run(cfg, comm, _Job()))
    assert summaries[0]["frames"] == FRAMES and all(s is None for s in summaries[1:])  # rank 0's summary only
    assert json.loads((out / "summary.json").read_text())["frames_written"] == FRAMES
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(FRAMES)]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """One rank's frames of the 120x96 display (and of the 1x3 wall's 120x32)."""
    base = tmp_path_factory.mktemp("one")
    return {(120, 96): _walk(base / "a", (1, 1), (120, 96)), (120, 32): _walk(base / "b", (1, 1), (120, 32))}


@pytest.mark.parametrize("latency", [0, 1])
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
