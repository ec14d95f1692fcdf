"""``bench passes`` measures what it names: both scenes, both parts, every variant of part 2, and
the joined layout of ``cross`` renders fewer passes per rank than Equalizer's on the same
walkthroughs."""

import numpy as np


def test_passes_bench_reports_pass_costs_and_every_variant(egl):
    from multigpu.studies.passes_bench import VARIANTS, WIDTHS, bench_passes

    rows = bench_passes(quick=True)
    got = {(r["scene"], r["part"], r.get("variant")) for r in rows}
    assert got == {(s, "passes", None) for s in ("plant", "city")} | {
        (s, "variants", v) for s in ("plant", "city") for v in VARIANTS}
    for r in rows:
        values = [v for k, v in r.items() if k not in ("scene", "part", "variant")]
        assert values and np.isfinite(values).all()
        if r["part"] == "passes":
            assert r["tile_ms"] > 0 and {f"pass_{w}" for w in WIDTHS} <= set(r)
    for scene in ("plant", "city"):
        by = {r["variant"]: r for r in rows if r["scene"] == scene and r["part"] == "variants"}
        assert 1.0 <= by["joined"]["passes"] < by["equalizer"]["passes"]
        assert 1.0 <= by["uniform"]["passes"] < by["equalizer"]["passes"]
        assert by["joined"]["tris"] > 0 and by["joined"]["slowest_ms"] >= by["joined"]["mean_ms"] > 0
