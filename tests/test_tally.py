"""The running summary (records/tally.py) against a direct computation over every row, its
memory bounded however many frames it takes, and the appended ``--record`` path file."""

import errno
import json
import sys

import numpy as np
import pytest

from multigpu.records.report import BALANCE_NAMES, COLUMNS, TimingWriter
from multigpu.records.tally import EXACT, REL, Quantiles, RunningSummary, summarize, summarize_file, whole_frames

C = {c: i for i, c in enumerate(COLUMNS)}


def random_rows(frames: int, ranks: int, seed: int = 0) -> np.ndarray:
    """(F * K, C) rows as a run writes them: times in ms, integer counts, a balance index."""
    rng = np.random.default_rng(seed)
    rows = rng.gamma(2.0, 1.5, (frames * ranks, len(COLUMNS)))
    rows[:, C["frame"]] = np.repeat(np.arange(frames), ranks)
    rows[:, C["rank"]] = np.tile(np.arange(ranks), frames)
    rows[:, C["triangles"]] = rng.integers(0, 1000, frames * ranks)
    rows[:, C["balance"]] = np.repeat(rng.integers(0, len(BALANCE_NAMES), frames), ranks)
    rows[:, C["render_scale"]] = np.repeat(rng.choice([0.5, 1.0], frames), ranks)
    rows[:, C["lod_error_px"]] = 0.0
    return rows


def direct(rows: np.ndarray, K: int) -> dict:
    """The figures straight from every row at once (the way the summary was first computed)."""
    per = rows.reshape(-1, K, len(COLUMNS))
    g = lambda c: per[:, :, C[c]]
    cpu = g("load_balancing_cpu_ms") + g("rendering_cpu_ms") + g("frame_exchange_cpu_ms") + g("display_cpu_ms")
    em = cpu.max(axis=1)
    tri = g("triangles")
    drawn = tri.sum(axis=1) > 0
    t = tri[drawn]
    return {"frame_ms": g("frame_ms").mean(), "emulated_frame_ms": em.mean(), "emulated_median": np.median(em),
            "render_cpu_max_ms": g("rendering_cpu_ms").max(axis=1).mean(),
            "imbalance_triangles": np.mean(t.max(axis=1) / t.mean(axis=1)),
            "present_p99": np.percentile(g("present_ms"), 99), "input_median": np.median(g("input_ms")),
            "skew_max": g("swap_skew_ms")[:, 0].max(), "bytes": g("bytes_sent").sum(axis=1).mean(),
            "balance": np.bincount(g("balance")[:, 0].astype(int), minlength=len(BALANCE_NAMES))}


def check(s: dict, d: dict, rel_q: float = 0.0) -> None:
    assert s["frame_ms"] == pytest.approx(d["frame_ms"], rel=1e-12)
    assert s["emulated_frame_ms"] == pytest.approx(d["emulated_frame_ms"], rel=1e-12)
    assert s["render_cpu_max_ms"] == pytest.approx(d["render_cpu_max_ms"], rel=1e-12)
    assert s["imbalance_triangles"] == pytest.approx(d["imbalance_triangles"], rel=1e-12)
    assert s["bytes_sent_per_frame"] == pytest.approx(d["bytes"], rel=1e-12)
    assert s["present"]["swap_skew_ms_max"] == d["skew_max"]
    assert [s["balance_frames"].get(n, 0) for n in BALANCE_NAMES] == d["balance"].tolist()
    for got, want in ((s["emulated_frame_ms_median"], d["emulated_median"]),
                      (s["present"]["present_ms_p99"], d["present_p99"]), (s["input_ms_median"], d["input_median"])):
        assert got == pytest.approx(want, rel=rel_q, abs=1e-12)


def flat(doc: dict, at: str = "") -> dict:
    """A nested summary as one level of keys (for pytest.approx)."""
    out = {}
    for k, v in doc.items():
        out.update(flat(v, f"{at}{k}.") if isinstance(v, dict) else {f"{at}{k}": v})
    return out


@pytest.mark.parametrize("K", [2, 3, 4])
def test_a_short_run_is_summarized_exactly(K):
    rows = random_rows(300, K, seed=K)
    check(summarize(rows, K), direct(rows, K))


def test_a_long_run_keeps_means_exact_and_quantiles_within_the_bin_width():
    K = 4
    rows = random_rows(6000, K)  # 24,000 values per rank-wide stream: past EXACT
    assert 6000 * K > EXACT
    check(summarize(rows, K), direct(rows, K), rel_q=REL)


def test_batches_of_any_size_give_the_same_summary():
    K = 2
    rows = random_rows(257, K, seed=3)
    per = whole_frames(rows, K)
    one, many = RunningSummary(K), RunningSummary(K)
    one.add(per)
    for a in range(0, len(per), 50):
        many.add(per[a:a + 50])
    assert flat(one.result()) == pytest.approx(flat(many.result()), rel=1e-12)


def test_incomplete_frames_and_any_row_order_are_handled():
    K = 3
    rows = random_rows(40, K, seed=5)
    shuffled = rows[np.random.default_rng(1).permutation(len(rows))]
    extra = rows[-1:].copy()
    extra[0, C["frame"]] = 100
    partial = np.concatenate([shuffled, extra])
    assert flat(summarize(partial, K)) == pytest.approx(flat(summarize(rows, K)), rel=1e-12)  # frame 100: left out
    assert summarize(rows[:0], K) == {"frames": 0}


