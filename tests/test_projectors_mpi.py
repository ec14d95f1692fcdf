"""A three-projector blended wall driven by three ranks: the wall file names an MPCDI file
(``warp make``'s), each rank's tile is its projector's region of the canvas (neighbours
overlap), the composed canvas equals one rank's render of it bit for bit (screen, db, hybrid),
each rank's picture (warped, blended, coloured on its GPU) is the numpy reference's within the
GPU's filtering, their simulated projection shows the canvas, and the windows on an X server
show those pictures at their places (each job under a hard timeout)."""

import json

import numpy as np
import pytest
from mpirun import SMALL, read_png, run_mpi, start_mpi
from projected import reference
from xserver import Xvfb, escape, screenshot, wait_for, windows

from multigpu.core.warpblend import decode, sample
from multigpu.warp import mpcdi
from multigpu.warp.make import buffer_size, outputs
from multigpu.warp.rig import flat_rig

pytestmark = pytest.mark.mpi
RIG = flat_rig(3, 0.18, size=(96, 72))
NAMES = ("p1", "p2", "p3")


@pytest.fixture(scope="module")
def wall(tmp_path_factory):
    """The rig's MPCDI file and a wall file naming it; and one rank's render of its canvas."""
    d = tmp_path_factory.mktemp("projectors")
    bw, bh = buffer_size(RIG)
    mpcdi.write(d / "wall.mpcdi", (bw, bh), outputs(RIG, (bw, bh)))
    (d / "wall.json").write_text(json.dumps({"mpcdi": "wall.mpcdi"}))
    one = d / "one"
    res = run_mpi(1, ["walkthrough", *SMALL, "--grid", "1x1", "--tile", f"{bw}x{bh}", "--frames", "2",
                      "--mosaic-every", "1", "--no-overlay", "--out", str(one)])
    assert res.returncode == 0, res.stderr[-3000:]
    return d


def still_path(where):
    """A path file of the walkthrough's 41st camera, held for 600 frames (what a window shows is
    then what the run recorded)."""
    import subprocess
    import sys

    from mpirun import ROOT

    path = where / "walk.json"
    subprocess.run([sys.executable, "-m", "multigpu", "path", "make", "walkthrough", *SMALL[:2], "--frames", "60",
                    "--out", str(path)], cwd=ROOT, check=True, capture_output=True, timeout=120)
    doc = json.loads(path.read_text())
    doc["cameras"] = [doc["cameras"][40]] * 600
    path.write_text(json.dumps(doc))
    return path


def in_windows(ranks: int, wall_file, path, screen: tuple[int, int], out, last: str) -> tuple:
    """``ranks`` ranks of the wall file in windows on an X server of ``screen`` pixels, until every
    window is up and output ``last`` has a picture on disk: (the screen, exit code, stderr)."""
    with Xvfb(screen) as x:
        proc, kill = start_mpi(ranks, ["walkthrough", *SMALL, "--wall", str(wall_file), "--path", str(path),
                                       "--mosaic-every", "100", "--no-overlay", "--present", "window", "--out",
                                       str(out)], env={"DISPLAY": x.name})
        try:
            wait_for(lambda: len(windows(x.name)) == ranks and (out / "mosaic" / "outputs" / last).is_dir())
            shot = screenshot(x.name)
            escape(x.name, windows(x.name)[0])
            _, err = proc.communicate(timeout=120)
        finally:
            kill() if proc.poll() is None else None
    return shot, proc.returncode, err


def close_to(got: np.ndarray, want: np.ndarray, name: str) -> None:
    """The GPU's pass against the numpy reference: its bilinear weights are 8-bit (a level or two)."""
    d = np.abs(got.astype(int) - want)
    assert got.shape == want.shape and d.max() <= 2 and d.mean() < 0.5, (name, d.max(), d.mean())


