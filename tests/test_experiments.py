"""Smoke test: every experiment at --quick size runs and writes parseable outputs."""

import csv
import os
import signal
import subprocess
import sys

import pytest
from PIL import Image

from multigpu.studies.experiments import EXPERIMENTS


@pytest.mark.slow
def test_all_experiments_quick(tmp_path):
    out = tmp_path / "exp"
    page = tmp_path / "RESULTS.md"
    proc = subprocess.Popen([sys.executable, "-m", "multigpu", "experiment", "all", "--quick", "--out", str(out),
                             "--results", str(page)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, env={**os.environ, "LP_NUM_THREADS": "1"})
    try:
        log, _ = proc.communicate(timeout=2100)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise AssertionError("experiment all --quick did not finish within 2100 s")
    assert proc.returncode == 0, log[-3000:]
    text = page.read_text()
    for name in EXPERIMENTS:
        d = out / name
        rows = list(csv.DictReader(open(d / f"{name}.csv")))
        assert rows, name
        for r in rows:  # every figure parses as a number or is a label
            for k, v in r.items():
                assert v != "", (name, k)
        md = (d / f"{name}.md").read_text()
        assert md.startswith(f"## {name}") and "|" in md
        assert f"## {name}" in text
        for png in d.glob("*.png"):
            with Image.open(png) as im:
                assert im.size[0] > 10
    for name in ("gpus", "resolution", "balance", "strips", "overlap"):
        assert (out / name / f"{name}.png").exists()
    gpus = list(csv.DictReader(open(out / "gpus" / "gpus.csv")))
    one = [r for r in gpus if int(r["ranks"]) == 1]
    many = [r for r in gpus if int(r["ranks"]) > 1]
    # speedups are timings (no bound on them here: a shared 2-core machine can run 4 ranks slower
    # than 1); each is a finite positive ratio, and the 1-rank base over itself is exactly 1
    assert one and many and all(0.0 < float(r["render_speedup"]) < float("inf") for r in gpus), gpus
    assert all(float(r["render_speedup"]) == 1.0 for r in one), one


def test_payoff_says_what_a_choosing_default_planned_with():
    """The payoff page's account of ``auto``: the share of its frames the best strategy planned,
    and the frame its choices would cost at its candidates' own frame times."""
    from multigpu.studies.payoff import planned_by

    rows = [{"scene": "city", "balance": b, "emulated_ms": ms}
            for b, ms in (("cross", 3.0), ("strips", 4.0), ("auto", 3.5), ("none", 3.6))]
    check = {"scene": "city", "best": "cross"}
    got = planned_by(rows, check, [{"cross": 180, "strips": 60}, {"cross": 240}, {"cross": 120, "strips": 120}])
    assert got["by_best"] == "75%"  # the median of 0.75, 1.0, 0.5
    # shares 0.75 and 0.25 (medians of 0.25, 0, 0.5), renormalised: 0.75 * 3 + 0.25 * 4 = 3.25
    assert got["expected_of_best"] == f"{3.0 / 3.25:.3f}"
    assert planned_by(rows, check, [{}, {}]) == {"by_best": "-", "expected_of_best": "-"}  # not a choosing default
    assert planned_by(rows, {"scene": "city", "best": "time"}, [{"cross": 240}])["by_best"] == "-"


def test_payoff_splits_the_balancing_of_none_the_default_and_the_best():
    """Per scene, ``none``, the default and the best strategy (each once where they coincide),
    their balancing CPU in its phases, what it adds to ``none``'s, and the projection's share."""
    from multigpu.studies.payoff import balancing_parts

    def row(scene, balance, learn, project, plan, frame):
        lb = learn + project + plan
        return {"scene": scene, "balance": balance, "learn_ms": learn, "project_ms": project, "plan_ms": plan,
                "lb_cpu_ms": lb, "lb_share": lb / frame, "emulated_ms": frame}

    rows = [row("city", "none", 0.02, 0.14, 0.20, 8.0), row("city", "auto", 0.04, 0.14, 0.24, 7.0),
            row("city", "cross", 0.04, 0.15, 0.23, 6.0), row("city", "strips", 0.0, 0.14, 0.3, 9.0),
            row("plant", "none", 0.01, 0.1, 0.1, 10.0), row("plant", "auto", 0.02, 0.1, 0.12, 8.0)]
    checks = [{"scene": "city", "default": "auto", "best": "cross"}, {"scene": "plant", "default": "auto",
                                                                        "best": "auto"}]
    got = balancing_parts(rows, checks)
    assert [(r["scene"], r["balance"]) for r in got] == [("city", "none"), ("city", "auto"), ("city", "cross"),
                                                          ("plant", "none"), ("plant", "auto")]
    assert got[0]["above_none_ms"] == 0.0
    assert got[1]["above_none_ms"] == pytest.approx(0.42 - 0.36)
    assert got[2]["project_share"] == pytest.approx(0.15 / 6.0) and got[2]["lb_share"] == pytest.approx(0.42 / 6.0)


def test_payoff_splits_the_default_against_the_best_at_its_first_trial():
    """The best's frame over the default's, paired by round, on the frames of the default's
    first trial and after it; '-' where there is no trial to split at."""
    from multigpu.studies.payoff import first_trial

    def run(frames, trials=None):
        strategy = {"name": "auto", "trials": trials} if trials is not None else {"name": "cross"}
        return {"per_frame_emulated_ms": frames, "decomposition": {"strategy": strategy}}

    auto = [run([6.0] * 4 + [4.0] * 6, [{"frames": 4}]), run([5.0] * 2 + [4.0] * 8, [{"frames": 2}, {"frames": 9}]),
            run([6.0] * 4 + [5.0] * 6, [{"frames": 4}])]
    best = [run([3.0] * 10), run([4.0] * 10), run([4.5] * 10)]
    got = first_trial(auto, best)
    assert got["trial_frames"] == "2-4"
    assert got["trial_of_best"] == f"{0.75:.3f}"  # 3/6, 4/5, 4.5/6: median 0.75
    assert got["after_of_best"] == f"{0.9:.3f}"  # 3/4, 4/4, 4.5/5
    dash = {"trial_frames": "-", "trial_of_best": "-", "after_of_best": "-"}
    assert first_trial(best, best) == dash  # no trial: the default does not choose
    assert first_trial(auto, []) == dash  # the default is the best
    assert first_trial([run([5.0] * 10, [{"frames": 10}])], best[:1]) == dash  # a trial as long as the run


def test_rounds_override_each_experiments_own_and_are_checked():
    """``--rounds``: the experiments that repeat runs take it over their own numbers (3, or 1 when
    quick); below 1 it is refused at the door with the flag's name."""
    from multigpu.errors import InputError
    from multigpu.studies.runs import Settings

    assert Settings.make(False).repeat(3) == 3 and Settings.make(True).repeat(3) == 1
    assert Settings.make(False, 5).repeat(3) == 5 and Settings.make(True, 2).repeat(2) == 2
    with pytest.raises(InputError, match="--rounds must be at least 1, got 0"):
        Settings.make(False, 0)
