"""Balancing strategies: the fill term, the cost model's term selection, time feedback."""

import numpy as np
import pytest

from multigpu.core.balance import partition, tree_partition
from multigpu.core.regions import pixel_spans
from multigpu.core.splits import fill_prefix, strip_chooser
from multigpu.strategies import (
    REGISTRY,
    Adaptive,
    CostModel,
    CrossSegment,
    TimeFeedback,
    describe,
    make_strategy,
    rank_pixels,
)


def workload(n=400, seed=0):
    rng = np.random.default_rng(seed)
    lo = rng.random((n, 2)) * 0.9
    size = rng.exponential(0.05, (n, 2))
    rects = np.c_[lo, np.minimum(lo + size, 1.0)]
    tris = rng.integers(10, 500, n)
    return rects, tris


def test_zero_fill_equals_triangle_balancing():
    rects, tris = workload()
    a = partition(rects, tris, (2, 2), (256, 256), 64)
    b = partition(rects, tris, (2, 2), (256, 256), 64, fill=0.0)
    np.testing.assert_array_equal(a.regions, b.regions)


def test_fill_prefix_matches_brute_force_raster():
    rects, tris = workload(60, seed=2)
    W, H = 64, 48
    density = np.random.default_rng(3).random(60)
    seen = {}

    def spy(t, spans):
        if t.n == 0:
            seen["f"] = fill_prefix(t, spans, density)
            seen["t"] = t
        return strip_chooser()(t, spans)

    tree_partition(rects, tris, (1, 2), (W, H), 16, spy)
    spans, on = pixel_spans(rects, (W, H))
    grid = np.zeros((H, W))
    for i in np.flatnonzero(on):
        x0, y0, x1, y1 = spans[i]
        grid[y0:y1 + 1, x0:x1 + 1] += density[i] / (x1 - x0 + 1) * (x1 - x0 + 1)
    below, total = seen["f"]
    cols = grid.sum(axis=0)
    expect = np.array([cols[:c].sum() for c in seen["t"].cuts])
    np.testing.assert_allclose(below, expect, rtol=1e-9)
    assert total == pytest.approx(cols.sum())


def test_fill_term_moves_split_towards_pixels():
    # left: one huge object with 10 triangles; right: 100 tiny objects with 100 triangles each
    rects = np.array([[0.0, 0.0, 0.5, 1.0]] + [[0.9, 0.5, 0.901, 0.501]] * 100)
    tris = np.array([10] + [100] * 100)
    tri_only = partition(rects, tris, (1, 2), (1000, 100), 1000)
    with_fill = partition(rects, tris, (1, 2), (1000, 100), 1000, fill=10000 / 50000)
    assert tri_only.split_pixels[0] > 890  # triangles pull the cut onto the cluster
    assert with_fill.split_pixels[0] < tri_only.split_pixels[0] - 300


def test_bad_fill_raises():
    rects, tris = workload(10)
    with pytest.raises(ValueError, match="fill"):
        partition(rects, tris, (2, 2), (64, 64), 16, fill=-1.0)


def test_rank_pixels_counts_clipped_rect_areas():
    rects = np.array([[0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 0.25, 0.25]])
    vis = np.array([[True, True], [True, False]])
    regions = np.array([[0, 0, 4, 8], [4, 0, 8, 8]])
    px = rank_pixels(rects, vis, regions, (8, 8))
    assert px.tolist() == [32 + 9, 32]  # inclusive spans: a rect touching pixel 2 covers columns 0..2


def simulate(strategy, rects, tris, time_of, frames=30):
    parts = []
    for f in range(frames):
        p = strategy.plan(rects, tris, np.ones(len(tris)) if strategy.needs_coverage else None)
        strategy.observe(f, p, time_of(p))
        parts.append(p)
    return parts


def _times(rects, tris, a, b, c, size):
    def time_of(p):
        px = rank_pixels(rects, p.visible, p.regions, size)
        return a * (p.visible @ tris) + b * px + c
    return time_of


