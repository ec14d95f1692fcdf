"""A simulation's time series played on a 2x2 wall: every step at its own frames (``--late-step
wait``), every step's composite equal to one rank's render of that step (a recording's step at its
one frame), for screen, db and hybrid; a live wall (``hold``) never waits and
shows one step on every rank at every frame; a first step that cannot be read ends the job with one
line (exit 2), a later one is said once and the run plays on past it; a recorded run replays frame
for frame. Each job runs under a hard timeout."""

import csv
import json

import numpy as np
import pytest
from mpirun import read_png, run_mpi
from test_series import surface, write_series

pytestmark = pytest.mark.mpi
FRAMES = 40
#: 3 steps a second of scene time at 30 frames a second: a step every 10 frames
RATE = "3"
CASES = {"screen": [], "db": ["--decomposition", "db", "--latency", "0"],
         "hybrid": ["--decomposition", "hybrid", "--latency", "3"]}
#: each frame's step: a step every 10 frames, round the loop of 4
WANTED = [(f // 10) % 4 for f in range(FRAMES)]


def arguments(out, model, grid, tile, extra, path, frames=FRAMES) -> list[str]:
    return ["walkthrough", "--model", str(model), "--frames", str(frames), "--grid", f"{grid[0]}x{grid[1]}",
            "--tile", f"{tile[0]}x{tile[1]}", "--mosaic-every", "1", "--no-overlay", "--no-progress",
            "--path", str(path), "--out", str(out), *extra]


def walk(out, model, grid, tile, extra, path, frames=FRAMES):
    return run_mpi(grid[0] * grid[1], arguments(out, model, grid, tile, extra, path, frames), timeout=180)


def warm(steps, *args) -> None:
    """The cache of each of ``steps`` built as the run with ``args`` (``arguments``) reads it: the
    run's first load of a step then maps it (a cold one builds it: a second and more here, under
    load, and the wall holds the step before it meanwhile, as it should)."""
    from multigpu.flags import joined_negatives, walk_config, walkthrough_parser
    from multigpu.rank.series import load_step

    spec = walk_config(walkthrough_parser().parse_args(joined_negatives(arguments(*args)[1:]))).scene
    for k in steps:
        load_step(spec, k)


def steps_shown(out) -> list[int]:
    """Each frame's step, checked the same on every rank."""
    rows = list(csv.DictReader(open(out / "timings.csv")))
    by_frame: dict[int, set] = {}
    for r in rows:
        by_frame.setdefault(int(r["frame"]), set()).add(int(r["step"]))
    assert all(len(s) == 1 for s in by_frame.values()), {f: s for f, s in by_frame.items() if len(s) > 1}
    return [by_frame[f].pop() for f in sorted(by_frame)]


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    """Four steps (the third with a third fewer cells: built alone; the others in the first step's
    layout), a still camera, and one rank's render of each step: the references."""
    where = write_series(tmp_path_factory.mktemp("series"), 4, drop=2)
    cams = [{"position": [0.5, -1.1, 1.2], "target": [0.5, 0.45, 0.0], "up": [0, 0, 1], "fov": 50.0,
             "near": 0.05, "far": 20.0}] * FRAMES
    path = where / "still.json"
    path.write_text(json.dumps({"version": 1, "cameras": cams}))
    refs = []
    for k in range(4):  # one rank shows step k at its one frame (a recording's step)
        at = where / f"at{k}.json"
        at.write_text(json.dumps({"version": 1, "cameras": [{**cams[0], "step": k}]}))
        res = walk(where / f"ref{k}", where / "run.pvd", (1, 1), (96, 80), ["--color-by", "height"], at, frames=1)
        assert res.returncode == 0, res.stderr[-3000:]
        refs.append(read_png(where / f"ref{k}" / "mosaic" / "frame_00000.png"))
    assert all((refs[k] != refs[k + 1]).any() for k in range(3))  # the steps differ
    warm(range(4), where / "o", where / "run.pvd", (2, 2), (48, 40), ["--color-by", "height"], path)
    return where, path, refs


@pytest.mark.parametrize("name", list(CASES))
def test_every_step_composes_as_one_rank_renders_its_file(tmp_path, series, name):
    where, path, refs = series
    res = walk(tmp_path / "wall", where / "run.pvd", (2, 2), (48, 40),
               ["--color-by", "height", "--steps-per-second", RATE, "--late-step", "wait", *CASES[name]], path)
    assert res.returncode == 0, res.stderr[-3000:]
    assert steps_shown(tmp_path / "wall") == WANTED  # every step at its own frames
    for f, k in enumerate(WANTED):
        got = read_png(tmp_path / "wall" / "mosaic" / f"frame_{f:05d}.png")
        assert (got == refs[k]).all(), f"frame {f} (step {k}): {(got != refs[k]).any(axis=2).sum()} pixels differ"
    summary = json.loads((tmp_path / "wall" / "summary.json").read_text())
    assert summary["complete"] and summary["frames"] == FRAMES
    assert summary["series"] == {"steps_shown": 4, "step_changes": 3, "late_frames": 0, "last_step": 3}


def test_a_live_wall_never_waits_and_shows_one_step_everywhere(tmp_path, series):
    where, path, refs = series
    res = walk(tmp_path / "wall", where / "run.pvd", (2, 2), (48, 40),
               ["--color-by", "height", "--steps-per-second", RATE, "--latency", "1"], path)
    assert res.returncode == 0, res.stderr[-3000:]
    shown = steps_shown(tmp_path / "wall")  # the same step on every rank at every frame
    assert shown[0] == 0 and len(set(shown)) >= 2, shown  # the series played
    # a step shows no earlier than its time, and the wall moves forward (round the loop)
    assert all(k == 0 or f >= 10 * k for f, k in enumerate(shown)), shown
    assert all(b >= a or (a, b) == (3, 0) for a, b in zip(shown, shown[1:])), shown
    for f, k in enumerate(shown):
        got = read_png(tmp_path / "wall" / "mosaic" / f"frame_{f:05d}.png")
        assert (got == refs[k]).all(), f"frame {f} (step {k}): {(got != refs[k]).any(axis=2).sum()} pixels differ"


def test_a_first_step_that_cannot_be_read_ends_the_job_in_one_line(tmp_path, series):
    where, path, _ = series
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "step_0.vtu").write_bytes(b"<VTKFile>cut short")
    (bad / "step_1.vtu").write_bytes((where / "step_1.vtu").read_bytes())
    res = walk(tmp_path / "o", bad / "step_*.vtu", (1, 2), (48, 40), ["--color-by", "height"], path, frames=5)
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("multigpu: error:")]
    assert res.returncode == 2 and len(lines) == 1, res.stderr[-3000:]
    assert "step 0 of the series" in lines[0] and "step_0.vtu" in lines[0], lines


