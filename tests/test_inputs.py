"""Bad inputs named at the door, in one process: path files, model files, odd file kinds,
and outputs written whole (issue: reliability, round two)."""

import json
import os
import warnings

import pytest

from multigpu.errors import InputError, check_file
from multigpu.scene.models import SceneSpec, load_scene
from multigpu.scene.paths import load_path


def _path_file(tmp_path, text):
    p = tmp_path / "p.json"
    p.write_text(text)
    return p


KEYS = [{"position": [0, 0, 0], "target": [1, 0, 0]}, {"position": [0, 1, 0], "target": [1, 1, 0]}]


@pytest.mark.parametrize("doc,needle", [
    ('{"frames": %s, "keyframes": %s}' % ("9" * 400, json.dumps(KEYS)), "field 'frames' must be an integer"),
    ('{"frames": 1000000000000, "keyframes": %s}' % json.dumps(KEYS),
     "field 'frames' must be an integer in 1..10000000"),
    ('{"frames": 1e12, "keyframes": %s}' % json.dumps(KEYS), "field 'frames' must be an integer"),
    ('{"keyframes": [{"position": [%s, 0, 0], "target": [1, 0, 0]}]}' % ("1" * 400),
     "position must be 3 finite numbers"),
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ('{"fov": %s, "keyframes": %s}' % ("9" * 5000, json.dumps(KEYS)), "not a camera path"),
])
def test_path_file_errors_name_file_and_field(tmp_path, doc, needle):
    p = _path_file(tmp_path, doc)
    with pytest.raises(InputError) as e:
        load_path(p)
    assert needle in str(e.value) and str(p) in str(e.value)
    assert "\n" not in str(e.value) and len(str(e.value)) < 400


def test_interpolated_eye_meeting_target_is_refused_at_the_door(tmp_path):
    """Each keyframe is valid; the spline puts the eye on the target at frame 1 of 3."""
    from multigpu.scene.paths import check_cameras

    keys = [{"position": [0, 0, 0], "target": [2, 0, 0]}, {"position": [2, 0, 0], "target": [0, 0, 0]}]
    path = load_path(_path_file(tmp_path, json.dumps({"frames": 3, "keyframes": keys})))
    with pytest.raises(InputError, match=r"frame 1 of 3: the eye meets the target"):
        check_cameras(path, "p.json")
    ok = load_path(_path_file(tmp_path, json.dumps({"frames": 4, "keyframes": keys})))
    check_cameras(ok, "p.json")  # t = 0, 1/3, 2/3, 1 never meets


def test_seed_must_be_non_negative():
    with pytest.raises(InputError, match="seed must be >= 0, got -1") as e:
        SceneSpec(seed=-1)
    assert e.value.field == "seed" and str(e.value) == "--seed must be >= 0, got -1"


def test_odd_file_kinds_say_what_they_are(tmp_path):
    (tmp_path / "d.obj").mkdir()
    os.symlink(tmp_path / "loop2.obj", tmp_path / "loop1.obj")
    os.symlink(tmp_path / "loop1.obj", tmp_path / "loop2.obj")
    os.mkfifo(tmp_path / "fifo.obj")
    cases = {tmp_path / "d.obj": "is a directory", tmp_path / "loop1.obj": "symbolic link loop",
             "/dev/null": "is a character device", tmp_path / "fifo.obj": "is a named pipe",
             tmp_path / "none.obj": "model file not found"}
    for path, needle in cases.items():
        with pytest.raises(InputError) as e:
            load_scene(SceneSpec(model=str(path)), use_cache=False)
        assert needle in str(e.value) and str(e.value).startswith("--model ")
    with pytest.raises(InputError, match="is a directory, not a path file") as e:
        load_path(tmp_path / "d.obj")
    assert str(e.value).startswith("--path ")


def test_check_file_passes_regular_files(tmp_path):
    f = tmp_path / "ok.obj"
    f.write_text("v 0 0 0\n")
    assert check_file(f, "--model") == f


PLY = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n{verts}3 0 1 {last}\n")