def test_cost_model_learns_a_fill_bound_scene_and_beats_triangles():
    # fill-bound synthetic: big low-poly rects on the left, a dense high-poly cluster on the right
    rng = np.random.default_rng(0)
    big = np.c_[rng.uniform(0, 0.2, 20), rng.uniform(0, 0.2, 20), rng.uniform(0.3, 0.5, 20), rng.uniform(0.8, 1, 20)]
    lo = rng.uniform(0.6, 0.95, (300, 2))
    small = np.c_[lo, lo + 0.01]
    rects = np.r_[big, small]
    tris = np.r_[np.full(20, 12), np.full(300, 400)]
    size = (512, 512)
    time_of = _times(rects, tris, 1e-4, 2e-5, 1.0, size)
    cost = CostModel((2, 2), size, 512)
    parts = simulate(cost, rects, tris, time_of)
    strips = make_strategy("strips", (2, 2), size, 512).plan(rects, tris)
    imb = lambda t: t.max() / t.mean()
    assert "pixels" in cost.report()["terms"]
    assert imb(time_of(parts[-1])) < imb(time_of(strips)) / 1.5


def test_cost_model_drops_pixels_on_a_triangle_bound_scene():
    rects, tris = workload(500, seed=4)
    size = (512, 512)
    time_of = _times(rects, tris, 1e-3, 0.0, 0.5, size)
    cost = CostModel((2, 2), size, 512)
    parts = simulate(cost, rects, tris, time_of)
    assert cost.report()["terms"] == ["triangles"]
    strips = partition(rects, tris, (2, 2), size, 512)
    np.testing.assert_array_equal(parts[-1].regions, strips.regions)


def test_time_feedback_converges_and_tiles():
    rects, tris = workload(500, seed=5)
    size = (256, 256)
    # a hidden cost: the right half of the screen costs 4x per object
    heavy = (rects[:, 0] > 0.5).astype(float) * 3 + 1
    time_of = lambda p: p.visible.astype(float) @ (tris * heavy) * 1e-3
    parts = simulate(TimeFeedback((2, 2), size, 256), rects, tris, time_of, frames=25)
    strips = partition(rects, tris, (2, 2), size, 256)
    imb = lambda t: t.max() / t.mean()
    assert imb(time_of(parts[-1])) < imb(time_of(strips))
    for p in parts:
        r = p.regions
        assert ((r[:, 2] - r[:, 0]) * (r[:, 3] - r[:, 1])).sum() == 256 * 256


def test_registry_and_unknown_name():
    assert set(REGISTRY) == {"strips", "cost", "time", "adaptive", "cross", "shares", "auto", "none", "static"}
    assert all(name in describe() for name in REGISTRY)
    with pytest.raises(ValueError, match="unknown balancing strategy"):
        make_strategy("magic", (2, 2), (64, 64), 16)


def test_static_holds_the_first_frames_split_while_the_load_moves():
    """``--balance static``: frame 0 is the paper's split; later frames keep its regions (only the
    objects each needs change), so a load that moves leaves it unbalanced where strips follows."""
    from multigpu.strategies.static import Static

    size = (256, 256)
    rects, tris = workload(600, seed=7)
    for compiled in (False, True):
        static = Static((2, 2), size, 256, compiled=compiled)
        first = static.plan(rects, tris)
        want = partition(rects, tris, (2, 2), size, 256, compiled=compiled)
        assert (first.regions == want.regions).all() and (first.visible == want.visible).all()
        moved = rects.copy()
        moved[:, [0, 2]] = moved[:, [0, 2]] * 0.4  # the load gathers at the left
        held = static.plan(moved, tris)
        follows = partition(moved, tris, (2, 2), size, 256, compiled=compiled)
        assert (held.regions == first.regions).all() and not (follows.regions == first.regions).all()
        spans, onscreen = pixel_spans(moved, size)  # which objects each held region needs now
        for k, (x0, y0, x1, y1) in enumerate(held.regions):
            need = onscreen & (spans[:, 0] < x1) & (spans[:, 2] >= x0) & (spans[:, 1] < y1) & (spans[:, 3] >= y0)
            assert (held.visible[k] == need).all() and held.loads[k] == tris[need].sum()
        assert held.loads.max() / held.loads.mean() > follows.loads.max() / follows.loads.mean()
        assert static.report()["held_split_pixels"] == first.split_pixels.tolist()


