"""Scenes that move, under mpiexec (2-4 ranks, each job under a hard timeout): a moving scene's
wall equals one rank's render of the same frame bit for bit, for every decomposition, frames in
flight, machinery cut into clusters and parts, Open MPI, a replay and a recovery; its mosaics
change with the camera held still."""

import json
import os

import numpy as np
import pytest
from mpirun import mpi_named, read_png, run_mpi

pytestmark = pytest.mark.mpi
FRAMES = 5
SWARM = ["--scene", "swarm", "--triangles", "20000", "--path-kind", "still", "--no-progress"]
# the plant's machinery, its objects cut into clusters (one body each) and parts
PLANT = ["--triangles", "20000", "--moving", "0.3", "--cluster", "64", "--path-kind", "orbit", "--no-progress"]


def walk(out, grid, tile, extra=(), scene=SWARM, frames=FRAMES, launcher=None):
    args = ["walkthrough", *scene, "--frames", str(frames), "--grid", f"{grid[0]}x{grid[1]}",
            "--tile", f"{tile[0]}x{tile[1]}", "--mosaic-every", "1", "--no-overlay", "--out", str(out), *extra]
    res = run_mpi(grid[0] * grid[1], args, launcher=launcher)
    assert res.returncode == 0, res.stderr[-3000:]
    return out


def frames_of(out, n=FRAMES):
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(n)]


def same(got, want):
    for f, (g, w) in enumerate(zip(got, want)):
        assert g.shape == w.shape and (g == w).all(), f"frame {f}: {(g != w).any(axis=2).sum()} pixels differ"


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    base = tmp_path_factory.mktemp("moving")
    return {"swarm": frames_of(walk(base / "swarm", (1, 1), (120, 96))),
            "plant": frames_of(walk(base / "plant", (1, 1), (120, 96), scene=PLANT))}


def test_the_swarm_moves_with_the_camera_held_still(reference):
    shots = reference["swarm"]
    changed = [int((shots[f] != shots[f - 1]).any(axis=2).sum()) for f in range(1, FRAMES)]
    assert min(changed) > 100, changed  # every frame differs from the last: the objects flew


@pytest.mark.parametrize("extra", [[], ["--decomposition", "db"], ["--decomposition", "hybrid"],
                                   ["--latency", "2"], ["--balance", "static"], ["--balance", "time"],
                                   ["--projection", "shared"], ["--decomposition", "db", "--latency", "3"]],
                         ids=["screen", "db", "hybrid", "latency2", "static", "time", "shared-projection",
                              "db-latency3"])
def test_a_moving_swarm_equals_one_rank_render(reference, tmp_path, extra):
    out = walk(tmp_path / "wall", (2, 2), (60, 48), extra)
    same(frames_of(out), reference["swarm"])
    s = json.loads((out / "summary.json").read_text())
    assert s["cpu"]["posing_cpu_ms"] > 0  # the objects were posed every frame


@pytest.mark.parametrize("grid,tile,extra", [((2, 2), (60, 48), []), ((1, 3), (40, 96), ["--decomposition", "hybrid"]),
                                             ((1, 2), (60, 96), ["--latency", "0"])], ids=["2x2", "1x3-hybrid", "1x2"])
def test_moving_machinery_equals_one_rank_render(reference, tmp_path, grid, tile, extra):
    """A plant whose machinery turns, slides and orbits, its objects cut into clusters and parts:
    each cluster and part moves with its object."""
    same(frames_of(walk(tmp_path / "wall", grid, tile, extra, scene=PLANT)), reference["plant"])


def test_under_open_mpi_too(reference, tmp_path):
    same(frames_of(walk(tmp_path / "wall", (2, 2), (60, 48), launcher=mpi_named("openmpi"))), reference["swarm"])


