"""Rank 0's records written whole (``records/report.py``: the timing rows and the JSON files;
``records/record.py``: the run's record): a write that fails part way keeps what came before
it and names the file."""

import errno
import os

import numpy as np
import pytest

from multigpu.errors import WriteFailed
from multigpu.records.report import COLUMNS, TimingWriter, read_timings, write_json


def test_timing_rows_are_whole_after_a_failed_write(tmp_path, monkeypatch):
    """A write that fails part way (disk full) leaves the file at the last whole frame."""
    w = TimingWriter(tmp_path / "timings.csv")
    rows = np.arange(2 * len(COLUMNS), dtype=float).reshape(2, len(COLUMNS))
    rows[:, COLUMNS.index("balance")] = [0, 1]  # by name in the file, its index when read back
    w.write(rows)
    real = os.pwrite

    def half_then_full(fd, data, offset):
        if len(data) > 20:
            real(fd, data[:len(data) // 2], offset)
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data, offset)

    monkeypatch.setattr(os, "pwrite", half_then_full)
    with pytest.raises(WriteFailed, match="cannot write .*timings.csv: No space left on device; kept .* bytes"):
        w.write(rows)
    monkeypatch.setattr(os, "pwrite", real)
    later = rows.copy()
    later[:, 0] += 200
    w.write(later)  # the run could go on: appends after the last whole frame
    w.close()
    got = read_timings(tmp_path / "timings.csv")
    assert got.shape == (4, len(COLUMNS))
    assert (got[2:, 0] == rows[:, 0] + 200).all()
    assert (got[:, COLUMNS.index("balance")] == [0, 1, 0, 1]).all()
    lines = (tmp_path / "timings.csv").read_text().splitlines()[1:]
    names = [line.split(",")[COLUMNS.index("balance")] for line in lines]
    assert names == ["strips", "cost"] * 2


def test_json_write_failure_leaves_no_temp_file(tmp_path, monkeypatch):
    from pathlib import Path

    def full(self, target):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "replace", full)
    with pytest.raises(WriteFailed, match=f"cannot write {tmp_path / 'summary.json'}: No space left"):
        write_json(tmp_path / "summary.json", {"a": 1})
    from multigpu.records.mosaic import save_png

    with pytest.raises(WriteFailed, match="f.png: No space left"):
        save_png(np.zeros((4, 4, 3), np.uint8), tmp_path / "f.png")
    assert list(tmp_path.iterdir()) == []


def test_a_recorded_path_that_cannot_be_written_is_the_runs_failure(tmp_path, monkeypatch):
    """``--record``'s file failing (disk full): the record names it (``failed``, which
    ends the job with one line and exit 2), timings and summary are still written whole, and
    the printout claims no recorded frames."""
    import io
    from contextlib import redirect_stdout

    from multigpu.records.outdir import OutputDir
    from multigpu.records.record import RunRecord
    from multigpu.scene.pathfile import PathAppender

    def full(self, data, frames):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(PathAppender, "_write", full)
    record = RunRecord(OutputDir(tmp_path / "o"), 1, 2, {}, lambda: None, False, False, False,
                       str(tmp_path / "rec.json"))
    rows = np.ones((1, len(COLUMNS)))
    for f in range(2):
        record.camera(type("C", (), {"position": (0, 0, 1), "target": (0, 0, 0), "up": (0, 1, 0), "fov": 60.0,
                                     "near": 0.1, "far": 10.0})())
        rows[0, 0] = f
        record.rows(f, rows)
    summary = record.close(True, None)
    assert str(record.failed) == f"cannot write {tmp_path / 'rec.json'}: No space left on device"
    assert summary["frames"] == 2 and read_timings(tmp_path / "o" / "timings.csv").shape == (2, len(COLUMNS))
    assert not (tmp_path / "rec.json").exists()
    out = io.StringIO()
    with redirect_stdout(out):
        record.print_table(summary, "t")
    assert "camera path" not in out.getvalue()