def test_adaptive_learns_a_per_object_cost_the_model_cannot_see():
    """Objects in one corner cost 5x per triangle (say, an expensive shader): triangles and
    pixels cannot express it, the per-object correction can; two copies agree bit for bit."""
    rects, tris = workload(600, seed=6)
    size = (256, 256)
    heavy = np.where((rects[:, 0] > 0.5) & (rects[:, 1] > 0.5), 5.0, 1.0)
    time_of = lambda p: p.visible.astype(float) @ (tris * heavy) * 1e-3 + 0.2
    runs = [simulate(Adaptive((2, 2), size, 256), rects, tris, time_of, frames=30) for _ in range(2)]
    cost = simulate(CostModel((2, 2), size, 256), rects, tris, time_of, frames=30)
    imb = lambda t: t.max() / t.mean()
    assert imb(time_of(runs[0][-1])) < 0.8 * imb(time_of(cost[-1]))
    assert imb(time_of(runs[0][-1])) < 1.15
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a.regions, b.regions)
    for p in runs[0]:
        assert p.loads.dtype.kind == "i"  # loads stay triangle counts
        np.testing.assert_array_equal(p.loads, p.visible @ tris)


@pytest.mark.parametrize("name", list(REGISTRY))
def test_every_registered_strategy_keeps_the_contract(name):
    """Each strategy: a Strategy, partitions that tile the display with consistent loads and
    masks, a JSON-able report naming it; reproducible ones repeat themselves bit for bit."""
    import json

    from multigpu.strategies import Strategy

    rects, tris = workload(300, seed=7)
    size = (192, 128)
    heavy = np.where(rects[:, 0] > 0.6, 3.0, 1.0)
    time_of = lambda p: p.visible.astype(float) @ (tris * heavy) * 1e-3 + 0.1
    runs = []
    for _ in range(2):
        strategy = REGISTRY[name]((2, 3), size, 64)
        assert isinstance(strategy, Strategy) and strategy.name == name
        runs.append(simulate(strategy, rects, tris, time_of, frames=12))
        doc = strategy.report()
        assert doc["name"] == name and json.loads(json.dumps(doc)) == doc
    from multigpu.core.work import from_partition, pieces_tile_display

    for p in runs[0]:
        assert pieces_tile_display(from_partition(p, tris), size)
        if p.pieces is None:
            np.testing.assert_array_equal(p.loads, p.visible @ tris)
        if p.pieces is None:  # one rect per rank: the walk's spans come along (the cost model reads them)
            assert p.spans is not None and p.spans.shape == (4, len(tris))
        else:  # cross-segment pieces keep none (nothing reads them)
            assert p.spans is None
    if REGISTRY[name].reproducible:
        for a, b in zip(*runs):
            np.testing.assert_array_equal(a.regions, b.regions)
            np.testing.assert_array_equal(a.visible, b.visible)


