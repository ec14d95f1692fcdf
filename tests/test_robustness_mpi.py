"""Bad input ends the whole job with one clear line; a failing rank ends it fast; nothing lost."""

import csv
import json
import time

import pytest

from mpirun import SMALL, run_mpi

pytestmark = pytest.mark.mpi


@pytest.mark.parametrize("flags,needle", [
    (["--strips", "1"], "--strips must be >= 2"),
    (["--tile", "0x5"], "--tile must be positive"),
    (["--grid", "two"], "--grid must look like"),
    (["--frames", "0"], "--frames must be >= 1"),
    (["--balance", "magic"], "--balance must be one of"),
    (["--model", "/nonexistent/m.obj"], "file not found"),
    (["--path", "/nonexistent/p.json"], "path file not found"),
    (["--out", "/proc/multigpu-cannot-write"], "not writable"),
    (["--device", "99"], "--device 99"),
])
def test_bad_input_matrix(tmp_path, flags, needle):
    args = ["walkthrough", *SMALL, "--grid", "1x2", "--frames", "2", "--out", str(tmp_path / "o"), *flags]
    args = args[:args.index("--grid")] + args[args.index("--grid") + 2:] if "--grid" in flags else args
    res = run_mpi(2, args, timeout=90)
    assert res.returncode != 0
    assert needle in res.stderr, res.stderr[-2000:]
    assert "Traceback" not in res.stderr
    assert res.stderr.count("multigpu: error:") == 1


def test_corrupt_model_and_bad_path_file(tmp_path):
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"glTF\x02\x00\x00\x00garbage")
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--model", str(bad), "--out", str(tmp_path / "o")])
    assert res.returncode != 0 and "bad.glb" in res.stderr and "Traceback" not in res.stderr
    p = tmp_path / "p.json"
    p.write_text(json.dumps({"keyframes": [{"position": [0, 0, 0]}]}))
    res = run_mpi(2, ["walkthrough", *SMALL, "--grid", "1x2", "--path", str(p), "--out", str(tmp_path / "o")])
    assert res.returncode != 0 and "missing the field 'target'" in res.stderr


def test_exception_on_one_rank_ends_job_and_keeps_frames(tmp_path):
    out = tmp_path / "o"
    t = time.monotonic()
    res = run_mpi(3, ["walkthrough", *SMALL, "--grid", "1x3", "--frames", "40", "--mosaic-every", "0",
                      "--out", str(out)], timeout=60, env={"MULTIGPU_FAULT": "1:6"})
    assert time.monotonic() - t < 30
    assert res.returncode != 0
    assert "rank 1: RuntimeError: injected fault at frame 6" in res.stderr
    with open(out / "timings.csv") as fh:
        rows = list(csv.DictReader(fh))
    frames = {int(r["frame"]) for r in rows}
    assert set(range(6)) <= frames and len(rows) >= 6 * 3
    s = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else None
    assert s is None or s["complete"] is False
