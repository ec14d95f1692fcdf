"""``bench imbalance`` splits a rank's deviation from its frame's mean into what repeats when the
same work renders again and this machine's noise, and finds the part a feature explains."""

import numpy as np
import pytest

from multigpu.studies.imbalance_bench import FEATURES, split


def _process(rng, frames, ranks, sd, persist):
    """(frames, ranks) zero-mean deviations per frame, AR(1) over frames with ``persist``."""
    r = np.zeros((frames, ranks))
    r[0] = rng.normal(0, sd, ranks)
    for f in range(1, frames):
        r[f] = persist * r[f - 1] + np.sqrt(1 - persist ** 2) * rng.normal(0, sd, ranks)
    return r - r.mean(axis=1, keepdims=True)


def _renders(rng, frames=4000, ranks=4, repeat=0.10, noise=0.05, persist=0.0, from_feature=0.0):
    """Two renders of the same work: a repeatable deviation (``from_feature`` of its variance
    carried by the first feature) and independent noise."""
    seen, hidden = (_process(rng, frames, ranks, repeat, persist) for _ in range(2))
    r = np.sqrt(from_feature) * seen + np.sqrt(1 - from_feature) * hidden
    feats = rng.uniform(1, 2, (frames, ranks, len(FEATURES)))
    if from_feature:
        feats[..., 0] = 1.0 + seen  # relative to its frame's mean: the seen part itself
    base = 10.0 * (1 + r)
    first = base * (1 + rng.normal(0, noise, (frames, ranks)))
    second = base * (1 + rng.normal(0, noise, (frames, ranks)))
    return first, second, feats


def test_split_separates_what_repeats_from_noise():
    rng = np.random.default_rng(1)
    first, second, feats = _renders(rng, repeat=0.10, noise=0.05)
    got = split(first, second, feats)
    k = 4
    assert got["noise_sd"] == pytest.approx(0.05 * np.sqrt((k - 1) / k), rel=0.08)  # the frame's mean removes 1/K
    assert got["repeatable_sd"] == pytest.approx(0.10 * np.sqrt((k - 1) / k), rel=0.08)
    assert got["deviation_sd"] ** 2 == pytest.approx(got["repeatable_sd"] ** 2 + got["noise_sd"] ** 2, rel=0.05)
    assert abs(got["persists"]) < 0.1  # independent frames
    assert got["fit_leaves"] > 0.9  # random features explain nothing
    assert got["imbalance"] > got["imbalance_of_two"] > 1.0  # averaging two renders halves the noise


def test_split_sees_persistence_and_what_a_feature_explains():
    rng = np.random.default_rng(2)
    first, second, feats = _renders(rng, persist=0.7, from_feature=0.6)
    got = split(first, second, feats)
    assert got["persists"] == pytest.approx(0.7, abs=0.1)
    assert got["fit_leaves"] == pytest.approx(0.4, abs=0.1)


def test_imbalance_bench_runs_both_scenes(egl, capsys):
    """Both scenes measured, and the table it prints is what it returns (column by column)."""
    from multigpu.studies.imbalance_bench import bench_imbalance

    rows = bench_imbalance(quick=True)
    assert [r["scene"] for r in rows] == ["plant", "city"]
    printed = {line.split()[0]: [float(v) for v in line.split()[1:]] for line in capsys.readouterr().out.splitlines()
               if line.split() and line.split()[0] in ("plant", "city")}
    keys = ("imbalance", "imbalance_of_two", "deviation_sd", "repeatable_sd", "noise_sd", "persists", "fit_leaves")
    for r in rows:
        assert r["deviation_sd"] > 0 and r["noise_sd"] > 0
        assert printed[r["scene"]] == pytest.approx([r[k] for k in keys], abs=0.006, nan_ok=True), r