@pytest.mark.parametrize("cross_cost", [0.5, 2.0])
def test_auto_keeps_the_candidate_whose_frames_were_faster_and_checks_again(cross_cost):
    """Frames planned by cross (pieces) cost ``cross_cost`` times strips' frames: the trial picks
    the faster (after one mirrored pair of rounds: without noise the lead is clear at once), the
    winner plans every frame of the hold, the next trial decides again; two copies fed the same
    times decide alike."""
    from multigpu.strategies.auto import Auto

    rects, tris = workload(300, seed=11)
    time_of = lambda p: np.full(4, cross_cost if p.pieces is not None else 1.0)
    runs = []
    for _ in range(2):
        auto = Auto((2, 2), (128, 128), 64, window=4, settle=1, rounds=4, hold=10)
        trial = 2 * auto.round_frames
        cycle = trial + auto.hold
        runs.append(simulate(auto, rects, tris, time_of, frames=2 * cycle))
    want = "cross" if cross_cost < 1 else "strips"
    doc = auto.report()
    assert doc["using"] == want and [t["chose"] for t in doc["trials"]] == [want, want]
    assert [t["frames"] for t in doc["trials"]] == [trial] * 2  # one pair each: clear
    assert doc["trials"][0]["scores_ms"] == {"cross": cross_cost, "strips": 1.0}  # settled frames only
    assert doc["trials"][0]["scored"] == [6, 6]
    # the windows: cross, strips, then strips, cross (mirrored; a window's second frame: cross's
    # first plan ever has no pieces to learn from yet)
    assert [p.pieces is not None for p in runs[0][1:trial:auto.window]] == [True, False, False, True]
    # a re-check starts with the candidate in use: cross, strips, strips, cross only if cross won
    again = [p.pieces is not None for p in runs[0][cycle + 1:cycle + trial:auto.window]]
    assert again == ([True, False, False, True] if want == "cross" else [False, True, True, False])
    for start in (0, cycle):  # the winner holds after each trial
        held = runs[0][start + trial:start + cycle]
        assert all((p.pieces is not None) == (want == "cross") for p in held)
    assert doc["frames"]["cross"] + doc["frames"]["strips"] == len(runs[0])
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a.regions, b.regions)


def test_auto_holds_a_confirmed_choice_longer_and_a_new_one_briefly():
    """Re-checks that keep the candidate in use double the hold after them, up to ``max_hold``;
    a re-check that switches (the scene's winner changed) restores ``hold``."""
    from multigpu.strategies.auto import Auto

    rects, tris = workload(200, seed=15)
    frame = [0]

    def time_of(p):  # strips faster until frame 150, cross after it
        frame[0] += 1
        slow = (p.pieces is not None) == (frame[0] <= 150)
        return np.full(4, 2.0 if slow else 1.0)

    auto = Auto((2, 2), (128, 128), 64, window=4, settle=1, rounds=4, hold=10, max_hold=40)
    simulate(auto, rects, tris, time_of, frames=260)
    trials = auto.report()["trials"]
    # 16-frame trials (one mirrored pair: the lead is clear), then: hold 10, 20, 40, 40 (capped)
    assert [(t["chose"], t["hold"]) for t in trials[:4]] == [("strips", h) for h in (10, 20, 40, 40)]
    assert ("cross", 10) in [(t["chose"], t["hold"]) for t in trials[4:]]  # the switch: a short hold again
    with pytest.raises(ValueError, match="max_hold"):
        Auto((2, 2), (128, 128), 64, hold=10, max_hold=5)


@pytest.mark.parametrize("lead, rounds", [(0.5, 2), (0.01, 4)])
def test_auto_ends_a_trial_early_only_on_a_clear_lead(lead, rounds):
    """Noisy times (sd 0.1): strips ahead by ``lead``. A lead of five standard deviations ends
    the trial after the first mirrored pair of rounds; one far inside the noise runs every
    round, and the scores say how many frames each candidate was scored on."""
    from multigpu.strategies.auto import Auto

    rects, tris = workload(200, seed=12)
    rng = np.random.default_rng(3)
    time_of = lambda p: np.full(4, (1.0 + lead if p.pieces is not None else 1.0) + 0.1 * rng.standard_normal())
    auto = Auto((2, 2), (128, 128), 64, window=6, settle=1, rounds=4, hold=5)
    simulate(auto, rects, tris, time_of, frames=auto.trial_frames + 1)
    t = auto.report()["trials"][0]
    assert t["frames"] == rounds * auto.round_frames and t["scored"] == [5 * rounds] * 2
    if rounds == 2:
        assert t["chose"] == "strips"


