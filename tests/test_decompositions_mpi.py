"""Sort-last and static decompositions in the same pipeline (2-4 ranks, each run under a hard
timeout): walls bit-identical to one rank, the depth tie rule, empty parts, the outputs."""

import csv
import json

import pytest
from mpirun import SMALL, read_png, run_mpi

pytestmark = pytest.mark.mpi
FRAMES = 4
DECOMPOSITIONS = {
    "db": ["--decomposition", "db"],
    "db-static": ["--decomposition", "db", "--db-ranges", "static"],
    "bins-vdc": ["--decomposition", "bins", "--bin-pattern", "vandercorput", "--bin-size", "16"],
    "bins-scan": ["--decomposition", "bins", "--bin-pattern", "scanline", "--bin-size", "5"],
    "cross": ["--balance", "cross"],
    "shares": ["--balance", "shares"],  # learns each rank's share from the gathered times
    # the host's ranks project a slice of the bounds each into one shared array (uneven on 1x3)
    "shared-projection": ["--projection", "shared"],
    "db-shared-projection": ["--decomposition", "db", "--projection", "shared"],
    # the wide objects drawn once, depth-composited; regions by strips and by cross's pieces
    "hybrid": ["--decomposition", "hybrid"],
    "hybrid-cross": ["--decomposition", "hybrid", "--balance", "cross"],
}


def walk(tmp_path, name, grid, tile, extra=(), scene=SMALL):
    out = tmp_path / name
    args = ["walkthrough", *scene, "--frames", str(FRAMES), "--grid", f"{grid[0]}x{grid[1]}",
            "--tile", f"{tile[0]}x{tile[1]}", "--mosaic-every", "1", "--no-overlay", "--out", str(out), *extra]
    res = run_mpi(grid[0] * grid[1], args)
    assert res.returncode == 0, res.stderr[-3000:]
    return out


def frames_of(out, n=FRAMES):
    return [read_png(out / "mosaic" / f"frame_{f:05d}.png") for f in range(n)]


@pytest.fixture(scope="module")
def references(tmp_path_factory):
    """One-rank renders of the 120x96 display and of a 21x9 one (7-pixel-wide tiles on 1x3)."""
    base = tmp_path_factory.mktemp("refs")
    return {(120, 96): frames_of(walk(base, "ref", (1, 1), (120, 96))),
            (21, 9): frames_of(walk(base, "ref7", (1, 1), (21, 9)))}


GRIDS = {"1x2": ((1, 2), (60, 96)), "2x2": ((2, 2), (60, 48)), "1x3": ((1, 3), (40, 96)), "1x3-7px": ((1, 3), (7, 9))}
#: every decomposition on the 2x2 wall and on 7-pixel tiles (the hardest: pieces of a pixel or two);
#: the even 1x2 and the uneven 1x3 each for half of them, in turn (every one is met by three walls)
WALLS = [(n, g) for i, n in enumerate(DECOMPOSITIONS) for g in ("2x2", "1x3-7px", ("1x2", "1x3")[i % 2])]


@pytest.mark.parametrize(("name", "wall"), WALLS, ids=[f"{n}-{g}" for n, g in WALLS])
def test_walls_equal_one_rank_render(tmp_path, references, name, wall):
    grid, tile = GRIDS[wall]
    if name == "bins-vdc" and tile[0] < 16 and tile[1] < 16:
        pytest.skip("fewer 16-pixel bins than ranks (refused at the door, tested below)")
    out = walk(tmp_path, name, grid, tile, DECOMPOSITIONS[name])
    ref = references[(grid[1] * tile[0], grid[0] * tile[1])]
    for f, (got, want) in enumerate(zip(frames_of(out), ref)):
        assert (got == want).all(), f"frame {f}: {(got != want).any(axis=2).sum()} pixels differ"


IN_FLIGHT = ["screen", "db", "bins-vdc", "cross", "db-shared-projection", "messages", "db-messages", "hybrid",
             "hybrid-messages"]
#: every one at latency 1, and every other one at 2 too (a frame's two stages apart; the held-back
#: rank below goes to 3 with both exchanges)
LATENCIES = [(n, "1") for n in IN_FLIGHT] + [(n, "2") for n in IN_FLIGHT[::2]]


