"""Speed for accuracy under mpiexec: a scaled, level-of-detail frame composes to what one rank
renders with the same settings, for the screen partition and sort-last; with a frame-rate
target the frames whose camera stopped are bit for bit those of a run without it; bad values are
one line and exit 2. Every job under a hard timeout."""

import json

import pytest
from mpirun import SMALL, read_png, run_mpi

pytestmark = pytest.mark.mpi
W, H = 120, 96


def walk(out, n, grid, frames, extra=()):
    rows, cols = grid
    args = ["walkthrough", *SMALL, "--frames", str(frames), "--grid", f"{rows}x{cols}",
            "--tile", f"{W // cols}x{H // rows}", "--mosaic-every", "1", "--no-overlay", "--out", str(out), *extra]
    res = run_mpi(n, args)
    assert res.returncode == 0, res.stderr[-3000:]
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(frames)]


@pytest.mark.parametrize("extra", [[], ["--decomposition", "db"], ["--latency", "0", "--balance", "cross"],
                                   ["--decomposition", "hybrid"]])
def test_scaled_levelled_composite_equals_one_rank_with_the_same_settings(tmp_path, extra):
    quality = ["--render-scale", "0.45", "--lod-error", "3", *extra]
    one = walk(tmp_path / "one", 1, (1, 1), 4, quality)
    four = walk(tmp_path / "four", 4, (2, 2), 4, quality)
    full = walk(tmp_path / "full", 1, (1, 1), 4, extra)
    for f, (a, b, c) in enumerate(zip(four, one, full)):
        assert (a == b).all(), f"frame {f}: {(a != b).any(axis=2).sum()} pixels differ"
        assert (a != c).any(axis=2).mean() > 0.01  # the settings did change the picture
    s = json.loads((tmp_path / "four" / "summary.json").read_text())
    assert s["quality"]["render_scale_mean"] == pytest.approx(0.45) and s["config"]["lod_error"] == 3.0
    assert s["triangles_per_frame"] < json.loads((tmp_path / "full" / "summary.json").read_text())[
        "triangles_per_frame"] or extra  # fewer triangles at coarser levels (sort-last draws each object once)


def test_frames_whose_camera_stopped_are_full_quality_under_a_target(tmp_path):
    walk(tmp_path / "rec", 1, (1, 1), 7, ["--record", str(tmp_path / "rec.json")])
    cams = json.loads((tmp_path / "rec.json").read_text())["cameras"]
    order = [0, 1, 2, 3, 4, 5, 5, 5, 6, 6]  # the camera stops at frames 6, 7 and 9
    (tmp_path / "still.json").write_text(json.dumps({"version": 1, "cameras": [cams[i] for i in order]}))
    path = ["--path", str(tmp_path / "still.json")]
    held = walk(tmp_path / "held", 4, (2, 2), len(order), [*path, "--target-fps", "100000"])
    free = walk(tmp_path / "free", 4, (2, 2), len(order), path)
    for f in (6, 7, 9):
        differ = (held[f] != free[f]).any(axis=2).sum()
        assert differ == 0, f"frame {f}: the camera stopped, yet {differ} pixels differ"
    assert any((held[f] != free[f]).any() for f in (4, 5, 8))  # moving frames were cheaper
    s = json.loads((tmp_path / "held" / "summary.json").read_text())
    assert s["target"]["target_fps"] == 100000 and s["target"]["reduced_frames"] >= 2
    rows = (tmp_path / "held" / "timings.csv").read_text().splitlines()
    head = rows[0].split(",")
    scale = {int(r.split(",")[0]): float(r.split(",")[head.index("render_scale")]) for r in rows[1:]}
    assert scale[6] == scale[7] == scale[9] == 1.0 and min(scale.values()) < 1.0


@pytest.mark.parametrize("flag,value,words", [("--target-fps", "0", "--target-fps must be a frame rate above 0"),
                                              ("--target-fps", "-5", "--target-fps must be a frame rate above 0"),
                                              ("--target-fps", "fast", "--target-fps: invalid float value"),
                                              ("--target-fps", "nan", "--target-fps must be a frame rate above 0"),
                                              ("--lod-error", "-1", "--lod-error must be >= 0 pixels"),
                                              ("--lod-error", "px", "--lod-error: invalid float value"),
                                              ("--render-scale", "1.5", "--render-scale must be 0.25..1")])
def test_bad_quality_flags_are_one_line_and_exit_2(tmp_path, flag, value, words):
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "2", "--out", str(tmp_path / "o"),
                      flag, value], timeout=60)
    assert res.returncode == 2
    lines = [x for x in res.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and words in lines[0], res.stderr
    assert not (tmp_path / "o" / "summary.json").exists()