@pytest.mark.parametrize("trend, ahead", [(0.01, "strips"), (-0.01, "cross")])
def test_auto_trials_are_fair_to_both_candidates_on_a_moving_path(trend, ahead):
    """Every frame costs ``trend`` more than the last (the camera turning towards or away from
    the heavy part of a scene), and ``ahead`` is faster by less than the trend adds between two
    windows: scored in mirrored rounds the trend costs both the same and ``ahead`` wins (in plain
    alternation, cross going first, a rising trend would favour cross and a falling one strips)."""
    from multigpu.strategies.auto import Auto

    rects, tris = workload(200, seed=13)
    frame = [0]

    def time_of(p):
        frame[0] += 1
        faster = (p.pieces is None) == (ahead == "strips")
        return np.full(4, 2.0 + trend * frame[0] - (0.02 if faster else 0.0))

    auto = Auto((2, 2), (128, 128), 64, window=4, settle=1, rounds=2, hold=5)
    simulate(auto, rects, tris, time_of, frames=auto.trial_frames + 1)
    t = auto.report()["trials"][0]
    other = "cross" if ahead == "strips" else "strips"
    assert t["chose"] == ahead and t["scores_ms"][ahead] < t["scores_ms"][other]


@pytest.mark.parametrize("ahead, drop", [("strips", True), ("cross", False)])
def test_auto_scores_frames_against_their_load_through_a_step(ahead, drop):
    """Half the scene leaves the view (``drop``) or comes into it during the trial, after the
    middle windows of a mirrored pair (a step, not a trend: the walkthrough turning a corner).
    ``ahead`` is 10 % faster at any load, yet by raw mean times the other would win, its frames
    lying on the light side of the step. Scored against each frame's triangles in view,
    ``ahead`` wins, with the load slope the times have (1: time proportional to load)."""
    from multigpu.strategies.auto import Auto

    rects, tris = workload(400, seed=14)
    half = rects.copy()
    half[::2] = np.nan  # the half that leaves or enters the view
    before, after = (rects, half) if drop else (half, rects)
    # windows: cross 0-3, strips 4-7, strips 8-11, cross 12-15; the step after frame 11
    auto = Auto((2, 2), (128, 128), 64, window=4, settle=1, rounds=2, hold=5)
    for f in range(auto.trial_frames + 1):
        r = before if f < 12 else after
        p = auto.plan(r, tris)
        faster = (p.pieces is None) == (ahead == "strips")
        in_view = tris[~np.isnan(r[:, 0])].sum()
        auto.observe(f, p, np.full(4, in_view * 1e-3 * (0.9 if faster else 1.0)))
    t = auto.report()["trials"][0]
    other = "cross" if ahead == "strips" else "strips"
    assert t["chose"] == ahead and t["scores_ms"][ahead] < t["scores_ms"][other]
    assert t["load_slope"] == pytest.approx(1.0, abs=1e-6)
    assert t["frames"] == 2 * auto.round_frames  # no noise: clear after the first pair


def test_auto_picks_cross_where_a_cost_hides_from_triangle_counts():
    """Objects in one corner cost 5x per triangle: strips, balancing triangles, leaves that
    rank slow; cross follows the measured times, and auto settles on it."""
    from multigpu.strategies.auto import Auto

    rects, tris = workload(600, seed=6)
    heavy = np.where((rects[:, 0] > 0.5) & (rects[:, 1] > 0.5), 5.0, 1.0)

    def time_of(p):
        masks = p.piece_visible or p.visible[:, None, :]
        return np.array([(m.astype(float) @ (tris * heavy)).sum() for m in masks]) * 1e-3

    auto = Auto((2, 2), (256, 256), 256)
    simulate(auto, rects, tris, time_of, frames=auto.trial_frames + 5)
    t = auto.report()["trials"][0]
    assert t["chose"] == "cross" and t["scores_ms"]["cross"] < t["scores_ms"]["strips"]


