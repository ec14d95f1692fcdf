"""Sub-object culling under mpiexec (each job under a hard timeout): a scanned mesh of a few
large objects, each cut into many parts, composes bit for bit what one rank renders, with and
without mullions, and every rank draws fewer triangles than the whole objects it was given."""

import csv
import json

import numpy as np
import pytest
from mpirun import read_png, run_mpi

from multigpu.core.canvas import Canvas

pytestmark = pytest.mark.mpi
FRAMES = 3


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    import subprocess
    import sys

    path = tmp_path_factory.mktemp("scan") / "scan.ply"
    subprocess.run([sys.executable, "-m", "multigpu", "scene", "scan", str(path), "--triangles", "30000"],
                   check=True, capture_output=True, timeout=120)
    return ["--model", str(path), "--split", "grid:2", "--cluster", "0", "--path-kind", "orbit", "--no-progress"]


def walk(out, scan, grid, tile, mullion=(0, 0), extra=()):
    args = ["walkthrough", *scan, "--frames", str(FRAMES), "--grid", f"{grid[0]}x{grid[1]}",
            "--tile", f"{tile[0]}x{tile[1]}", "--mullion", f"{mullion[0]}x{mullion[1]}", "--mosaic-every", "1",
            "--no-overlay", "--out", str(out), *extra]
    res = run_mpi(grid[0] * grid[1], args)
    assert res.returncode == 0, res.stderr[-3000:]
    return out


@pytest.mark.parametrize("grid,tile,mullion,extra", [
    ((2, 2), (60, 48), (0, 0), ()), ((1, 3), (40, 96), (11, 0), ()), ((2, 2), (60, 48), (7, 5), ("--balance", "cross")),
    ((2, 2), (60, 48), (0, 0), ("--decomposition", "db"))], ids=["2x2", "1x3-mullions", "2x2-mullions-cross", "db"])
def test_culled_walls_equal_one_rank_and_draw_less(tmp_path, scan, grid, tile, mullion, extra):
    c = Canvas(grid, tile, mullion)
    ref = walk(tmp_path / "ref", scan, (1, 1), c.size)
    out = walk(tmp_path / "wall", scan, grid, tile, mullion, extra)
    for f in range(FRAMES):
        want = read_png(ref / "mosaic" / f"frame_{f:05d}.png").copy()
        want[c.hidden()] = 0
        got = read_png(out / "mosaic" / f"frame_{f:05d}.png")
        assert (got == want).all(), f"frame {f}: {(got != want).any(axis=2).sum()} pixels differ"
    with open(out / "timings.csv") as fh:
        rows = list(csv.DictReader(fh))
    drawn = np.array([int(r["triangles"]) for r in rows])
    planned = np.array([int(r["planned_triangles"]) for r in rows])
    assert (drawn <= planned).all()  # never more than the whole objects
    if "db" not in extra:  # sort-first regions cut the objects: parts culled (db's rects hold theirs whole)
        assert drawn.sum() < planned.sum()
    if "db" not in extra:  # the cull of those parts took time, and the summary's figure is the CSV's mean
        culling = [float(r["culling_cpu_ms"]) for r in rows]
        assert max(culling) > 0
        s = json.loads((out / "summary.json").read_text())
        assert s["cpu"]["culling_cpu_ms"] == pytest.approx(np.mean(culling), abs=1e-4)
