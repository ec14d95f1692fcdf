"""``multigpu bench longrun``: a wall left running, its frame time and rank 0's memory over a
long run (issue 63, item 6: both must stay flat however long the run).

A job of 2 ranks on 64x64 tiles flies the plant for 100,000 frames (``--quick``: 5,000) with
the outputs that grow with a run: timings.csv and summary.json checkpoints, ``--record`` and
``--timeline``; a second job a tenth as long adds ``--video`` (its encoder takes one of this
machine's two cores, so its frames are slower from the start and it runs apart). Frame time is
wall time, each frame's period (``frame_ms``, the mean over ranks) from timings.csv, by tenths
of the run; memory is rank 0's resident set (``VmRSS``), sampled every half second while it
runs, with the frames written then (summary.json's count). Prints figures, never asserts.
"""

from __future__ import annotations

import json
import subprocess
import tempfile
import threading
from pathlib import Path

import numpy as np

from multigpu.studies.tables import Columns


def _rss(pid: int) -> int:
    """Bytes of ``pid``'s resident set (0 when gone)."""
    from multigpu.studies.memory_bench import proc_kib

    return proc_kib(pid, "status", "VmRSS:") * 1024


def _rank0(root: int) -> int | None:
    """The pid of rank 0 among the job's rank processes (MPICH's and Open MPI's rank variables)."""
    from multigpu.studies.memory_bench import _ranks

    for pid in _ranks(root):
        try:
            with open(f"/proc/{pid}/environ", "rb") as fh:
                env = fh.read().split(b"\0")
        except OSError:
            continue
        if b"PMI_RANK=0" in env or b"OMPI_COMM_WORLD_RANK=0" in env:
            return pid
    return None


def bench_longrun(quick: bool) -> list[dict]:
    """The long run with ``--record`` and ``--timeline``, then a tenth as long with ``--video``
    (its encoder takes a core of this machine's two, so it has a run of its own)."""
    frames = 5_000 if quick else 100_000
    return [_longrun(frames, ["--record", "flight.json", "--timeline"]), _longrun(frames // 10, ["--video"])]


def _longrun(frames: int, extra: list[str]) -> dict:
    from multigpu.records.report import COLUMNS, read_timings
    from multigpu.studies.runs import end, start, study_env

    out = Path(tempfile.mkdtemp(prefix="longrun-"))
    extra = [str(out / a) if a == "flight.json" else a for a in extra]
    args = ["walkthrough", "--grid", "1x2", "--tile", "64x64", "--triangles", "2000", "--frames", str(frames),
            "--mosaic-every", "0", "--no-progress", *extra, "--out", str(out)]
    print(f"\nbench longrun: 2 ranks, 1x2 wall of 64x64 tiles, {frames} frames, with {' '.join(extra)}; "
          "frame period = wall time (mean over ranks), rank 0's memory = VmRSS")
    proc = start(2, args, study_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    samples: list[tuple[int, int]] = []  # (frames written, rank 0's resident bytes)
    stop = threading.Event()

    def sample():
        pid = None
        while not stop.is_set():
            pid = pid or _rank0(proc.pid)
            try:
                done = json.loads((out / "summary.json").read_text())["frames_written"]
            except (OSError, ValueError, KeyError):
                done = 0
            if pid is not None and done and (v := _rss(pid)):
                samples.append((done, v))
            stop.wait(0.5)

    t = threading.Thread(target=sample, daemon=True)
    t.start()
    try:
        log, _ = proc.communicate(timeout=3600)
    finally:
        stop.set()
        t.join()
        end(proc)
    if proc.returncode != 0:
        raise RuntimeError(f"bench longrun: the run failed (exit {proc.returncode}): {log.strip().splitlines()[-1:]}")
    rows = read_timings(out / "timings.csv")
    period = rows[:, COLUMNS.index("frame_ms")].reshape(-1, 2).mean(axis=1)
    tenths = np.array_split(period[10:], 10)  # past the first frames' warm-up
    done = np.array([d for d, _ in samples])
    mem = np.array([v for _, v in samples], dtype=np.float64) / 2**20
    table = Columns(("tenth", "tenth", "6d"), ("frames", "frames", ">8"), ("median_ms", "median ms", "10.3f"),
                    ("p99_ms", "p99 ms", "8.3f"), ("max_ms", "max ms", "8.2f"), ("mean_ms", "mean ms", "8.3f"),
                    ("rss_mib", "rank 0 MiB", "11.1f"))
    print(table.header())
    result = {"frames": int(period.size), "tenths": []}
    first = 10
    for i, p in enumerate(tenths):
        m = mem[(done >= first) & (done < first + p.size)]  # sampled while these frames were written
        row = {"frames": f"{first}-{first + p.size - 1}", "median_ms": float(np.median(p)),
               "p99_ms": float(np.percentile(p, 99)), "max_ms": float(p.max()), "mean_ms": float(p.mean()),
               "rss_mib": float(np.median(m)) if m.size else float("nan")}
        first += p.size
        result["tenths"].append(row)
        print(table.row({**row, "tenth": i + 1}))
    a, b = result["tenths"][0], result["tenths"][-1]
    flight = json.loads((out / "flight.json").read_text()) if (out / "flight.json").exists() else None
    result.update({"mean_last_over_first": b["mean_ms"] / a["mean_ms"],
                   "p99_last_over_first": b["p99_ms"] / a["p99_ms"],
                   "rss_last_minus_first_mib": b["rss_mib"] - a["rss_mib"],
                   "summary_bytes": (out / "summary.json").stat().st_size})
    print(f"last tenth over first: mean frame {result['mean_last_over_first']:.2f}x, p99 "
          f"{result['p99_last_over_first']:.2f}x; rank 0's memory {result['rss_last_minus_first_mib']:+.1f} MiB; "
          f"summary.json {result['summary_bytes']} bytes"
          + (f"; --record holds {len(flight['cameras'])} frames" if flight else "")
          + (f"; video {(out / 'mosaic.mp4').stat().st_size / 2**20:.1f} MiB" if "--video" in extra else ""))
    subprocess.run(["rm", "-rf", str(out)], check=False)
    return result