def test_rank_pixels_uses_the_partition_spans():
    rects, tris = workload(200, seed=8)
    p = partition(rects, tris, (2, 2), (128, 128), 64)
    np.testing.assert_array_equal(rank_pixels(rects, p.visible, p.regions, (128, 128)),
                                  rank_pixels(rects, p.visible, p.regions, (128, 128), spans=p.spans))


@pytest.mark.parametrize("compiled", [False, True])
def test_cross_segment_load_moves_with_the_objects(compiled):
    """The weighted time model weighs this frame's rects: when the objects move from the right
    tile into the left one, the left segment gets more of the ranks in that same frame, before
    any time is measured for it. Equalizer's uniform model (a rank's last time spread over its
    last pixels) moves nothing until the times come."""
    from multigpu.strategies.cross import CrossSegment

    rng = np.random.default_rng(3)
    size, n = (200, 100), 400
    lo = rng.random((n, 2)) * [0.95, 0.9]
    spread = np.concatenate([lo, lo + 0.05], axis=1)
    left = spread * [0.5, 1.0, 0.5, 1.0]  # the same objects squeezed into the left tile
    tris = np.full(n, 100)
    shares = {}
    for model in ("weighted", "uniform"):
        cross = CrossSegment((1, 2), size, 64, compiled=compiled, model=model, damping=0.0)
        for f in range(3):  # spread evenly, equal times: the segments' shares settle at one rank each
            cross.observe(f, cross.plan(spread, tris), np.ones(2))
        assert np.allclose(cross.shares, 1.0, atol=0.05), model
        cross.plan(left, tris)
        shares[model] = cross.shares.copy()
    # the left tile is the first segment (labels column-major)
    assert shares["weighted"][0] > 1.5 > shares["uniform"][0] and np.allclose(shares["uniform"], 1.0, atol=0.05)


@pytest.mark.parametrize("compiled", [False, True])
def test_cross_segment_helpers_take_at_least_min_help(compiled):
    """Nearly even loads leave every segment's share near one rank: with ``min_help`` 0 the
    view equalizer's layout gives a neighbour slivers of a segment (a render pass each); with
    the default no rank helps a segment with less than ``min_help`` of its unit, unless it is
    the segment's only helper, and the pieces still tile the display."""
    from multigpu.core.work import from_partition, pieces_tile_display

    rects, tris = workload(400, seed=21)
    size = (128, 128)
    rng = np.random.default_rng(5)
    time_of = lambda p: 1.0 + 0.08 * rng.standard_normal(4)  # even loads, noisy times

    def overlaps(strategy, part):
        """(its unit's overlap with the segment, ranks drawing it) per rank drawing a segment."""
        order = list(strategy.order)
        start = np.zeros(len(order))
        start[strategy.order] = np.r_[0.0, np.cumsum(strategy.shares[strategy.order])[:-1]]
        area = lambda p, t: max(min(p[2], t[2]) - max(p[0], t[0]), 0) * max(min(p[3], t[3]) - max(p[1], t[1]), 0)
        got = []
        for t, tile in enumerate(strategy.tiles):
            ranks = [r for r, pieces in enumerate(part.pieces)
                     if any(area(p, tile) > 0 for p in np.asarray(pieces).reshape(-1, 4))]
            lo, hi = start[t], start[t] + strategy.shares[t]
            got += [(min(order.index(r) + 1, hi) - max(order.index(r), lo), len(ranks)) for r in ranks]
        return got

    smallest = {}
    for min_help in (0.0, 0.1):
        cross = CrossSegment((2, 2), size, 64, compiled=compiled, min_help=min_help)
        seen = []
        for f in range(40):
            part = cross.plan(rects, tris)
            if f:
                assert pieces_tile_display(from_partition(part, tris), size)
                seen += [u for u, ranks in overlaps(cross, part) if ranks > 1]
            cross.observe(f, part, time_of(part))
        smallest[min_help] = min(seen)
    assert smallest[0.0] < 0.05  # slivers without the rule
    assert smallest[0.1] >= 0.1


