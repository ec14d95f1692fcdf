"""Depth complexity / overdraw counting on the GL side (EGL, one process)."""

import numpy as np

from multigpu.gpu.depth import harmonic, measure, summarize
from multigpu.gpu.render import create_context
from multigpu.scene.layout import assemble


def stacked_quads(depths):
    """Full-screen quads at the given NDC depths, drawn in list order."""
    n = len(depths)
    pos = np.zeros((n, 4, 3))
    pos[:, :, 0] = [-1, 1, 1, -1]
    pos[:, :, 1] = [-1, -1, 1, 1]
    pos[:, :, 2] = np.asarray(depths)[:, None]
    nrm = np.zeros_like(pos)
    nrm[..., 2] = 1
    return assemble([(pos, nrm, np.array([0, 1, 2, 0, 2, 3]), np.full((n, 3), 0.5))], "quads", {})


def test_harmonic():
    np.testing.assert_allclose(harmonic(np.array([0, 1, 2, 3])), [0, 1, 1.5, 1 + 1 / 2 + 1 / 3])


def test_counts_back_to_front_and_front_to_back():
    ctx, _ = create_context()
    # the draw order is the Morton order of the centres (here: by z), so all three quads are
    # drawn either near-to-far (o = 1) or far-to-near (o = 3), never a mix
    scene = stacked_quads([-0.5, 0.0, 0.5])
    d, o = measure(ctx, scene, np.eye(4), (16, 16))
    assert (d == 3).all()
    assert (o == 1).all() or (o == 3).all()  # one order or the other, never partial
    s = summarize(d, o)
    assert s["mean_d"] == 3 and s["covered_pixels"] == 256
    assert abs(s["model_o"] - (1 + 1 / 2 + 1 / 3)) < 1e-12
