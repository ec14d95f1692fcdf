"""A model in its own colours (materials, vertex colours and a texture; crease-angle normals) composes on
a 2x2 wall bit for bit as one rank renders it, for every decomposition and with render scale
and levels of detail, and across mullions (each job under a hard timeout)."""

import pytest
from mpirun import read_png, run_mpi
from test_looks import boxes_glb

from multigpu.core.canvas import Canvas

pytestmark = pytest.mark.mpi
FRAMES = 3
VARIANTS = {
    "screen": [],
    "cross": ["--balance", "cross"],
    "db": ["--decomposition", "db"],
    "hybrid": ["--decomposition", "hybrid"],
    "scale-lod": ["--render-scale", "0.5", "--lod-error", "2"],
}


def walk(out, model, grid, tile, extra=()):
    args = ["walkthrough", "--model", str(model), "--frames", str(FRAMES), "--grid", f"{grid[0]}x{grid[1]}",
            "--tile", f"{tile[0]}x{tile[1]}", "--mosaic-every", "1", "--no-overlay", "--no-progress",
            "--out", str(out), *extra]
    res = run_mpi(grid[0] * grid[1], args)
    assert res.returncode == 0, res.stderr[-3000:]
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(FRAMES)]


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return boxes_glb(tmp_path_factory.mktemp("looks") / "look.glb", textured=True)


@pytest.mark.parametrize("name", list(VARIANTS))
def test_a_coloured_model_composes_as_one_rank_renders_it(tmp_path, model, name):
    ref = walk(tmp_path / "ref", model, (1, 1), (96, 80), VARIANTS[name])
    got = walk(tmp_path / "wall", model, (2, 2), (48, 40), VARIANTS[name])
    for f, (g, w) in enumerate(zip(got, ref)):
        assert (g == w).all(), f"frame {f}: {(g != w).any(axis=2).sum()} pixels differ"
    colours = {tuple(p) for p in ref[0].reshape(-1, 3)}
    assert len(colours) > 50  # the model's colours and shading, not one flat colour


def test_a_coloured_model_composes_across_mullions(tmp_path, model):
    """With bezels: the canvas rendered by one rank, its mullion pixels black, is the wall's mosaic."""
    c = Canvas((2, 2), (48, 40), (6, 4))
    ref = [img.copy() for img in walk(tmp_path / "ref", model, (1, 1), c.size)]
    for img in ref:
        img[c.hidden()] = 0
    got = walk(tmp_path / "wall", model, (2, 2), (48, 40), ["--mullion", "6x4"])
    for f, (g, w) in enumerate(zip(got, ref)):
        assert g.shape == w.shape and (g == w).all(), f"frame {f}: {(g != w).any(axis=2).sum()} pixels differ"