def _video_in_subprocess(tmp_path, limit: int, frames: int) -> str:
    """Write ``frames`` noise frames through ``record.Video`` under a file-size limit (ffmpeg
    inherits it, as from a full disk); what the writer raised, or 'ok'."""
    import subprocess
    import sys

    code = f"""
import resource, numpy as np
from pathlib import Path
from multigpu.errors import WriteFailed
from multigpu.records.record import Video
resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
v = Video(Path({str(tmp_path / 'v.mp4')!r}))
rng = np.random.default_rng(0)
try:
    for _ in range({frames}):
        v.append(rng.integers(0, 255, (96, 128, 3), dtype=np.uint8))
    v.close()
    print('ok')
except WriteFailed as exc:
    print('WriteFailed:', exc)
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    return res.stdout.strip()


def test_a_video_cut_short_is_a_failed_write_and_a_whole_one_is_not(tmp_path):
    """A truncated mp4 (ffmpeg out of room) once ended the run with exit 0: its encoder exits
    quietly. ``Video`` counts the frames back and names the file; a whole video passes."""
    got = _video_in_subprocess(tmp_path, 5000, 40)
    assert got.startswith(f"WriteFailed: cannot write {tmp_path / 'v.mp4'}: "), got
    assert len(got.splitlines()) == 1
    assert _video_in_subprocess(tmp_path, 1 << 30, 12) == "ok"


def test_a_video_frame_the_encoder_refuses_stops_the_run_as_a_failed_write(tmp_path, monkeypatch):
    """The encoder's own error on a frame (imageio raises its own types) is kept as the run's
    failed write, so every rank stops after the next frame; nothing more is written."""
    from multigpu.rank.framelog import FrameLog
    from multigpu.records.outdir import OutputDir
    from multigpu.records.record import RunRecord

    record = RunRecord(OutputDir(tmp_path / "o"), 1, 2, {}, lambda: None, True, False, False)

    def broken(img):
        raise OSError("[Errno 32] Broken pipe\n\nFFMPEG COMMAND:\nffmpeg ...")

    monkeypatch.setattr(record.video.writer, "append_data", broken)
    log = FrameLog.__new__(FrameLog)
    log.record = record
    log.write(record.image, 0, np.zeros((48, 64, 3), dtype=np.uint8), [], False)
    assert str(record.failed) == f"cannot write {tmp_path / 'o' / 'mosaic.mp4'}: [Errno 32] Broken pipe"
    record.close(False, "an output could not be written (rank 0)")


@pytest.mark.parametrize("decomposition", ["screen", "db", "bins", "hybrid"])
def test_a_run_is_titled_and_summarized_by_what_divides_its_frames(decomposition):
    """The title and summary.json's ``balance`` follow the decomposition: hybrid balances its
    regions with ``--balance`` (it was titled "db (... ranges)" with no balance)."""
    from types import SimpleNamespace

    from multigpu.config import WalkConfig
    from multigpu.decompositions import REGISTRY
    from multigpu.records.record import config_doc, run_title

    cfg = WalkConfig(decomposition=decomposition, balance="cross")
    scene = SimpleNamespace(name="plant", n_triangles=10, n_objects=2, meta={})
    place = [{"host": "a", "egl_device": None}]
    doc = config_doc(cfg, scene, {"seconds": 0.0, "cached": False}, 4, place, "scissor")
    title = run_title(cfg, scene)
    assert title.split("), ")[-1].split()[0].startswith(("balance=", decomposition))
    if decomposition in ("screen", "hybrid"):
        assert REGISTRY[decomposition].balanced and doc["balance"] == "cross" and "balance=cross" in title
    else:
        assert not REGISTRY[decomposition].balanced and doc["balance"] is None and "balance" not in title
    assert ("hybrid" in title) == (decomposition == "hybrid") and ("db (" in title) == (decomposition == "db")
