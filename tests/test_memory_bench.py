"""``bench memory-steps`` measures what it names: every step, in order, for both ways of drawing."""

import pytest


def test_memory_steps_report_every_step(tmp_path, monkeypatch):
    from multigpu.studies.memory_bench import bench_memory_steps

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path))
    try:
        steps = dict(bench_memory_steps(quick=True))
    except RuntimeError as exc:
        if "EGL" in str(exc):
            pytest.skip(f"no EGL here: {exc}")
        raise
    assert list(steps) == ["scene loaded (mapped) + EGL context", "GL upload", "compiled kernel loaded", "frame 0",
                           "frame 1", "frame 0 (plain draw)", "frame 1 (plain draw)"]
    assert steps["GL upload"] > steps["scene loaded (mapped) + EGL context"] > 0  # the driver's copy of the buffers
    assert all(v > 0 for v in steps.values())
