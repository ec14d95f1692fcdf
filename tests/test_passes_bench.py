"""``bench passes`` measures what it names: both scenes, both parts, and the joined layout of
``cross`` renders fewer passes per rank than Equalizer's on the same walkthroughs."""

import numpy as np
import pytest


def test_passes_bench_reports_pass_costs_and_both_layouts():
    from multigpu.gpu.render import EglUnavailable, create_context
    from multigpu.studies.passes_bench import WIDTHS, bench_passes

    try:
        create_context()
    except EglUnavailable as exc:
        pytest.skip(str(exc))
    rows = bench_passes(quick=True)
    got = {(r["scene"], r["part"], r.get("layout")) for r in rows}
    assert got == {(s, "passes", None) for s in ("plant", "city")} | {
        (s, "layouts", layout) for s in ("plant", "city") for layout in ("equalizer", "joined")}
    for r in rows:
        values = [v for k, v in r.items() if k not in ("scene", "part", "layout")]
        assert values and np.isfinite(values).all()
        if r["part"] == "passes":
            assert r["tile_ms"] > 0 and {f"pass_{w}" for w in WIDTHS} <= set(r)
    for scene in ("plant", "city"):
        by = {r["layout"]: r for r in rows if r["scene"] == scene and r["part"] == "layouts"}
        assert 1.0 <= by["joined"]["passes"] < by["equalizer"]["passes"]
        assert by["joined"]["tris"] > 0 and by["joined"]["slowest_ms"] >= by["joined"]["mean_ms"] > 0
