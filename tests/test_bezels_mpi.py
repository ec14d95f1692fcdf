"""Bezels under mpiexec (each job under a hard timeout): walls with mullions compose bit-exactly
to a one-rank render of the whole canvas with the mullion pixels blacked out, for every
decomposition, at 2x2 and 1x3; the mullion pixels are never rendered."""

import csv

import pytest
from mpirun import SMALL, read_png, run_mpi

from multigpu.core.canvas import Canvas

pytestmark = pytest.mark.mpi
FRAMES = 3
WALLS = {"2x2": ((2, 2), (60, 48), (7, 5)), "1x3": ((1, 3), (40, 96), (11, 0))}
KINDS = {"cross": ["--balance", "cross"], "strips": ["--balance", "strips"], "db": ["--decomposition", "db"],
         "bins": ["--decomposition", "bins", "--bin-size", "16"], "hybrid": ["--decomposition", "hybrid"]}


def walk(out, grid, tile, mullion=None, extra=()):
    args = ["walkthrough", *SMALL, "--frames", str(FRAMES), "--grid", f"{grid[0]}x{grid[1]}",
            "--tile", f"{tile[0]}x{tile[1]}", "--mosaic-every", "1", "--no-overlay", "--out", str(out), *extra]
    if mullion:
        args += ["--mullion", f"{mullion[0]}x{mullion[1]}"]
    res = run_mpi(grid[0] * grid[1], args)
    assert res.returncode == 0, res.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def references(tmp_path_factory):
    base = tmp_path_factory.mktemp("canvas")
    refs = {}
    for name, (grid, tile, mullion) in WALLS.items():
        c = Canvas(grid, tile, mullion)
        out = walk(base / name, (1, 1), c.size)
        imgs = [read_png(out / "mosaic" / f"frame_{f:05d}.png").copy() for f in range(FRAMES)]
        for img in imgs:
            img[c.hidden()] = 0
        refs[name] = imgs
    return refs


@pytest.mark.parametrize("kind", list(KINDS))
@pytest.mark.parametrize("wall", list(WALLS))
def test_bezel_walls_equal_the_canvas_render_with_mullions_black(tmp_path, references, wall, kind):
    grid, tile, mullion = WALLS[wall]
    out = walk(tmp_path / "w", grid, tile, mullion, KINDS[kind])
    for f in range(FRAMES):
        got = read_png(out / "mosaic" / f"frame_{f:05d}.png")
        want = references[wall][f]
        assert got.shape == want.shape and (got == want).all(), f"frame {f}: {(got != want).any(axis=2).sum()} px"
    c = Canvas(grid, tile, mullion)
    hidden = c.hidden()[::-1]  # bottom row first, as the rows' pixel rects
    with open(out / "timings.csv") as fh:
        for r in csv.DictReader(fh):  # every rank's render box stays on visible pixels at its corners
            x0, y0, x1, y1 = (int(r[k]) for k in ("x0", "y0", "x1", "y1"))
            if x1 > x0 and kind in ("cross", "strips"):
                assert not hidden[y0, x0] and not hidden[y1 - 1, x1 - 1]
            assert float(r["swap_skew_ms"]) == 0.0 and float(r["swap_ms"]) == 0.0  # headless: nothing swaps