def test_ply_face_index_out_of_range(tmp_path):
    p = tmp_path / "bad.ply"
    p.write_text(PLY.format(verts="0 0 0\n1 0 0\n0 1 0\n", last=7))
    with pytest.raises(InputError, match=r"bad.ply: a face uses vertex index 7, but the file has 3 vertices"):
        load_scene(SceneSpec(model=str(p)), use_cache=False)


def test_model_beyond_float_range_is_one_clear_error_without_warnings(tmp_path):
    p = tmp_path / "far.obj"
    p.write_text("v 1e300 0 0\nv -1e300 1 0\nv 0 0 1e300\nf 1 2 3\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any RuntimeWarning fails the test
        with pytest.raises(InputError, match=r"far.obj: coordinates reach 1e\+300, beyond \+-1e\+15"):
            load_scene(SceneSpec(model=str(p)), use_cache=False)


def test_latin1_text_models_load(tmp_path):
    obj = tmp_path / "caf\u00e9.obj"
    obj.write_bytes("# mod\xe8le caf\xe9\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".encode("latin-1"))
    stl = tmp_path / "s.stl"
    stl.write_bytes("solid pi\xe8ce\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                    "endloop\nendfacet\nendsolid\n".encode("latin-1"))
    for f in (obj, stl):
        scene, _ = load_scene(SceneSpec(model=str(f)), use_cache=False)
        assert scene.n_triangles == 1


@pytest.mark.parametrize("suffix", [".obj", ".stl", ".off"])
def test_garbage_text_models_say_so(tmp_path, suffix):
    p = tmp_path / f"junk{suffix}"
    p.write_bytes(b"\x00\x01 garbage \xff\xfe nonsense\nxx yy zz\n" * 5)
    with pytest.raises(InputError) as e:
        load_scene(SceneSpec(model=str(p)), use_cache=False)
    msg = str(e.value)
    assert msg.startswith(f"--model {p}") and "charset" not in msg and "module" not in msg
    assert ("no triangles" in msg or f"cannot read as {suffix[1:].upper()}" in msg
            or "not a complete binary STL" in msg)


def test_record_into_a_directory_that_takes_no_files_is_refused_at_the_door(tmp_path):
    from multigpu.rank.walkthrough import check_record

    for path, needle in [("/proc/x.json", "--record /proc/x.json: cannot write in /proc"),
                         (str(tmp_path / "no" / "x.json"), "does not exist"),
                         (str(tmp_path), "is a directory")]:
        with pytest.raises(InputError) as e:
            check_record(path)
        assert needle in str(e.value)
    check_record(str(tmp_path / "ok.json"))
    assert list(tmp_path.iterdir()) == []  # the probe left nothing


@pytest.mark.parametrize("flags,needle", [
    (["--strips", "1"], "--strips must be >= 2"),
    (["--tile", "0x5"], "--tile must be positive"),
    (["--grid", "two"], "--grid must look like"),
    (["--frames", "0"], "--frames must be >= 1"),
    (["--balance", "magic"], "--balance must be one of strips, cost, time, adaptive, cross, shares, auto, none"),
    (["--subfrustum", "tiles"], "--subfrustum must be one of"),
    (["--partition", "gossip"], "--partition must be one of redundant, broadcast, got 'gossip'"),
    (["--exchange", "pigeon"], "--exchange must be one of auto, messages, shared"),
    (["--projection", "pigeon"], "--projection must be one of each, shared"),
    (["--cluster", "-3"], "--cluster must be >= 0"),
    (["--cluster", "lots"], "--cluster must be 'auto' or a number"),
    (["--offset", "1e8,x"], "--offset must look like X,Y,Z"),
    (["--offset", "1e300,0,0"], "--offset must be three finite numbers"),
    (["--seed", "-1"], "--seed must be >= 0"),
    (["--up", "q"], "--up must be one of x, y, z"),
    (["--split", "halves"], "--split must be 'auto', 'components' or 'grid:N'"),
    (["--liveness", "-1"], "--liveness must be >= 0"),
    (["--timeout", "0"], "--timeout must be > 0"),
    (["--device", "-2"], "--device must be >= 0"),
    (["--mosaic-every", "-1"], "--mosaic-every must be >= 0"),
    (["--latency", "-1"], "--latency must be 0..3 frames, got -1"),
    (["--latency", "4"], "--latency must be 0..3 frames, got 4"),
    (["--path-kind", "spiral"], "--path-kind must be one of walkthrough, orbit"),
    (["--scene", "moon"], "--scene must be one of plant, fill"),
])
def test_walkthrough_flags_are_validated_at_the_door(flags, needle):
    """Every flag's bad value, in one process, as the CLI prints it (the MPI path prints the
    same text once: test_robustness_mpi.test_errors_print_once_and_exit_together)."""
    from multigpu.cli import build_parser, walk_config

    args = build_parser().parse_args(["walkthrough", *flags])
    with pytest.raises(InputError) as e:
        walk_config(args)
    assert needle in str(e.value)


def test_setup_stage_errors_name_their_flag(tmp_path):
    """Checks that need the file system or GL: output directory, files, device, GL limits."""
    from multigpu.gpu.render import choose_method, create_context, gl_limits
    from multigpu.records.outdir import OutputDir

    for make, needle in [
        (lambda: OutputDir("/proc/multigpu-cannot-write"), "--out /proc/multigpu-cannot-write: not writable"),
        (lambda: load_scene(SceneSpec(model="/nonexistent/m.obj")), "--model /nonexistent/m.obj: model file not found"),
        (lambda: load_path("/nonexistent/p.json"), "--path /nonexistent/p.json: path file not found"),
        (lambda: create_context(99), "--device 99: this machine has"),
    ]:
        with pytest.raises(InputError) as e:
            make()
        assert needle in str(e.value)
    ctx, _ = create_context()
    with pytest.raises(InputError) as e:
        choose_method("scissor", (16384 * 4, 64), gl_limits(ctx))
    assert "--subfrustum scissor: a 65536x64 display exceeds this GL's maximum framebuffer" in str(e.value)
    ctx.release()


@pytest.mark.parametrize("flags,needle", [
    (["--decomposition", "sortlast"], "--decomposition must be one of screen, db, bins"),
    (["--decomposition", "bins", "--bin-pattern", "sudoku"], "--bin-pattern must be one of scanline, diagonal"),
    (["--decomposition", "bins", "--bin-size", "0"], "--bin-size must be 1..4096"),
    (["--decomposition", "bins", "--bin-size", "4000", "--tile", "64x64"], "fewer than the 4 ranks"),
    (["--decomposition", "bins", "--bin-size", "1", "--tile", "512x512"], "at most 65536"),
    (["--decomposition", "db", "--db-ranges", "random"], "--db-ranges must be one of visible, static"),
    (["--decomposition", "db", "--partition", "broadcast"], "--partition broadcast works with --decomposition screen"),
])
def test_decomposition_flags_are_validated_at_the_door(flags, needle):
    from multigpu.cli import build_parser, walk_config

    with pytest.raises(InputError) as e:
        walk_config(build_parser().parse_args(["walkthrough", *flags]))
    assert needle in str(e.value)


def test_bench_floor_sizes_are_checked_in_one_line(capsys):
    from multigpu.cli import main

    assert main(["bench", "floor", "--tile", "0"]) == 2
    assert main(["bench", "floor", "--tile", "64", "--display", "32"]) == 2
    err = capsys.readouterr().err
    assert err.count("--tile must be >= 1 and --display >= the tile") == 2 and len(err.strip().splitlines()) == 2


def test_bench_floor_ranks_are_counts_or_one_line():
    from multigpu.studies.bench import ranks_list as _ranks_list

    assert _ranks_list("4,9,16") == [4, 9, 16] and _ranks_list("4") == [4]
    for bad in ("x", "", "4,0", "4,,9"):
        with pytest.raises(InputError, match="--ranks must be rank counts"):
            _ranks_list(bad)


def test_bench_name_help_shows_that_benchmarks_own_flags(capsys):
    from multigpu.cli import main

    assert main(["bench", "floor", "--help"]) == 0
    floor = capsys.readouterr().out
    assert "multigpu bench floor" in floor and "--tile" in floor and "--model" not in floor
    assert main(["bench", "textures", "--help"]) == 0
    tex = capsys.readouterr().out
    assert "--quick" in tex and "--ranks" not in tex and "textured" in tex