def test_a_replay_of_a_recording_shows_the_same_moving_frames(reference, tmp_path):
    rec = tmp_path / "rec.json"
    walk(tmp_path / "first", (1, 2), (60, 96), ["--record", str(rec)])
    replay = walk(tmp_path / "replay", (2, 2), (60, 48), ["--path", str(rec)], scene=[
        a for a in SWARM if a not in ("--path-kind", "still")])
    same(frames_of(replay), reference["swarm"])


def test_a_recovered_wall_resumes_at_the_same_scene_time(tmp_path):
    """A rank killed mid-run: the restarted job poses the frames it shows where the first would
    have, so every mosaic equals the one-rank render of its frame."""
    frames = 160
    ref = frames_of(walk(tmp_path / "one", (1, 1), (96, 48), frames=frames), frames)
    out = tmp_path / "o"
    args = ["-n", "2", "walkthrough", *SWARM, "--grid", "1x2", "--tile", "48x48", "--frames", str(frames),
            "--mosaic-every", "1", "--no-overlay", "--out", str(out), "--recover", "1", "--liveness", "3"]
    from test_recovery_mpi import killed_once

    code, err = killed_once(args, out, 2 * 40)
    assert code == 0, err[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is True and s["recovery_count"] == 1
    resumed = s["recoveries"][0]["resumed_at"]
    assert 40 <= resumed < frames
    got = frames_of(out, frames)
    same(got, ref)
    assert not np.array_equal(got[resumed], got[resumed - 1])


PUMP = ["--model", "models/pump-running.glb", "--path-kind", "still", "--cluster", "64", "--no-progress"]  # one scene


def test_an_animated_gltf_plays_on_a_2x2_wall_like_one_rank(tmp_path):
    ref = frames_of(walk(tmp_path / "one", (1, 1), (128, 96), scene=PUMP, frames=8), 8)
    assert all((ref[f] != ref[f - 1]).any() for f in range(1, 8))  # the camera still, the pump running
    for extra in ([], ["--decomposition", "hybrid", "--latency", "2"]):
        same(frames_of(walk(tmp_path / "wall", (2, 2), (64, 48), extra, scene=PUMP, frames=8), 8), ref)
    same(frames_of(walk(tmp_path / "ompi", (2, 2), (64, 48), scene=PUMP, frames=8, launcher=mpi_named("openmpi")), 8),
         ref)  # Open MPI too


def test_a_bad_animation_ends_the_job_in_one_line_with_exit_2(tmp_path):
    import pygltflib

    doc = pygltflib.GLTF2().load("models/pump-running.glb")
    doc.animations[0].channels[0].target.node = 500
    bad = tmp_path / "bad.glb"
    doc.save_binary(str(bad))
    res = run_mpi(2, ["walkthrough", "--model", str(bad), "--grid", "1x2", "--tile", "32x32", "--frames", "2",
                      "--out", str(tmp_path / "o"), "--no-progress"])
    assert res.returncode == 2, res.stderr[-2000:]
    lines = [ln for ln in res.stderr.splitlines() if "target.node" in ln]
    assert lines and "Traceback" not in res.stderr and str(bad) in lines[0], res.stderr[-2000:]
    res = run_mpi(2, ["walkthrough", "--model", "models/pump-running.glb", "--animation", "spin", "--grid", "1x2",
                      "--tile", "32x32", "--frames", "2", "--out", str(tmp_path / "o2"), "--no-progress"])
    assert res.returncode == 2 and "it has: 'run', 'lift'" in res.stderr and "Traceback" not in res.stderr


def test_the_page_pauses_and_scrubs_scene_time_and_the_recording_replays_it(tmp_path):
    """A moving scene steered from the page: its time paused (the frames stand still, the camera
    too), set to 3 s, played on; the page shows the time; ``--record`` stores each frame's time,
    so a replay on another wall shows the same frames bit for bit."""
    from pageclient import drive
    from test_panel_mpi import Job

    from multigpu.core.motion import FRAME_SECONDS
    from multigpu.scene.paths import load_path

    out, rec = tmp_path / "out", tmp_path / "rec.json"
    job = Job(["walkthrough", *SWARM, "--grid", "1x2", "--tile", "60x96", "--frames", "100000", "--mosaic-every", "1",
               "--no-overlay", "--panel", "127.0.0.1:0", "--record", str(rec), "--out", str(out)])

    async def script(page) -> None:
        await page.more_rows(5)
        await page.send(do="scene_pause")
        await page.until(lambda: page.status.get("scene_paused"))
        await page.more_rows(6)
        await page.send(do="scene_time", value=3.0)
        await page.more_rows(4)
        await page.send(do="scene_play")
        await page.until(lambda: page.status.get("scene_paused") is False)
        await page.more_rows(6)
        await page.send(do="stop")
        await page.until(lambda: page.summary is not None)

    code, page = drive(job, script)
    assert code == 0, job.output[-3000:]
    assert 3.0 in page.times  # the page showed the scene's time
    flown = load_path(rec)
    times, n = flown.times, len(flown)
    assert times is not None and n >= 20
    steps = np.diff(times)
    held = np.flatnonzero(steps == 0)
    assert len(held) >= 4 and times[0] == 0.0  # paused: the time stood
    assert 3.0 in times and (np.isclose(steps, FRAME_SECONDS) | (steps == 0) | (times[1:] == 3.0)).all()
    shots = frames_of(out, n)
    for f in held:  # the camera still and the time held: the very same picture
        assert (shots[f + 1] == shots[f]).all()
    replay = walk(tmp_path / "replay", (2, 2), (60, 48), ["--path", str(rec)],
                  scene=[a for a in SWARM if a not in ("--path-kind", "still")], frames=n)
    same(frames_of(replay, n), shots)


KHRONOS = "/usr/share/assimp/models/glTF2/"


@pytest.mark.skipif(not os.path.isdir(KHRONOS), reason="Debian's assimp-testmodels is not installed")
@pytest.mark.parametrize("model,kind,extra", [
    ("glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf", "still",
     ["--decomposition", "hybrid", "--latency", "2"]),
    ("simple_skin/simple_skin.gltf", "orbit", ["--decomposition", "db", "--latency", "2"])], ids=["morph", "skin"])
def test_khronos_files_play_on_a_2x2_wall_like_one_rank(tmp_path, model, kind, extra):
    """Files other tools wrote: a cube's morph target weights, a strip bent by its skin's joints
    in the vertex shader; the composites equal one rank's render of every frame (screen, a
    sort-last decomposition in flight, Open MPI)."""
    scene = ["--model", KHRONOS + model, "--path-kind", kind, "--cluster", "0", "--no-progress"]
    ref = frames_of(walk(tmp_path / "one", (1, 1), (128, 96), scene=scene, frames=12), 12)
    assert (ref[-1] != ref[0]).any()
    for flags, launcher in (([], None), (extra, None), ([], mpi_named("openmpi"))):
        same(frames_of(walk(tmp_path / "wall", (2, 2), (64, 48), flags, scene=scene, frames=12, launcher=launcher),
                       12), ref)


def test_the_shipped_arm_waves_its_clusters_as_one_body_like_one_rank(tmp_path):
    """models/arm.glb, skinned, cut into clusters for the wall: every cluster of the arm bends
    with it (one body), on a 2x2 hybrid wall as on one rank."""
    scene = ["--model", "models/arm.glb", "--path-kind", "orbit", "--cluster", "64", "--no-progress"]
    ref = frames_of(walk(tmp_path / "one", (1, 1), (128, 96), scene=scene, frames=10), 10)
    got = walk(tmp_path / "wall", (2, 2), (64, 48), ["--decomposition", "hybrid"], scene=scene, frames=10)
    same(frames_of(got, 10), ref)
    assert json.loads((got / "summary.json").read_text())["config"]["scene"]["objects"] > 4  # cut into clusters