def test_a_later_step_that_cannot_be_read_is_said_once_and_the_run_goes_on(tmp_path, series):
    where, path, refs = series
    bad = tmp_path / "bad"
    bad.mkdir()
    for k in (0, 1, 3):
        (bad / f"step_{k}.vtu").write_bytes((where / f"step_{k}.vtu").read_bytes())
    (bad / "step_2.vtu").write_bytes(b"<VTKFile>cut short")
    heights = np.concatenate([surface(k).point_data["height"] for k in range(4)])
    flags = ["--color-by", "height", "--range", f"{float(heights.min())!r},{float(heights.max())!r}",
             "--steps-per-second", RATE, "--at-end", "hold", "--late-step", "wait"]
    warm((0, 1, 3), tmp_path / "o", bad / "step_*.vtu", (1, 2), (48, 80), flags, path)
    res = walk(tmp_path / "o", bad / "step_*.vtu", (1, 2), (48, 80), flags, path)
    assert res.returncode == 0, res.stderr[-3000:]
    said = [ln for ln in res.stderr.splitlines() if "step 2 of the series" in ln]
    assert len(said) == 1 and said[0].startswith("multigpu: warning: ") and "step_2.vtu" in said[0], res.stderr[-2000:]
    shown = steps_shown(tmp_path / "o")
    assert shown == [1 if k == 2 else k for k in WANTED[:30]] + [3] * 10, shown  # step 1 held through step 2's time
    late = [int(r["step_late"]) for r in csv.DictReader(open(tmp_path / "o" / "timings.csv")) if r["rank"] == "0"]
    assert late == [int(20 <= f < 30) for f in range(FRAMES)], late
    for f, k in enumerate(shown):
        got = read_png(tmp_path / "o" / "mosaic" / f"frame_{f:05d}.png")
        assert (got == refs[k]).all(), f"frame {f} (step {k})"


