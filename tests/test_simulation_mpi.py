"""A simulation's mesh (a VTU of hexahedra) coloured by a point or a cell field composes on a 2x2
wall bit for bit as one rank renders it, for screen, db and hybrid (each job under a hard
timeout)."""

import meshio
import numpy as np
import pytest
from mpirun import read_png, run_mpi
from test_simulation import hex_block

pytestmark = pytest.mark.mpi
FRAMES = 3
CASES = {"point field, screen": ("velocity", []), "cell field, db": ("pressure", ["--decomposition", "db"]),
         "component, hybrid": ("velocity:y", ["--decomposition", "hybrid", "--colormap", "coolwarm"])}


def walk(out, model, grid, tile, extra):
    args = ["walkthrough", "--model", str(model), "--frames", str(FRAMES), "--grid", f"{grid[0]}x{grid[1]}",
            "--tile", f"{tile[0]}x{tile[1]}", "--mosaic-every", "1", "--no-overlay", "--no-progress",
            "--path-kind", "orbit", "--out", str(out), *extra]
    res = run_mpi(grid[0] * grid[1], args)
    assert res.returncode == 0, res.stderr[-3000:]
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(FRAMES)]


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("simulation") / "block.vtu"
    meshio.write(path, hex_block(8))
    return path


@pytest.mark.parametrize("name", list(CASES))
def test_a_coloured_simulation_composes_as_one_rank_renders_it(tmp_path, model, name):
    field, extra = CASES[name]
    flags = ["--color-by", field, *extra]
    ref = walk(tmp_path / "ref", model, (1, 1), (96, 80), flags)
    got = walk(tmp_path / "wall", model, (2, 2), (48, 40), flags)
    for f, (g, w) in enumerate(zip(got, ref)):
        assert (g == w).all(), f"frame {f}: {(g != w).any(axis=2).sum()} pixels differ"
    colours = {tuple(p) for p in ref[0].reshape(-1, 3)}
    assert len(colours) > 20  # the field's colours, shaded
    assert np.ptp(ref[0].reshape(-1, 3).astype(int), axis=0).max() > 100


def test_the_colour_bar_on_the_wall_composes_as_one_rank_shows_it(tmp_path, model):
    from multigpu.display.colorbar import MARGIN, color_bar
    from multigpu.scene.simulation import lookup

    flags = ["--color-by", "pressure", "--color-bar"]
    ref = walk(tmp_path / "ref", model, (1, 1), (240, 160), flags)
    got = walk(tmp_path / "wall", model, (2, 2), (120, 80), flags)
    for f, (g, w) in enumerate(zip(got, ref)):
        assert (g == w).all(), f"frame {f}: {(g != w).any(axis=2).sum()} pixels differ"
    legend = {"field": "pressure", "where": "cell", "range": [0.0, 511.0], "colormap": "viridis"}
    bar = color_bar(legend, lookup("viridis"))
    h, w = bar.shape[:2]
    assert np.array_equal(ref[0][160 - MARGIN - h:160 - MARGIN, MARGIN:MARGIN + w], bar)