def test_the_file_summary_equals_the_rows_summary(tmp_path):
    K = 2
    rows = random_rows(500, K, seed=7)
    rows[:, C["balance"]] = 0
    w = TimingWriter(tmp_path / "timings.csv")
    for f in range(500):
        w.write(rows[f * K:(f + 1) * K])
    w.close()
    written = np.round(rows, 4)  # the CSV keeps 4 decimals
    for c in ("frame", "rank", "triangles", "x0", "y0", "x1", "y1", "bytes_sent", "objects", "pieces", "depth_bytes",
              "planned_triangles"):
        written[:, C[c]] = np.trunc(rows[:, C[c]])
    got, want = summarize_file(tmp_path / "timings.csv", K), summarize(written, K)
    assert got.keys() == want.keys() and got["frames"] == 500
    assert got["emulated_frame_ms"] == pytest.approx(want["emulated_frame_ms"], rel=1e-9)
    assert got["input_ms_median"] == pytest.approx(want["input_ms_median"], rel=1e-9)


def test_host_skew_and_target_figures():
    K = 4
    rows = random_rows(100, K, seed=9)
    s = summarize(rows, K, hosts=["a", "a", "b", "b"], target=(30.0, 1.0, 0.0))
    per = rows.reshape(-1, K, len(COLUMNS))
    swap = per[:, :, C["swap_ms"]]
    assert s["present"]["swap_skew_ms_by_host"]["b"] == pytest.approx(np.median(np.ptp(swap[:, 2:], axis=1)))
    judged = per[2:]  # the controller's warm-up frames are not judged
    period = judged[:, :, C["frame_ms"]].mean(axis=1)
    t = s["target"]
    assert t["frames_judged"] == 98 and t["reduced_frames"] == int((judged[:, 0, C["render_scale"]] < 1).sum())
    assert t["within_band"] == pytest.approx(np.mean(np.abs(period / (1e3 / 30) - 1) <= 0.1))
    assert t["fps"] == pytest.approx(1e3 / period.mean())


def state_bytes(tally: RunningSummary) -> int:
    """Everything the tally holds, arrays by their buffers."""
    seen, total, todo = set(), 0, [tally]
    while todo:
        x = todo.pop()
        if id(x) in seen:
            continue
        seen.add(id(x))
        total += x.nbytes if isinstance(x, np.ndarray) else sys.getsizeof(x)
        if isinstance(x, dict):
            todo += [*x.keys(), *x.values()]
        elif isinstance(x, (list, tuple)):
            todo += list(x)
        elif hasattr(x, "__dict__"):
            todo.append(vars(x))
    return total


def test_the_tally_holds_the_same_memory_after_ten_times_the_frames():
    K = 2
    tally = RunningSummary(K, hosts=["a", "b"], target=(60.0, 1.0, 0.0))
    block = whole_frames(random_rows(1000, K), K)
    for _ in range(10):
        tally.add(block)
    size = state_bytes(tally)
    for _ in range(90):
        tally.add(block)
    assert tally.frames == 100_000 and state_bytes(tally) == size
    assert len(json.dumps(tally.result())) < 4000  # no per-frame list in summary.json


def test_quantiles_past_exact_are_within_the_bin_width_and_zero_stays_zero():
    rng = np.random.default_rng(2)
    v = np.concatenate([np.zeros(5000), rng.lognormal(0.0, 2.0, 50_000)])
    q = Quantiles()
    for part in np.array_split(v, 37):
        q.add(part)
    for p in (1, 5, 50, 90, 99, 99.9):
        exact = np.sort(v)[int(np.floor(p / 100 * (v.size - 1)))]
        assert q.quantile(p) == pytest.approx(exact, rel=REL / 2 + 1e-12, abs=0 if exact else 1e-12)


def test_a_recorded_path_is_appended_and_valid_after_every_append(tmp_path):
    from multigpu.scene.pathfile import PathAppender
    from multigpu.scene.paths import load_path

    rng = np.random.default_rng(0)
    cams = np.column_stack([rng.normal(size=(25, 3)), rng.normal(size=(25, 3)) + 5, np.tile([0, 0, 1.0], (25, 1)),
                            np.full(25, 60.0), np.full(25, 0.1), np.full(25, 100.0)])
    w = PathAppender(tmp_path / "p.json")
    assert not (tmp_path / "p.json").exists()  # nothing recorded: no file
    for a, b in ((0, 1), (1, 10), (10, 25)):
        w.append(cams[a:b])
        p = load_path(tmp_path / "p.json")
        assert len(p) == b and np.array_equal(p.position, cams[:b, 0:3]) and np.array_equal(p.far, cams[:b, 11])
    w.close()


def test_a_failed_append_leaves_the_cameras_before_it(tmp_path, monkeypatch):
    from multigpu.scene import pathfile as paths
    from multigpu.scene.paths import load_path

    cams = np.tile([0, 0, 5.0, 0, 0, 0, 0, 1, 0, 60, 0.1, 100], (3, 1))
    w = paths.PathAppender(tmp_path / "p.json")
    w.append(cams[:2])
    real = paths.os.pwrite

    calls = []

    def short(fd, data, offset):  # a partial write, then the disk is full (the closing brackets still fit)
        calls.append(len(data))
        if len(calls) == 1:
            return real(fd, data[:8], offset)
        if len(data) > len(paths.PathAppender.TAIL):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data, offset)

    monkeypatch.setattr(paths.os, "pwrite", short)
    with pytest.raises(OSError):
        w.append(cams[2:])
    monkeypatch.setattr(paths.os, "pwrite", real)
    assert len(load_path(tmp_path / "p.json")) == 2 and w.frames == 2
    w.append(cams[2:])
    assert len(load_path(tmp_path / "p.json")) == 3