PVBATCH_WRITE = """
import json, sys
from paraview.simple import *
files, out = json.load(open(sys.argv[1])), sys.argv[2]
reader = XMLUnstructuredGridReader(FileName=files)
SaveData(out, proxy=reader, WriteTimeSteps=1)
"""


def test_a_series_paraview_wrote_plays_as_one_rank_renders_it(tmp_path, series):
    """The series written again by ParaView (pvbatch's SaveData with every time step: a .pvd and its
    files, as ParaView users keep results), played on a 2x2 wall exactly as one rank renders it
    (skipped, naming why, where ParaView is not installed)."""
    import shutil
    import subprocess

    pvbatch = shutil.which("pvbatch")
    if pvbatch is None:
        pytest.skip("ParaView's pvbatch is not installed (Debian: apt install paraview)")
    where, path, _ = series
    (tmp_path / "files.json").write_text(json.dumps([str(where / f"step_{k}.vtu") for k in range(4)]))
    (tmp_path / "write.py").write_text(PVBATCH_WRITE)
    clean = {k: v for k, v in __import__("os").environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    made = subprocess.run([pvbatch, "--force-offscreen-rendering", str(tmp_path / "write.py"),
                           str(tmp_path / "files.json"), str(tmp_path / "pv" / "run.pvd")], env=clean,
                          capture_output=True, text=True, timeout=180)
    if not (tmp_path / "pv" / "run.pvd").is_file():
        pytest.skip(f"pvbatch could not write the series here: {(made.stdout + made.stderr).strip()[-300:]}")
    from multigpu.scene.series import find_series

    assert len(find_series(str(tmp_path / "pv" / "run.pvd"))) == 4
    flags = ["--color-by", "height", "--steps-per-second", RATE, "--late-step", "wait"]
    wall = walk(tmp_path / "wall", tmp_path / "pv" / "run.pvd", (2, 2), (48, 40), flags, path)
    one = walk(tmp_path / "one", tmp_path / "pv" / "run.pvd", (1, 1), (96, 80), flags, path)
    assert wall.returncode == 0 and one.returncode == 0, (wall.stderr + one.stderr)[-3000:]
    assert steps_shown(tmp_path / "wall") == WANTED
    for f in range(0, FRAMES, 5):
        got, want = (read_png(tmp_path / d / "mosaic" / f"frame_{f:05d}.png") for d in ("wall", "one"))
        assert (got == want).all(), f"frame {f}: {(got != want).any(axis=2).sum()} pixels differ"


def test_a_recorded_series_run_replays_frame_for_frame(tmp_path, series):
    """``--record`` keeps each frame's scene time; played back (``--path`` the recording, the
    series waiting for each step as it did), every frame shows the same step and the same pixels:
    the recorded times rule (recorded at twice the speed, replayed without saying so)."""
    from multigpu.scene.paths import load_path

    where, path, _ = series
    flags = ["--color-by", "height", "--steps-per-second", RATE, "--late-step", "wait"]
    first = walk(tmp_path / "first", where / "run.pvd", (2, 2), (48, 40),
                 [*flags, "--anim-speed", "2", "--record", str(tmp_path / "rec.json")], path, frames=25)
    assert first.returncode == 0, first.stderr[-3000:]
    assert len(load_path(tmp_path / "rec.json")) == 25
    again = walk(tmp_path / "again", where / "run.pvd", (2, 2), (48, 40), flags, tmp_path / "rec.json", frames=25)
    assert again.returncode == 0, again.stderr[-3000:]
    twice = [(f // 5) % 4 for f in range(25)]  # a step every 5 frames at twice the speed
    assert steps_shown(tmp_path / "again") == steps_shown(tmp_path / "first") == twice
    for f in range(25):
        got, want = (read_png(tmp_path / d / "mosaic" / f"frame_{f:05d}.png") for d in ("again", "first"))
        assert (got == want).all(), f"frame {f}: {(got != want).any(axis=2).sum()} pixels differ"


def test_a_recorded_live_run_replays_the_steps_it_showed(tmp_path, series):
    """A wall that never waits (``hold``) shows a step once every rank holds it, maybe frames after
    its time; ``--record`` keeps the step each frame showed, and the replay shows those steps at
    those frames (waiting for them where it must), not the steps of the frames' times: here a
    recording whose step 1 came three frames late (its cameras are still: the late frames show
    step 0's picture)."""
    from multigpu.scene.paths import load_path

    where, path, refs = series
    flags = ["--color-by", "height", "--steps-per-second", RATE, "--latency", "1"]
    first = walk(tmp_path / "first", where / "run.pvd", (2, 2), (48, 40),
                 [*flags, "--record", str(tmp_path / "rec.json")], path, frames=30)
    assert first.returncode == 0, first.stderr[-3000:]
    shown = steps_shown(tmp_path / "first")
    assert load_path(tmp_path / "rec.json").steps.tolist() == shown and len(set(shown)) >= 2
    doc = json.loads((tmp_path / "rec.json").read_text())
    late = [c["step"] for c in doc["cameras"]]
    late[10:13] = [0, 0, 0]  # step 1 three frames late
    for c, k in zip(doc["cameras"], late):
        c["step"] = k
    (tmp_path / "late.json").write_text(json.dumps(doc))
    again = walk(tmp_path / "again", where / "run.pvd", (2, 2), (48, 40), flags, tmp_path / "late.json", frames=30)
    assert again.returncode == 0, again.stderr[-3000:]
    assert steps_shown(tmp_path / "again") == late
    for f, k in enumerate(late):
        got = read_png(tmp_path / "again" / "mosaic" / f"frame_{f:05d}.png")
        assert (got == refs[k]).all(), f"frame {f} (step {k}): {(got != refs[k]).any(axis=2).sum()} pixels differ"


def test_a_recovered_series_run_resumes_at_the_step_of_its_frame(tmp_path, series):
    """A rank killed mid-run (``--recover 1``, ``--late-step wait``): the restarted job shows at
    every frame the step the first would have, each frame equal to one rank's render of it."""
    from test_recovery_mpi import killed_once

    where, path, refs = series
    frames, out = 120, tmp_path / "o"
    still = tmp_path / "still.json"  # the fixture's still camera, for every frame
    doc = json.loads(path.read_text())
    still.write_text(json.dumps({**doc, "cameras": doc["cameras"][:1] * frames}))
    args = ["-n", "2", *arguments(out, where / "run.pvd", (1, 2), (48, 80), ["--color-by", "height",
                                  "--steps-per-second", RATE, "--late-step", "wait", "--recover", "1", "--liveness",
                                  "3"], still, frames)]
    code, err = killed_once(args, out, 2 * 25)
    assert code == 0, err[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is True and s["recovery_count"] == 1 and 25 <= s["recoveries"][0]["resumed_at"] < frames
    wanted = [(f // 10) % 4 for f in range(frames)]
    assert steps_shown(out) == wanted
    for f, k in enumerate(wanted):
        got = read_png(out / "mosaic" / f"frame_{f:05d}.png")
        assert (got == refs[k]).all(), f"frame {f} (step {k}): {(got != refs[k]).any(axis=2).sum()} pixels differ"