@pytest.mark.parametrize(("name", "latency"), LATENCIES)
def test_frames_in_flight_compose_what_the_strict_order_does(tmp_path, references, name, latency):
    """--latency: frames planned and drawn while earlier ones travel; every composite the same
    bit for bit (a shared segment and messages alike, depth too)."""
    extra = {**DECOMPOSITIONS, "screen": [], "messages": ["--exchange", "messages"],
             "db-messages": ["--decomposition", "db", "--exchange", "messages"],
             "hybrid-messages": ["--decomposition", "hybrid", "--exchange", "messages"]}[name]
    out = walk(tmp_path, name, (2, 2), (60, 48), [*extra, "--latency", latency, "--timeline"])
    for f, (got, want) in enumerate(zip(frames_of(out), references[(120, 96)])):
        assert (got == want).all(), f"frame {f}: {(got != want).any(axis=2).sum()} pixels differ"
    s = json.loads((out / "summary.json").read_text())
    assert s["config"]["latency"] == int(latency) and s["frames_written"] == FRAMES
    assert s["input_to_photon_ms"] > 0 and s["input_to_photon_frames"] > 0
    # --timeline: every rank's phases of the last frames, in the order each rank ran them
    from multigpu.studies.timeline import COMPONENT

    doc = json.loads((out / "timeline.json").read_text())
    assert doc["latency"] == int(latency) and len(doc["ranks"]) == 4
    for frames in doc["ranks"]:
        assert [fr["frame"] for fr in frames] == list(range(FRAMES))
        for fr in frames:
            names = [n for n, _, _ in fr["phases"]]
            assert {"plan", "render", "readback", "exchange", "display"} <= set(names) <= set(COMPONENT)
            assert all(0 <= a <= b for _, a, b in fr["phases"])
            assert names.index("readback") < names.index("display")


def test_outputs_of_each_decomposition(tmp_path):
    rows = {}
    for name in ("db", "bins-vdc"):
        out = walk(tmp_path, name, (2, 2), (60, 48), DECOMPOSITIONS[name])
        with open(out / "timings.csv") as fh:
            rows[name] = list(csv.DictReader(fh))
        s = json.loads((out / "summary.json").read_text())
        assert s["config"]["decomposition"] == name.split("-")[0]
        assert s["decomposition"]["name"] == name.split("-")[0]
        assert s["load_cv"] >= 0 and "depth_bytes_per_frame" in s
    db, bins = rows["db"], rows["bins-vdc"]
    assert sum(int(r["depth_bytes"]) for r in db) > 0  # sort-last sends depth
    assert all(int(r["depth_bytes"]) == 0 for r in bins)
    assert all(int(r["pieces"]) == 12 for r in bins)  # 8 x 6 bins of 16 px over 4 ranks
    assert len({r["load_cv"] for r in bins if r["frame"] == "0"}) == 1  # one c_v per frame
    for r in db:  # every db rank holds at most one piece: where its objects project
        assert int(r["pieces"]) <= 1


COPLANAR = """o first
v 0 0 0
v 2 0 0
v 2 2 0
v 0 2 0
f 1 2 3
f 1 3 4
o second
v 1 1 0
v 3 1 0
v 3 3 0
v 1 3 0
f 5 6 7
f 5 7 8
"""


def test_depth_ties_go_to_the_first_drawn_and_empty_parts_are_fine(tmp_path):
    """Two coplanar overlapping squares, one per rank: where they overlap, depth is equal, and
    the wall must show the square a one-rank render draws first. On 1x3 one rank owns nothing."""
    model = tmp_path / "coplanar.obj"
    model.write_text(COPLANAR)
    path = tmp_path / "look.json"
    path.write_text(json.dumps({"version": 1, "cameras": [
        {"position": [1.5, 1.5, 5.0], "target": [1.5, 1.5, 0.0], "up": [0, 1, 0], "fov": 60, "near": 0.1,
         "far": 20}] * 2}))
    scene = ["--model", str(model), "--cluster", "0", "--up", "z", "--path", str(path), "--no-progress",
             "--colors", "objects"]  # a colour per object: which square won is visible
    ref = walk(tmp_path, "one", (1, 1), (60, 30), ["--frames", "2"], scene)
    want = read_png(ref / "mosaic" / "frame_00000.png")
    # the overlap (the middle of the screen) shows one of the two colours, not the background
    mid = want[15, 30]
    assert (want != mid).any() and len({tuple(c) for c in want.reshape(-1, 3)}) >= 3
    for grid, tile in (((1, 2), (30, 30)), ((1, 3), (20, 30))):
        out = walk(tmp_path, f"db{grid[1]}", grid, tile, ["--frames", "2", "--decomposition", "db"], scene)
        got = read_png(out / "mosaic" / "frame_00000.png")
        assert (got == want).all(), f"{grid}: {(got != want).any(axis=2).sum()} pixels differ"
        with open(out / "timings.csv") as fh:
            objs = [int(r["objects"]) for r in csv.DictReader(fh) if r["frame"] == "0"]
        assert sorted(objs)[-2:] == [1, 1] and (grid[1] == 2 or 0 in objs)  # 1x3: an empty part


SLAB = 4  # a SLAB x SLAB grid of unit quads in z = 0: one object of 2 SLAB^2 triangles


