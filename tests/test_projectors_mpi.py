"""A three-projector blended wall, headless: the wall file names an MPCDI file (``warp make``'s),
and the run keeps each projector output's final picture beside its mosaics; those pictures are
the canvas warped and blended, and their simulated projection shows the canvas (each job under a
hard timeout)."""

import json

import numpy as np
import pytest
from mpirun import read_png, run_mpi

from multigpu.core.warpblend import decode, sample
from multigpu.records.outputs import OutputPictures
from multigpu.warp import mpcdi
from multigpu.warp.make import buffer_size, outputs
from multigpu.warp.rig import flat_rig

pytestmark = pytest.mark.mpi


def test_a_projector_wall_keeps_each_outputs_picture_and_projects_its_canvas(tmp_path):
    rig = flat_rig(3, 0.18, size=(96, 72))
    bw, bh = buffer_size(rig)
    mpcdi.write(tmp_path / "wall.mpcdi", (bw, bh), outputs(rig))
    wall = tmp_path / "wall.json"
    wall.write_text(json.dumps({"grid": "1x3", "tile": f"{-(-bw // 3)}x{bh}", "mpcdi": "wall.mpcdi"}))
    out = tmp_path / "out"
    res = run_mpi(3, ["walkthrough", "--wall", str(wall), "--frames", "2", "--mosaic-every", "1", "--no-overlay",
                      "--no-progress", "--out", str(out)])
    assert res.returncode == 0, res.stderr[-3000:]
    made = OutputPictures(str(tmp_path / "wall.mpcdi"))
    for f in range(2):
        canvas = read_png(out / "mosaic" / f"frame_{f:05d}.png")
        pictures = [read_png(out / "mosaic" / "outputs" / name / f"frame_{f:05d}.png") for name in ("p1", "p2", "p3")]
        for got, (name, want) in zip(pictures, made.pictures(canvas)):
            assert got.shape == (72, 96, 3) and np.array_equal(got, want), name
    # the simulated projection of the last frame's pictures against the canvas shown straight
    s, t = np.meshgrid(np.linspace(0.02, 0.98, 240), np.linspace(0.05, 0.95, 60))
    light = rig.light(pictures, s, t).mean(axis=-1)
    straight = rig.most() * rig.black + (1 - rig.black) * decode(sample(canvas, np.stack([s, t], -1))).mean(axis=-1)
    assert np.corrcoef(light.ravel(), straight.ravel())[0, 1] > 0.95
    # the overlaps neither dim nor brighten the picture (against where one projector alone shows it: the
    # resampling's own softening falls alike on both)
    n = rig.covering(rig.screen.point(s, t))
    ratio = [light[m].mean() / straight[m].mean() for m in (n == 2, n == 1)]
    assert abs(ratio[0] / ratio[1] - 1) < 0.03
