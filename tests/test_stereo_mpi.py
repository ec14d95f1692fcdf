"""Stereo under mpiexec (each job under a hard timeout, killed by process id): a 2x2 side-by-side
and anaglyph wall headless, each eye's mosaic one rank's render of that eye and the wall its
packing; and a stereo wall in windows on one X server (Xvfb), the screen showing the packed tiles
bit for bit (side by side), or each eye's window its eye's tile (passive)."""

import json

import numpy as np
import pytest
from mpirun import SMALL, read_png, run_mpi
from test_present_mpi import shown, still_path  # noqa: F401 (a fixture)
from test_stereo import _packed
from xserver import Xvfb

from multigpu.core.canvas import Canvas

pytestmark = pytest.mark.mpi
FRAMES = 3
STEREO = ["--screen-size", "1.2,0.96"]


def _walk(out, grid, tile, mode, extra=(), ranks=None):
    args = ["walkthrough", *SMALL, "--frames", str(FRAMES), "--grid", f"{grid[0]}x{grid[1]}",
            "--tile", f"{tile[0]}x{tile[1]}", "--mosaic-every", "1", "--no-overlay", "--out", str(out),
            "--stereo", mode, *STEREO, *extra]
    res = run_mpi(ranks or grid[0] * grid[1], args)
    assert res.returncode == 0, res.stderr[-3000:]
    return [[read_png(out / "mosaic" / f"{d}frame_{f:05d}.png") for d in ("", "left/", "right/")]
            for f in range(FRAMES)]


@pytest.mark.parametrize("mode,one,extra", [("side-by-side", (120, 96), ["--decomposition", "db"]),
                                            ("anaglyph", (120, 96), ["--eyes", "split"])])
def test_a_stereo_wall_under_mpiexec_composes_each_eye_bit_for_bit(tmp_path, mode, one, extra):
    want = _walk(tmp_path / "one", (1, 1), one, mode)
    got = _walk(tmp_path / "four", (2, 2), (60, 48), mode, extra)
    canvas = Canvas((2, 2), (60, 48))
    for f, (g, w) in enumerate(zip(got, want)):
        assert (g[1] == w[1]).all() and (g[2] == w[2]).all(), f"frame {f}: an eye differs from one rank's"
        assert (g[0] == _packed(w[1], w[2], canvas, mode)).all(), f"frame {f}: the packed wall differs"
    assert (got[0][1] != got[0][2]).any()  # the eyes see differently
    s = json.loads((tmp_path / "four" / "summary.json").read_text())
    assert s["config"]["stereo"] == mode and s["complete"]


def test_passive_stereo_with_a_rank_for_each_eye_composes_each_eye_bit_for_bit(tmp_path):
    """``--eyes own``: 2K ranks for K tiles, ranks 0..K-1 the left eyes', K..2K-1 the right eyes':
    each eye's mosaic is one rank's render of that eye, the wall the left eyes beside the right."""
    want = _walk(tmp_path / "one", (1, 1), (120, 48), "passive")
    got = _walk(tmp_path / "own", (1, 2), (60, 48), "passive", ["--eyes", "own"], ranks=4)
    for f, (g, w) in enumerate(zip(got, want)):
        assert (g[1] == w[1]).all() and (g[2] == w[2]).all(), f"frame {f}: an eye differs from one rank's"
        assert (g[0] == np.concatenate([w[1], w[2]], axis=1)).all(), f"frame {f}: the wall differs"
    assert (got[0][1] != got[0][2]).any()  # the eyes see differently
    s = json.loads((tmp_path / "own" / "summary.json").read_text())
    assert s["config"]["eyes"] == "own" and len(s["config"]["ranks"]) == 4 and s["complete"]
    res = run_mpi(2, ["walkthrough", *SMALL, "--frames", "1", "--grid", "1x2", "--tile", "60x48", "--stereo",
                      "passive", "--eyes", "own", *STEREO, "--out", str(tmp_path / "two")])
    assert res.returncode == 2 and "1x2 needs 4 ranks (a rank for each eye of each tile: --eyes own) but the job " \
        "has 2" in res.stderr, res.stderr[-2000:]


def test_a_rank_for_each_eye_shows_its_eye_in_a_window_of_its_own(tmp_path, still_path):  # noqa: F811
    """``--eyes own`` in windows: four windows for a 1x2 wall, the right eyes' beside the left
    eyes' on one screen, as the mosaic shows them."""
    out = tmp_path / "win"
    args = ["walkthrough", *SMALL, "--path", str(still_path), "--grid", "1x2", "--tile", "60x48",
            "--mosaic-every", "100", "--no-overlay", "--present", "window", "--out", str(out),
            "--stereo", "passive", "--eyes", "own", *STEREO]
    with Xvfb((240, 48)) as x:
        shot, code, err = shown(4, args, x, 4, out)
    assert code == 0, err[-2000:]
    mosaic = read_png(out / "mosaic" / "frame_00000.png")
    assert shot.shape == mosaic.shape == (48, 240, 3)
    assert (shot == mosaic).all(), f"{(shot != mosaic).any(axis=2).sum()} screen pixels differ from the wall"
    left, right = (read_png(out / "mosaic" / d / "frame_00000.png") for d in ("left", "right"))
    assert (mosaic == np.concatenate([left, right], axis=1)).all() and (left != right).any()


@pytest.mark.parametrize("mode", ["side-by-side", "passive"])
def test_a_stereo_wall_in_windows_shows_the_packed_tiles(tmp_path, still_path, mode):  # noqa: F811
    """Side by side: each tile's window its packed tile. Passive: a window per eye, the right eyes'
    beside the left eyes' on one screen, as the mosaic shows them."""
    outputs = 2 if mode == "passive" else 1
    out = tmp_path / "win"
    args = ["walkthrough", *SMALL, "--path", str(still_path), "--grid", "2x2", "--tile", "60x48",
            "--mosaic-every", "100", "--no-overlay", "--present", "window", "--out", str(out),
            "--stereo", mode, *STEREO]
    with Xvfb((120 * outputs, 96)) as x:
        shot, code, err = shown(4, args, x, 4 * outputs, out)
    assert code == 0, err[-2000:]
    mosaic = read_png(out / "mosaic" / "frame_00000.png")
    assert shot.shape == mosaic.shape == (96, 120 * outputs, 3)
    assert (shot == mosaic).all(), f"{(shot != mosaic).any(axis=2).sum()} screen pixels differ from the packed wall"
    left, right = (read_png(out / "mosaic" / d / "frame_00000.png") for d in ("left", "right"))
    assert (mosaic == _packed(left, right, Canvas((2, 2), (60, 48)), mode)).all()
    assert np.count_nonzero((left != right).any(axis=2)) > 50