@pytest.mark.parametrize("compiled", [False, True])
def test_cross_segment_pieces_of_a_row_join_into_one_pass_per_rank(compiled):
    """On a one-row wall the resource axis runs along the row and every segment is cut across
    x, its helpers on their own side: whatever the shares, each rank's pieces join into one
    rect (one render pass), and the pieces still tile the display. On a 2x2 wall, the help
    along each row joins the same way (most ranks render one rect)."""
    from multigpu.core.work import from_partition, pieces_tile_display

    rects, tris = workload(500, seed=23)
    rng = np.random.default_rng(8)
    for grid, size in (((1, 4), (256, 64)), ((2, 2), (128, 128))):
        cross = CrossSegment(grid, size, 64, compiled=compiled, min_help=0.0)
        single, shared = [], 0
        for f in range(30):
            part = cross.plan(rects, tris)
            cross.observe(f, part, rng.uniform(0.5, 3.0, 4))  # shares far from even
            if f:
                assert pieces_tile_display(from_partition(part, tris), size)
                single += [len(p) == 1 for p in part.pieces]
                own = [len(p) == 1 and np.array_equal(np.asarray(p)[0], t) for p, t in zip(part.pieces, cross.tiles)]
                shared += not all(own)  # some rank drew more or less than its own tile
        if grid == (1, 4):
            assert all(single)
        else:
            assert np.mean(single) > 0.6
        assert shared  # the shares moved pieces between ranks


def test_cross_segment_moves_resources_to_the_heavy_segment():
    """Objects pile up in one display tile: the view equalizer gives that segment more than one
    rank's share, its helpers render pieces of it, and time imbalance falls below `none`."""
    rng = np.random.default_rng(9)
    lo = np.c_[rng.uniform(0.0, 0.45, 500), rng.uniform(0.55, 0.95, 500)]  # top-left tile (rank 0)
    rects = np.r_[np.c_[lo, lo + 0.02], np.c_[rng.uniform(0, 0.95, (100, 2)), rng.uniform(0, 0.95, (100, 2)) + 0.03]]
    rects[:, 2:] = np.maximum(rects[:, 2:], rects[:, :2])
    tris = np.full(len(rects), 100)
    size = (256, 256)

    def time_of(p):
        return np.array([(m.astype(float) @ tris).sum() for m in (p.piece_visible or p.visible[:, None, :])]) * 1e-3

    parts = simulate(CrossSegment((2, 2), size, 256), rects, tris, time_of, frames=20)
    last = parts[-1]
    cross = CrossSegment((2, 2), size, 256)
    assert last.pieces is not None
    helpers = [k for k in range(4) if any(((r[:2] >= [0, 128]) & (r[2:] <= [128, 256])).all() for r in last.pieces[k])]
    assert len(helpers) >= 2  # the crowded top-left segment (rank 0's tile) is shared
    none = make_strategy("none", (2, 2), size, 256).plan(rects, tris)
    imb = lambda t: t.max() / t.mean()
    assert imb(time_of(last)) < 0.8 * imb(time_of(none))
    assert cross.report()["name"] == "cross"


