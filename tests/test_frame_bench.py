"""``multigpu bench frame``: one rank's per-frame phases, planned by the frame loop's own planner."""

import numpy as np
import pytest

from multigpu.scene.models import SceneSpec, load_scene
from multigpu.scene.paths import generate
from multigpu.studies.frame_bench import FEW, PHASES, bench_frame, frame_phases


def test_bench_frame_times_every_phase_of_every_strategy_and_the_fixed_cost_of_a_few_objects(capsys):
    rows = bench_frame(quick=True)
    out = capsys.readouterr().out
    header = out.splitlines()[2].split()
    printed = {(line.split()[0], line.split()[2]): line.split() for line in out.splitlines()[3:] if line.strip()}
    for r in rows:  # the table printed is the rows returned, column by column
        got = dict(zip(header, printed[(r["scene"], r["strategy"])]))
        assert int(got["objects"]) == r["objects"] and int(got["calls"]) == r["calls"]
        for col in (*PHASES, "total", "balancing", "cold", "fixed"):
            assert float(got[col]) == pytest.approx(r[col], abs=6e-4), (col, got[col], r[col])
    assert {r["scene"] for r in rows} == {"plant", "city"}
    assert {r["strategy"] for r in rows} == {"strips", "time", "cross", "cost", "adaptive", "none"}
    for r in rows:
        assert all(r[p] >= 0 for p in PHASES) and r["balancing"] > 0 and r["cold"] > 0 and r["fixed"] > 0, r
        assert r["calls"] > 0


def test_frame_phases_plans_a_scene_s_few_objects_along_the_whole_scene_s_path():
    scene, _ = load_scene(SceneSpec(scene="city", triangles=20_000))
    path = generate("walkthrough", scene, 8)
    few = scene.objects(np.linspace(0, scene.n_objects - 1, FEW).astype(np.int64))
    med = frame_phases(few, "cross", frames=8, path=path)
    assert set(PHASES) <= set(med) and med["balancing"] > 0
