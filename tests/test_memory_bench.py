"""``bench memory-steps`` measures what it names: every step, in order, with and without
llvmpipe's raster thread."""

import pytest


def test_memory_steps_report_every_step(tmp_path, monkeypatch):
    from multigpu.studies.memory_bench import bench_memory_steps

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path))
    try:
        steps = dict(bench_memory_steps(quick=True))
    except RuntimeError as exc:
        if "EGL" in str(exc):
            pytest.skip(f"no EGL here: {exc}")
        from multigpu.studies.memory_bench import NO_PIN

        if NO_PIN in str(exc):  # a GL without GL_AMD_pinned_memory (NVIDIA's); any other failure to share fails
            pytest.skip(str(exc))
        raise
    frames = [f"frame {f} ({t})" for t in ("1 raster thread", "0 raster threads") for f in range(3)]
    shared = [f"frame {f} (0 raster threads, shared file)" for f in range(3)]
    assert list(steps) == ["scene loaded (mapped) + EGL context", "GL upload", "compiled kernel loaded", *frames,
                           "GL buffers drawn from the shared file", *shared]
    assert steps["GL upload"] > steps["scene loaded (mapped) + EGL context"] > 0  # the driver's copy of the buffers
    # drawn from the file's pages, the buffers add less than half of what the upload adds
    loaded = steps["scene loaded (mapped) + EGL context"]
    assert steps["GL buffers drawn from the shared file"] - loaded < (steps["GL upload"] - loaded) / 2
    assert all(v > 0 for v in steps.values())


def test_model_load_bench_reports_each_load(tmp_path, monkeypatch):
    from multigpu.studies.memory_bench import bench_model_load

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path))
    rows = bench_model_load(quick=True)
    assert [r["load"] for r in rows] == ["trimesh", "into the cache", "cached"]
    assert len({r["triangles"] for r in rows}) == 1 and rows[0]["triangles"] > 0
    assert all(r["peak_rss"] > 0 for r in rows)