@pytest.mark.parametrize("decomposition", ["screen", "db", "hybrid"])
def test_a_projector_wall_composes_its_overlaps_exactly_and_keeps_each_outputs_picture(wall, tmp_path, decomposition):
    out = tmp_path / "out"
    res = run_mpi(3, ["walkthrough", *SMALL, "--wall", str(wall / "wall.json"), "--frames", "2", "--mosaic-every",
                      "1", "--no-overlay", "--decomposition", decomposition, "--out", str(out)])
    assert res.returncode == 0, res.stderr[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["config"]["grid"] == [1, 3] and s["config"]["tile"][1] == buffer_size(RIG)[1]
    for f in range(2):
        canvas = read_png(out / "mosaic" / f"frame_{f:05d}.png")
        assert np.array_equal(canvas, read_png(wall / "one" / "mosaic" / f"frame_{f:05d}.png")), f
        want = reference(canvas, wall / "wall.mpcdi")
        pictures = [read_png(out / "mosaic" / "outputs" / name / f"frame_{f:05d}.png") for name in NAMES]
        for name, got in zip(NAMES, pictures):
            assert got.shape == (72, 96, 3)
            close_to(got, want[name], name)
    if decomposition != "screen":
        return
    # the simulated projection of the last frame's pictures against the canvas shown straight
    s, t = np.meshgrid(np.linspace(0.02, 0.98, 240), np.linspace(0.05, 0.95, 60))
    light = RIG.light(pictures, s, t).mean(axis=-1)
    straight = RIG.most() * RIG.black + (1 - RIG.black) * decode(sample(canvas, np.stack([s, t], -1))).mean(axis=-1)
    assert np.corrcoef(light.ravel(), straight.ravel())[0, 1] > 0.95
    # the overlaps neither dim nor brighten the picture (against where one projector alone shows it: the
    # resampling's own softening falls alike on both)
    n = RIG.covering(RIG.screen.point(s, t))
    ratio = [light[m].mean() / straight[m].mean() for m in (n == 2, n == 1)]
    assert abs(ratio[0] / ratio[1] - 1) < 0.03


def test_the_projectors_windows_show_their_pictures_side_by_side(wall, tmp_path):
    """Each rank's window is its projector's output (96x72), the three side by side on one X
    screen; a still path: what is on screen is the run's recorded pictures, bit for bit."""
    path = still_path(tmp_path)
    out = tmp_path / "win"
    shot, code, err = in_windows(3, wall / "wall.json", path, (3 * 96, 72), out, "p3")
    assert code == 0, err[-2000:]
    canvas = read_png(out / "mosaic" / "frame_00000.png")
    want = reference(canvas, wall / "wall.mpcdi")
    for k, name in enumerate(NAMES):
        got = read_png(out / "mosaic" / "outputs" / name / "frame_00000.png")
        close_to(got, want[name], name)
        assert np.array_equal(shot[:, 96 * k:96 * (k + 1)], got), name


@pytest.mark.parametrize("present", ["headless", "window"])
def test_the_example_three_projector_wall_runs(tmp_path, present):
    """``examples/walls/three-projectors.json`` as shipped (three 1920x1080 projectors, its MPCDI
    file made by ``warp make``): headless, and in windows on one X screen spanning the three."""
    from mpirun import ROOT

    wall = ROOT / "examples" / "walls" / "three-projectors.json"
    out = tmp_path / "out"
    args = ["walkthrough", *SMALL, "--wall", str(wall), "--frames", "2", "--mosaic-every", "1", "--no-overlay",
            "--present", present, "--out", str(out)]
    if present == "window":
        with Xvfb((5760, 1080)) as x:
            doc = json.loads(wall.read_text())  # the file's displays on this X server
            doc["mpcdi"] = str(wall.parent / doc["mpcdi"])
            for e in doc["displays"]:
                e["display"] = x.name
            (tmp_path / "wall.json").write_text(json.dumps(doc))
            args[args.index(str(wall))] = str(tmp_path / "wall.json")
            res = run_mpi(3, args, env={"DISPLAY": x.name}, timeout=300)
    else:
        res = run_mpi(3, args, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    canvas = read_png(out / "mosaic" / "frame_00001.png")
    assert canvas.shape == (1080, 5760, 3)
    want = reference(canvas, ROOT / "examples" / "walls" / "three-projectors.mpcdi")
    for name in NAMES:
        close_to(read_png(out / "mosaic" / "outputs" / name / "frame_00001.png"), want[name], name)


def test_a_rank_driving_two_projectors_shows_both_side_by_side(tmp_path):
    """Four projectors on two ranks (the wall file's grid 1x2: each rank a block of two regions,
    overlapping inside its tile as across tiles): the canvas equals one rank's render, each
    output's picture is the numpy reference's of its region, and each rank's window shows its two
    pictures side by side (a still path: bit for bit what the run recorded)."""
    rig = flat_rig(4, 0.18, size=(96, 72))
    bw, bh = buffer_size(rig)
    mpcdi.write(tmp_path / "four.mpcdi", (bw, bh), outputs(rig, (bw, bh)))
    (tmp_path / "wall.json").write_text(json.dumps({"mpcdi": "four.mpcdi", "grid": "1x2"}))
    path = still_path(tmp_path)
    one = tmp_path / "one"
    res = run_mpi(1, ["walkthrough", *SMALL, "--grid", "1x1", "--tile", f"{bw}x{bh}", "--path", str(path), "--frames",
                      "1", "--mosaic-every", "1", "--no-overlay", "--out", str(one)])
    assert res.returncode == 0, res.stderr[-3000:]
    out = tmp_path / "win"
    shot, code, err = in_windows(2, tmp_path / "wall.json", path, (4 * 96, 72), out, "p4")
    assert code == 0, err[-2000:]
    canvas = read_png(out / "mosaic" / "frame_00000.png")
    assert np.array_equal(canvas, read_png(one / "mosaic" / "frame_00000.png"))
    want = reference(canvas, tmp_path / "four.mpcdi")
    for k, name in enumerate(("p1", "p2", "p3", "p4")):
        got = read_png(out / "mosaic" / "outputs" / name / "frame_00000.png")
        close_to(got, want[name], name)
        assert np.array_equal(shot[:, 96 * k:96 * (k + 1)], got), name


def test_a_passive_stereo_projector_wall_drives_each_eyes_projectors_on_their_ranks(tmp_path):
    """Two tiles, a projector for each eye of each (the wall file's mpcdi and mpcdi_right, the
    right eyes' rig calibrated apart), four ranks (``--stereo passive --eyes own``): each eye's
    canvas equals one rank's render of that eye, and each projector's picture is the numpy
    reference's of its eye's region through its own file."""
    left_rig, right_rig = flat_rig(2, 0.18, size=(96, 72)), flat_rig(2, 0.18, size=(96, 72), black=0.01)
    bw, bh = buffer_size(left_rig)
    assert buffer_size(right_rig) == (bw, bh)
    for name, rig in (("left", left_rig), ("right", right_rig)):
        mpcdi.write(tmp_path / f"{name}.mpcdi", (bw, bh), outputs(rig, (bw, bh)))
    (tmp_path / "wall.json").write_text(json.dumps({"mpcdi": "left.mpcdi", "mpcdi_right": "right.mpcdi"}))
    stereo = ["--stereo", "passive", "--screen-size", "1.2,0.4", "--frames", "2", "--mosaic-every", "1",
              "--no-overlay"]
    one = tmp_path / "one"
    res = run_mpi(1, ["walkthrough", *SMALL, "--grid", "1x1", "--tile", f"{bw}x{bh}", *stereo, "--out", str(one)])
    assert res.returncode == 0, res.stderr[-3000:]
    out = tmp_path / "own"
    res = run_mpi(4, ["walkthrough", *SMALL, "--wall", str(tmp_path / "wall.json"), "--eyes", "own", *stereo,
                      "--out", str(out)])
    assert res.returncode == 0, res.stderr[-3000:]
    for f in range(2):
        for eye in ("left", "right"):
            canvas = read_png(out / "mosaic" / eye / f"frame_{f:05d}.png")
            assert np.array_equal(canvas, read_png(one / "mosaic" / eye / f"frame_{f:05d}.png")), (f, eye)
            want = reference(canvas, tmp_path / f"{eye}.mpcdi")
            for name in ("p1", "p2"):
                close_to(read_png(out / "mosaic" / "outputs" / eye / name / f"frame_{f:05d}.png"), want[name],
                         f"{eye} {name}")
    lw, rw = (read_png(out / "mosaic" / "outputs" / e / "p1" / "frame_00001.png") for e in ("left", "right"))
    assert (lw != rw).any()  # the eyes' projectors show their own pictures
    res = run_mpi(2, ["walkthrough", *SMALL, "--wall", str(tmp_path / "wall.json"), *stereo[:2], "--frames", "1",
                      "--out", str(tmp_path / "joint")])
    assert res.returncode == 2 and "needs --stereo passive --eyes own" in res.stderr, res.stderr[-2000:]
