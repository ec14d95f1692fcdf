"""Does balancing pay? Frame time of every strategy against ``none`` on the plant, the city,
the paper's plants on an orbit and a scanned-style model cut into ~100 parts, alternated in
rounds with the noise floor and the ceiling it implies (``payoff``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.studies.floor import run as floor_run
from multigpu.studies.prose import prose
from multigpu.studies.runs import Settings, walk
from multigpu.studies.tables import md_table, write_csv


def orbit_copies(s: Settings) -> int:
    """Plants in the orbit scene (the paper's Section 7 setup)."""
    return 2 if s.quick else 4


def scan_triangles(s: Settings) -> int:
    """Size of the scanned-style model: ~1 M triangles (the issue's 871k-triangle scan); small
    when quick."""
    return 2 * s.triangles if s.quick else 10 * s.triangles


def scenes(s: Settings, out: Path) -> dict[str, list[str]]:
    """Scene flags of each scene: the plant walkthrough, the city drive, the paper's Section 7
    setup (plants, orbit), and a scanned-style model (``scene scan``, written into ``out``) cut
    into ~100 parts by ``--split grid:8``, on an orbit: few large objects."""
    from multigpu.scene.scan import write_scan

    copies = orbit_copies(s)
    scan = out / f"scan_{scan_triangles(s)}.ply"  # named by size: a quick run never reuses a full run's
    if not scan.exists():
        write_scan(scan, scan_triangles(s))
    return {"plant": ["--scene", "plant", "--triangles", str(s.triangles)],
            "city": ["--scene", "city", "--triangles", str(s.triangles)],
            "orbit": ["--triangles", str(s.triangles * copies), "--copies", str(copies), "--path-kind", "orbit"],
            "scan": ["--model", str(scan), "--split", "grid:8", "--path-kind", "orbit"]}


#: the balancing CPU's phases in a payoff row, from each run's summary's columns of them
PARTS = {"learn_ms": "learning_cpu_ms", "project_ms": "projection_cpu_ms", "plan_ms": "planning_cpu_ms"}


def balancing_parts(rows: list[dict], checks: list[dict]) -> list[dict]:
    """Per scene, where the balancing CPU of ``none``, the default and the best strategy goes
    (learn, project, plan: medians over rounds) and its share of the frame; ``above none``:
    the balancing CPU beyond what ``none``'s culling (projection and tile masks) costs."""
    out = []
    for c in checks:
        mine = {r["balance"]: r for r in rows if r["scene"] == c["scene"]}
        for name in dict.fromkeys(("none", c["default"], c["best"])):
            r = mine[name]
            out.append({"scene": c["scene"], "balance": name, **{k: r[k] for k in PARTS}, "lb_cpu_ms": r["lb_cpu_ms"],
                        "above_none_ms": r["lb_cpu_ms"] - mine["none"]["lb_cpu_ms"], "lb_share": r["lb_share"],
                        "project_share": r["project_ms"] / r["emulated_ms"]})
    return out


def exp_payoff(s: Settings, out: Path) -> str:
    """Emulated frame of each strategy over ``none``, same scene and path, alternated rounds."""
    rounds = s.repeat(3)
    strategies = s.strategies  # every registered strategy (quick: a few), `none` last
    runs: dict = {}
    floors: dict = {}
    out.mkdir(parents=True, exist_ok=True)
    SCENES = scenes(s, out)
    if s.quick:  # the smoke test's: a walkthrough of many objects and an orbit of few large ones
        SCENES = {k: SCENES[k] for k in ("plant", "scan")}
    for r in range(rounds):  # rounds alternate the strategies, so drift hits all alike
        for got in floor_run(SCENES, 4, min(s.frames, 120), s.timeout):
            floors.setdefault(got["scene"], []).append(got["imbalance_floor"])
        for scene, flags in SCENES.items():
            # odd rounds in reverse: a run is slower right after a heavy one (on the scan, the run
            # after `cross` by 4-6 %), so no strategy follows the same one in every round
            for name in (strategies if r % 2 == 0 else strategies[::-1]):
                run = walk(out / f"{scene}_{name}_{r}", (2, 2), (256, 256), [
                    *flags, "--frames", str(s.frames), "--balance", name, "--mosaic-every", "0"], s.timeout)
                runs.setdefault((scene, name), []).append(run)
    rows = []
    for scene in SCENES:
        none = np.median([r.summary["emulated_frame_ms"] for r in runs[(scene, "none")]])
        for name in strategies:
            rs = runs[(scene, name)]
            em = [r.summary["emulated_frame_ms"] for r in rs]
            lb = [r.summary["cpu"]["load_balancing_cpu_ms"] for r in rs]
            rows.append({"scene": scene, "objects": rs[0].summary["config"]["scene"]["objects"],
                     "triangles": rs[0].summary["config"]["scene"]["triangles"], "balance": name,
                         "emulated_ms": float(np.median(em)), "speedup_vs_none": float(none / np.median(em)),
                         "speedup_min": float(none / max(em)), "speedup_max": float(none / min(em)),
                         "imb_render": float(np.median([r.summary["imbalance_render_cpu"] for r in rs])),
                         "imb_tris": float(np.median([r.summary["imbalance_triangles"] for r in rs])),
                         "lb_cpu_ms": float(np.median(lb)), "lb_share": float(np.median(lb) / np.median(em)),
                         "cull_ms": float(np.median([r.summary["cpu"]["culling_cpu_ms"] for r in rs])),
                         "lb_cull_share": float(np.median([r.summary["balancing_share"] for r in rs])),
                         **{k: float(np.median([r.summary["cpu"][c] for r in rs])) for k, c in PARTS.items()},
                         "render_max_ms": float(np.median([r.summary["render_cpu_max_ms"] for r in rs])),
                         "render_mean_ms": float(np.median([r.summary["cpu"]["rendering_cpu_ms"] for r in rs])),
                         "fixed_ms": float(np.median([_fixed_cpu(r.summary) for r in rs])),
                         "tris_drawn": float(np.median([r.summary["triangles_per_frame"] for r in rs]))})
    write_csv(out / "payoff.csv", rows)
    bounds = [ceiling(scene, runs[(scene, "none")], float(np.median(floors[scene])),
                      max(x["speedup_vs_none"] for x in rows if x["scene"] == scene and x["balance"] != "none"))
              for scene in SCENES]
    write_csv(out / "payoff_ceiling.csv", bounds)
    ranking, verdict = rank_strategies(rows, tuple(SCENES))
    write_csv(out / "payoff_ranking.csv", ranking)
    per_round = {key: [r.summary["emulated_frame_ms"] for r in rs] for key, rs in runs.items()}
    checks = default_checks(rows, bounds, per_round)
    default = checks[0]["default"] if checks else None
    for c in checks:  # which candidates planned the default's frames (auto), round by round
        c.update(planned_by(rows, c, [_planned(r.summary) for r in runs[(c["scene"], default)]]))
        series = lambda rs: [{**r.summary, "per_frame_emulated_ms": r.emulated} for r in rs]
        c.update(first_trial(series(runs[(c["scene"], default)]),
                             series(runs[(c["scene"], c["best"])]) if c["best"] != default else []))
    write_csv(out / "payoff_default.csv", checks)
    parts = balancing_parts(rows, checks)
    write_csv(out / "payoff_balancing.csv", parts)
    return _page(s, rows, bounds, ranking, verdict, checks, rounds, parts)


def _page(s: Settings, rows, bounds, ranking, verdict: str, checks, rounds: int, parts: list[dict]) -> str:
    """The payoff section of the results page from its tables (its words: ``text/payoff.md``)."""
    SCENES = tuple(dict.fromkeys(r["scene"] for r in rows))
    return prose(
        "payoff", "section", frames=s.frames, copies=orbit_copies(s), scan_triangles=rows_of(rows, "scan")["triangles"],
        scan_objects=rows_of(rows, "scan")["objects"], rounds=rounds, verdict=verdict,
        runs=md_table(rows, [("scene", "Scene", ""), ("objects", "Objects", "d"), ("balance", "Balance", ""),
                             ("emulated_ms", "Frame (emulated) ms", ".2f"), ("speedup_vs_none", "vs none", ".2f"),
                             ("speedup_min", "min", ".2f"), ("speedup_max", "max", ".2f"),
                             ("render_max_ms", "Slowest render ms", ".2f"), ("imb_render", "Imb. render", ".3f"),
                             ("imb_tris", "Imb. tris", ".3f"), ("tris_drawn", "Tris drawn / frame", ",.0f"),
                             ("lb_cpu_ms", "LB CPU ms", ".2f"), ("lb_share", "LB share", ".1%"),
                             ("cull_ms", "Cull ms", ".2f"), ("lb_cull_share", "LB + cull share", ".1%")]),
        bounds=md_table(bounds, [("scene", "Scene", ""), ("floor", "Floor", ".3f"), ("none_ms", "none frame ms", ".2f"),
                                 ("render_mean_ms", "Mean render ms", ".2f"),
                                 ("render_max_ms", "Slowest render ms", ".2f"), ("ideal_ms", "Ideal frame ms", ".2f"),
                                 ("ceiling", "Ceiling vs none", ".2f"), ("best", "Best measured vs none", ".2f")]),
        ranking=md_table(ranking, [("balance", "Balance", ""), *[(sc, sc, ".2f") for sc in SCENES],
                                   ("geomean", "Geometric mean", ".3f"), ("worst", "Worst", ".2f")]),
        checks=md_table(checks, [("scene", "Scene", ""), ("ceiling", "Ceiling", ".2f"), ("best", "Best", ""),
                                 ("best_speedup", "Best vs none", ".2f"), ("default", "Default", ""),
                                 ("default_speedup", "Default vs none", ".2f"), ("of_best", "Default / best", ".3f"),
                                 ("of_ceiling", "Default / ceiling", ".3f"), ("meets", "Meets both", ""),
                                 ("paired_of_best", "Default / best, paired by round", ".3f"),
                                 ("paired_min", "min", ".3f"), ("paired_max", "max", ".3f")]),
        planned=md_table(checks, [("scene", "Scene", ""), ("default", "Default", ""), ("best", "Best", ""),
                                  ("by_best", "Frames planned by the best", ""),
                                  ("expected_of_best", "Expected / best", ""), ("of_best", "Default / best", ".3f"),
                                  ("trial_frames", "First trial", ""), ("trial_of_best", "Best / default in it", ""),
                                  ("after_of_best", "Best / default after it", "")]),
        gaps=md_table(checks, [("scene", "Scene", ""), ("default", "Default", ""),
                               ("gap_ms", "Frame - ideal ms", ".2f"), ("overlap_ms", "Duplicated ms", ".2f"),
                               ("imbalance_ms", "Imbalance left ms", ".2f"),
                               ("fixed_extra_ms", "Fixed extra ms", ".2f")]),
        parts=md_table(parts, [("scene", "Scene", ""), ("balance", "Balance", ""), ("learn_ms", "Learn ms", ".3f"),
                               ("project_ms", "Project ms", ".3f"), ("plan_ms", "Plan ms", ".3f"),
                               ("lb_cpu_ms", "LB CPU ms", ".3f"), ("above_none_ms", "Above none ms", "+.3f"),
                               ("lb_share", "LB share", ".1%"), ("project_share", "Project share", ".1%")]))


def default_checks(rows: list[dict], bounds: list[dict], per_round: dict | None = None) -> list[dict]:
    """Per scene: the configured default's speedup against the best strategy's and the ceiling;
    with ``per_round`` ((scene, strategy) -> emulated frame of each round), also the best's
    frame over the default's round by round (the two ran minutes apart in the same round, so
    the machine's drift between rounds cancels): median, min and max."""
    from multigpu.config import WalkConfig

    default = WalkConfig().balance
    out = []
    for b in bounds:
        mine = [r for r in rows if r["scene"] == b["scene"]]
        best = max((r for r in mine if r["balance"] != "none"), key=lambda r: r["speedup_vs_none"])
        d = next(r for r in mine if r["balance"] == default)
        of_best, of_ceiling = d["speedup_vs_none"] / best["speedup_vs_none"], d["speedup_vs_none"] / b["ceiling"]
        meets = of_best >= 0.97 and (b["ceiling"] <= 1.05 or of_ceiling >= 0.9)
        paired = {}
        if per_round is not None:
            ratio = np.divide(per_round[(b["scene"], best["balance"])], per_round[(b["scene"], default)])
            paired = {"paired_of_best": float(np.median(ratio)), "paired_min": float(ratio.min()),
                      "paired_max": float(ratio.max())}
        out.append({"scene": b["scene"], "ceiling": b["ceiling"], "best": best["balance"],
                    "best_speedup": best["speedup_vs_none"], "default": default,
                    "default_speedup": d["speedup_vs_none"], "of_best": of_best, "of_ceiling": of_ceiling,
                    "meets": "yes" if meets else "no", **paired, **gap(d, b)})
    return out


def _strategy_report(summary: dict) -> dict:
    """The strategy's report in a run's summary ({} where there is none)."""
    return (summary.get("decomposition") or {}).get("strategy") or {}


def _planned(summary: dict) -> dict:
    """Frames each candidate planned in a run of a choosing strategy (``auto``; {} for others)."""
    return _strategy_report(summary).get("frames", {}) or {}


def planned_by(rows: list[dict], check: dict, planned: list[dict]) -> dict:
    """How a choosing default spent its frames on a scene: the share it planned with the best
    strategy (median over rounds), and the frame it would have if each candidate's frames cost
    what that candidate's own runs cost (``expected``: what its choices and trial frames cost,
    run-to-run noise aside), as the best's frame over it. '-' where the default does not choose
    or the best is not one of its candidates."""
    mine = {r["balance"]: r["emulated_ms"] for r in rows if r["scene"] == check["scene"]}
    names = sorted({c for p in planned for c in p})
    if not planned or not names or check["best"] not in names or not all(c in mine for c in names):
        return {"by_best": "-", "expected_of_best": "-"}
    share = {c: float(np.median([p.get(c, 0) / max(sum(p.values()), 1) for p in planned])) for c in names}
    expected = sum(share[c] * mine[c] for c in names) / sum(share.values())
    return {"by_best": f"{share[check['best']]:.0%}", "expected_of_best": f"{mine[check['best']] / expected:.3f}"}


def first_trial(default: list[dict], best: list[dict]) -> dict:
    """Where a choosing default's frames went against the best strategy's, round by round
    (summaries paired by round): the best's mean frame over the default's on the frames of the
    default's first trial (the frames it alternated candidates on) and on the frames after it
    (medians over rounds), and the trial's length in frames. '-' where the default holds no
    trial (it does not choose) or is the best (``best`` empty)."""
    from multigpu.strategies.auto import REPORT_TRIALS

    none = {"trial_frames": "-", "trial_of_best": "-", "after_of_best": "-"}
    trials = [_strategy_report(d).get("trials") for d in default]
    if not default or len(best) != len(default) or not all(trials) or max(map(len, trials)) >= REPORT_TRIALS:
        return none  # no trial, nothing to pair, or the first trial no longer in the report
    n, during, after = [], [], []
    for d, b, t in zip(default, best, trials):
        k = int(t[0]["frames"])
        fd, fb = np.asarray(d["per_frame_emulated_ms"]), np.asarray(b["per_frame_emulated_ms"])
        if not 0 < k < min(len(fd), len(fb)):
            return none
        n.append(k)
        during.append(fb[:k].mean() / fd[:k].mean())
        after.append(fb[k:].mean() / fd[k:].mean())
    frames = f"{min(n)}" if min(n) == max(n) else f"{min(n)}-{max(n)}"
    return {"trial_frames": frames, "trial_of_best": f"{np.median(during):.3f}",
            "after_of_best": f"{np.median(after):.3f}"}


def gap(d: dict, b: dict) -> dict:
    """What stands between a strategy's frame (row ``d``) and the ideal frame (``b``), in CPU ms
    per frame: the work its partition duplicates (mean render above ``none``'s: objects drawn
    by two ranks, pieces), the imbalance it leaves (slowest render above the mean times the
    noise floor), and its fixed CPU (balancing, exchange, display) above ``none``'s. Their sum
    approximates frame - ideal (the emulated frame is a slowest rank's sum, per frame)."""
    overlap = d["render_mean_ms"] - b["render_mean_ms"]
    imbalance = d["render_max_ms"] - d["render_mean_ms"] * b["floor"]
    fixed = d["fixed_ms"] - b["fixed_ms"]
    return {"gap_ms": d["emulated_ms"] - b["ideal_ms"], "overlap_ms": overlap, "imbalance_ms": imbalance,
            "fixed_extra_ms": fixed}


def rows_of(rows: list[dict], scene: str) -> dict:
    """The first row of ``scene``."""
    return next(r for r in rows if r["scene"] == scene)


def rank_strategies(rows: list[dict], names: tuple[str, ...]) -> tuple[list[dict], str]:
    """Strategies ranked as a default should be chosen: first by the worst case over the scenes
    (a default should not make frames slower than no balancing), then by the geometric-mean
    speedup over ``none``; and a sentence on whether the configured default is the best."""
    from multigpu.config import WalkConfig

    out = []
    for name in dict.fromkeys(r["balance"] for r in rows if r["balance"] != "none"):
        sp = {r["scene"]: r["speedup_vs_none"] for r in rows if r["balance"] == name}
        vals = [sp[sc] for sc in names]
        out.append({"balance": name, **sp, "geomean": float(np.exp(np.mean(np.log(vals)))), "worst": min(vals)})
    out.sort(key=lambda r: (-r["worst"], -r["geomean"]))
    default = WalkConfig().balance
    top = max(out, key=lambda r: r["geomean"])
    mine = next(r for r in out if r["balance"] == default)
    verdict = (f"Best by worst case, then geometric mean: `{out[0]['balance']}`; best geometric mean alone: "
               f"`{top['balance']}` ({top['geomean']:.3f}). The configured default (`WalkConfig.balance`) is "
               f"`{default}`: worst case {mine['worst']:.2f}, geometric mean {mine['geomean']:.3f} in this run.")
    return out, verdict


def _fixed_cpu(summary: dict) -> float:
    """CPU ms per rank and frame outside rendering: balancing, exchange, display."""
    cpu = summary["cpu"]
    return cpu["load_balancing_cpu_ms"] + cpu["frame_exchange_cpu_ms"] + cpu["display_cpu_ms"]


def ceiling(scene: str, none_runs: list, floor: float, best: float) -> dict:
    """The most any balancer could gain over ``none`` here: ``none``'s frame with its render time
    replaced by the mean rank's render time times the noise floor (medians over rounds)."""
    med = lambda f: float(np.median([f(r.summary) for r in none_runs]))
    cpu = lambda c: med(lambda x: x["cpu"][c])
    fixed = med(_fixed_cpu)
    ideal = fixed + cpu("rendering_cpu_ms") * floor
    none_ms = med(lambda x: x["emulated_frame_ms"])
    return {"scene": scene, "floor": floor, "none_ms": none_ms, "render_mean_ms": cpu("rendering_cpu_ms"),
            "fixed_ms": fixed,
            "render_max_ms": med(lambda x: x["render_cpu_max_ms"]), "ideal_ms": ideal, "ceiling": none_ms / ideal,
            "best": best}