def _slab_obj() -> str:
    """The slab, then four unit squares lying on it (separate components, one object)."""
    verts = [f"v {x} {y} 0" for y in range(SLAB + 1) for x in range(SLAB + 1)]
    faces = []
    for y in range(SLAB):
        for x in range(SLAB):
            a = 1 + y * (SLAB + 1) + x
            faces += [f"f {a} {a + 1} {a + SLAB + 2}", f"f {a} {a + SLAB + 2} {a + SLAB + 1}"]
    for x, y in ((0.5, 1.5), (2.5, 1.5), (1.5, 0.5), (1.5, 2.5)):
        n = len(verts) + 1
        verts += [f"v {x} {y} 0", f"v {x + 1} {y} 0", f"v {x + 1} {y + 1} 0", f"v {x} {y + 1} 0"]
        faces += [f"f {n} {n + 1} {n + 2}", f"f {n} {n + 2} {n + 3}"]
    return "\n".join(verts + faces) + "\n"


def test_hybrid_depth_ties_go_to_the_region(tmp_path):
    """A wide slab (drawn last, by a depth piece) under squares in its plane: where a square
    lies on the slab the depths tie, and the wall must show the square, as a one-rank render
    (which draws the slab last) does, on every wall."""
    from multigpu.core.drawlist import scene_order
    from multigpu.scene.models import SceneSpec, load_scene

    model = tmp_path / "slab.obj"
    model.write_text(_slab_obj())
    spec = SceneSpec(model=str(model), split="components", merge_below=0, cluster=0, up="z")
    order, wide = scene_order(load_scene(spec, use_cache=False)[0])
    assert wide.tolist() == [True, False] and order.tolist() == [1, 0]  # the slab is wide and drawn last
    path = tmp_path / "look.json"
    path.write_text(json.dumps({"version": 1, "cameras": [
        {"position": [2.0, 2.0, 5.0], "target": [2.0, 2.0, 0.0], "up": [0, 1, 0], "fov": 60, "near": 0.1,
         "far": 20}] * 2}))
    scene = ["--model", str(model), "--split", "components", "--merge-below", "0", "--cluster", "0", "--up", "z",
             "--path", str(path), "--no-progress", "--colors", "objects"]  # the slab and squares told apart
    want = read_png(walk(tmp_path, "one", (1, 1), (60, 40), ["--frames", "2"], scene) / "mosaic" / "frame_00000.png")
    assert len({tuple(c) for c in want.reshape(-1, 3)}) >= 3  # background, the slab and the squares on it
    for grid, tile in (((1, 2), (30, 40)), ((2, 2), (30, 20))):
        out = walk(tmp_path, f"hybrid{grid[0]}{grid[1]}", grid, tile, ["--frames", "2", "--decomposition", "hybrid"],
                   scene)
        got = read_png(out / "mosaic" / "frame_00000.png")
        assert (got == want).all(), f"{grid}: {(got != want).any(axis=2).sum()} pixels differ"


def test_bad_decomposition_flags_print_once(tmp_path):
    args = ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "2", "--out", str(tmp_path / "o"),
            "--decomposition", "bins", "--bin-pattern", "sudoku"]
    res = run_mpi(2, args, timeout=60)
    assert res.returncode == 2 and res.stderr.count("--bin-pattern must be one of") == 1, res.stderr


HELD = 10  # frames of the held-back runs


@pytest.fixture(scope="module")
def held_reference(tmp_path_factory):
    """One rank's render of the 120x96 display, HELD frames."""
    out = tmp_path_factory.mktemp("held") / "one"
    res = run_mpi(1, ["walkthrough", *SMALL, "--frames", str(HELD), "--grid", "1x1", "--tile", "120x96",
                      "--mosaic-every", "1", "--no-overlay", "--out", str(out)])
    assert res.returncode == 0, res.stderr[-3000:]
    return frames_of(out, HELD)


@pytest.mark.parametrize(("latency", "exchange"), [("0", "shared"), ("1", "shared"), ("2", "shared"), ("3", "shared"),
                                                   ("1", "messages"), ("3", "messages")])
def test_a_held_back_rank_composes_what_one_rank_renders(tmp_path, held_reference, latency, exchange):
    """One rank held back in every frame just before it reads its peers' parts (a sleep): the
    others run ahead as far as the loop's waits let them, and no frame they write reaches a slot
    still being read (--latency 3 with three slots put a block of another frame into a frame)."""
    out = tmp_path / "held"
    args = ["walkthrough", *SMALL, "--frames", str(HELD), "--grid", "2x2", "--tile", "60x48", "--mosaic-every",
            "1", "--no-overlay", "--out", str(out), "--latency", latency, "--exchange", exchange]
    res = run_mpi(4, args, env={"MULTIGPU_FAULT": "1:compose:sleep=0.15"})
    assert res.returncode == 0, res.stderr[-3000:]
    assert json.loads((out / "summary.json").read_text())["config"]["exchange"] == exchange
    for f, (got, want) in enumerate(zip(frames_of(out, HELD), held_reference)):
        assert (got == want).all(), f"frame {f}: {(got != want).any(axis=2).sum()} pixels differ"