def test_cross_time_model_weighs_objects_their_draws_and_their_cover():
    """An object weighs its triangles, ``object_weight`` times the mean triangles per on-screen
    object and ``cover_weight`` times the triangles per covered pixel on each pixel of its rect:
    over the whole display the objects weigh their triangles times (1 + object_weight +
    cover_weight), whatever their layout, and a small object draws no less than its own draw."""
    from multigpu.core.regions import pixel_spans
    from multigpu.strategies.cross import _density, _mass

    rng = np.random.default_rng(4)
    size = (120, 80)
    rects, tris = workload(300, seed=4)
    rects[:20] = np.nan  # off screen
    tris = rng.integers(0, 500, len(rects))
    spans, on = pixel_spans(rects, size)
    total = float(tris[on].sum())
    for pw, ow, cw in ((0.0, 0.0, 0.0), (0.5, 1.0, 1.0), (0.0, 2.5, 0.0), (0.0, 0.0, 2.5)):
        model = _density(spans, on, tris, size, pw, ow, cw, False)
        beta = model[2]
        assert beta == pytest.approx(pw * total / (size[0] * size[1]))
        whole = _mass(model, (0, 0, *size)) - beta * size[0] * size[1]
        assert whole == pytest.approx(total * (1 + ow + cw), rel=1e-9)
    # two objects: 10 triangles over 10x10 pixels, 30 on one pixel
    spans = np.array([[0, 0, 9, 9], [20, 20, 20, 20]])
    on, two = np.ones(2, dtype=bool), np.array([10, 30])
    _, d, _ = _density(spans, on, two, (64, 64), 0.0, 1.0, 0.0, False)
    np.testing.assert_allclose(d * [100, 1], [10 + 20, 30 + 20])  # each plus the mean object's 20
    _, d, _ = _density(spans, on, two, (64, 64), 0.0, 0.0, 1.0, False)
    np.testing.assert_allclose(d - [0.1, 30.0], 40 / 101)  # 40 triangles over 101 covered pixels


@pytest.mark.parametrize("weight", ["pixel_weight", "object_weight", "cover_weight"])
@pytest.mark.parametrize("bad", [-0.5, float("nan"), float("inf")])
def test_cross_time_model_weights_are_checked(weight, bad):
    from multigpu.strategies.cross import CrossSegment

    with pytest.raises(ValueError, match=weight):
        CrossSegment((2, 2), (128, 128), 64, **{weight: bad})


def test_shares_learn_a_slow_rank_and_settle_where_times_are_equal():
    """A simulated 2x2 wall whose rank 0 takes twice the time per triangle: the shares learn it
    from the times alone, and the times of the plans made with them come out near equal."""
    from multigpu.strategies.shares import Shares

    rng = np.random.default_rng(4)
    n = 3000
    lo = rng.random((n, 2))
    rects = np.c_[lo, lo + rng.exponential(0.01, (n, 2))]
    tris = rng.integers(1, 40, n)
    speed = np.array([0.5, 1.0, 1.0, 1.0])
    s = Shares((2, 2), (512, 512), 256)
    first = s.plan(rects, tris)
    spread = []
    for f in range(40):
        p = s.plan(rects, tris)
        times = 0.2 + p.loads / speed / 1e4  # a fixed cost, and rank 0 at half speed
        spread.append(times.max() / times.mean())
        s.observe(f, p, times * rng.lognormal(0, 0.03, 4))
    assert (s.plan(rects, tris).regions != first.regions).any()
    assert s.shares[0] < 0.7 * s.shares[1:].min()  # rank 0 learnt as the slow one
    assert spread[0] > 1.3 and max(spread[-10:]) < 1.08
    assert abs(np.log(s.shares).mean()) < 1e-9 and s.report()["shares"][0] < 1.0
    before = s.shares.copy()
    s.observe(41, p, np.array([1.0, 0.0, 1.0, 1.0]))  # a rank without a time: nothing learnt
    s.observe(42, p._replace(features=None), np.array([9.0, 1.0, 1.0, 1.0]))  # nor from a plan not its own
    assert (s.shares == before).all()


def test_auto_tries_shares_instead_of_strips_on_big_walls():
    from multigpu.strategies.auto import BIG_WALL, Auto

    for grid, second in (((2, 2), "strips"), ((3, 3), "shares"), ((4, 4), "shares")):
        assert [c.name for c in Auto(grid, (192, 192), 64).candidates] == ["cross", second]
        assert (grid[0] * grid[1] >= BIG_WALL) == (second == "shares")
