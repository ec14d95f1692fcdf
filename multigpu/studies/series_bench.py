"""``multigpu bench series``: a simulation's time series on the wall against one still step of it.

The series: a deforming surface (a travelling wave over a grid of quads) of about 1 M triangles a
step (100 k with ``--quick``), coloured by its height, written once as VTU files into
``out/series/data/`` (kept: later runs reuse them). Its steps' caches are built first, as a second
play of a series finds them. Headless 2x2 walls of 256x256 tiles (4 ranks) walk the same orbit:

1. **Never stalls**: the series played at a new step every 10 frames (``--steps-per-second 3``,
   the wall never waiting; ``PASSES`` times over) against the same walk on its first step alone
   (``--range`` the series'), alternated over rounds. The frame time is each frame's period (wall
   time between frames shown, the slowest rank's); its 99th percentile and median, the emulated
   frame (the slowest rank's phase CPU time, per frame) and the frames that showed a step late.
2. **Memory**: the host's peak proportional set size (every rank's ``Pss`` summed) of the series
   against the still step, and the difference in steps' worth (one step: its cached scene and GL
   buffers file, which the host's page cache holds once).
3. **Against ParaView** (``bench peer``'s pair, where ``pvbatch`` and Open MPI are installed): the
   same series on 4 ranks, the same orbit and 512x512 canvas, colour map and steps at the same
   frames (``pvbatch --symmetric``, IceT compositing, one reader of the step files; multigpu with
   ``--late-step wait``: every step at its frames, as ParaView shows them), alternated; wall time
   per frame (ParaView: rank 0's loop; multigpu: the frame period) and the slowest rank's CPU.
4. **Live**: the example simulation (``examples/simulation/heat.py``, a 96x96 plate, a step every
   0.1 s) streaming over SST to a 2x2 wall, at ``--latency 0`` (a window wall's) and 1 (a headless
   run's default); from each step's write (the writer's stamp) to the first frame that shows it (the
   run's own summary: ``series.delay_ms_median``), split into the part before rank 0 had read the
   step (the transfer), the keeping (until rank 0 had it made for the wall, to be sent at the next
   frame's start: ``rank/pushed.py``) and the rest, in ms and in frames of the run's median period.

Results in ``out/series/`` (``series.csv``). Figures only, no asserts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.studies.tables import write_csv

OUT = Path("out/series")
#: a new step every 10 frames of the path (30 frames a second of scene time)
RATE = 3.0
#: the stall part's walks play the series this many times over (it loops: ``--at-end loop``), so
#: that a run's 99th percentile stands on some 360 frames (on 120, it is the second slowest frame)
PASSES = 3


def write_steps(where: Path, n_side: int, steps: int) -> Path:
    """``steps`` VTU files of an ``n_side`` x ``n_side`` grid surface (2 (n-1)^2 triangles), kept."""
    import meshio

    where.mkdir(parents=True, exist_ok=True)
    done = where / f"done-{n_side}-{steps}"
    if done.exists():
        return where
    for old in (*where.glob("step_*.vtu"), *where.glob("done-*")):
        old.unlink()
    x, y = np.meshgrid(np.linspace(0, 4, n_side), np.linspace(0, 4, n_side))
    idx = np.arange(n_side * n_side).reshape(n_side, n_side)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    for k in range(steps):
        z = 0.3 * np.sin(2 * np.pi * (0.5 * x + 0.08 * k)) * np.cos(2 * np.pi * (0.3 * y - 0.05 * k))
        meshio.write(where / f"step_{k:03d}.vtu", meshio.Mesh(np.c_[x.ravel(), y.ravel(), z.ravel()], [("quad", quads)],
                                                              point_data={"height": z.ravel()}), binary=True)
    done.write_text("")
    return where


def _flags(data: Path, arm: str, frames: int, lo: float, hi: float) -> list[str]:
    model = str(data / "step_*.vtu") if arm == "series" else str(data / "step_000.vtu")
    return ["--model", model, "--color-by", "height", f"--range={lo!r},{hi!r}", "--steps-per-second", str(RATE),
            "--frames", str(frames), "--path-kind", "orbit", "--mosaic-every", "0"]


def _warm(data: Path, steps: int, frames: int, lo: float, hi: float) -> None:
    """Every step's cache built as the walks read them (a series' second play)."""
    from multigpu.flags import joined_negatives, walk_config, walkthrough_parser
    from multigpu.rank.series import load_step

    args = ["--grid", "2x2", "--tile", "256x256", *_flags(data, "series", frames, lo, hi)]
    spec = walk_config(walkthrough_parser().parse_args(joined_negatives(args))).scene
    for k in range(steps):
        load_step(spec, k)


def _measure(run) -> dict:
    """A walk's frame period (the slowest rank's, per frame), emulated frame and late frames."""
    period = run.col("frame_ms").max(axis=1)[1:]  # the first frame's period is its setup's
    series = run.summary.get("series", {})
    return {"p99_frame_ms": float(np.percentile(period, 99)), "median_frame_ms": float(np.median(period)),
            "emulated_ms": float(np.median(run.emulated)), "late_frames": float(series.get("late_frames", 0)),
            "steps_shown": float(series.get("steps_shown", 1))}


def bench_series(quick: bool) -> list[dict]:
    from multigpu.scene.series import find_series, series_range
    from multigpu.studies.memory_bench import measure
    from multigpu.studies.runs import alternated, medians, walk

    n_side, steps, rounds = (225, 6, 1) if quick else (708, 12, 3)
    frames = 10 * steps
    data = write_steps(OUT / "data", n_side, steps)
    tris = 2 * (n_side - 1) ** 2
    lo, hi, _ = series_range(find_series(str(data / "step_*.vtu")), "height")
    print(f"bench series: {steps} steps of {tris:,} triangles, a step every 10 frames; 2x2 walls of 256x256 "
          f"(4 ranks), {rounds} alternated round(s); frame = the slowest rank's period (wall time), emulated = "
          "its phase CPU per frame (ms)")
    _warm(data, steps, frames, lo, hi)
    got = alternated(("still", "series"), rounds,
                     lambda arm, folder: _measure(walk(folder, (2, 2), (256, 256),
                                                       _flags(data, arm, PASSES * frames, lo, hi), 3600)))
    rows = []
    for arm in ("still", "series"):
        m = medians(got[arm])
        ratio = float(np.median([s["p99_frame_ms"] / t["p99_frame_ms"] for s, t in zip(got["series"], got["still"])]))
        rows.append({"part": "stall", "arm": arm, "triangles": tris, "steps": steps, **m,
                     "p99_ratio": ratio if arm == "series" else 1.0})
        print(f"  {arm:>6}: frame p99 {m['p99_frame_ms']:.1f} ms, median {m['median_frame_ms']:.1f} ms, emulated "
              f"{m['emulated_ms']:.1f} ms; {m['steps_shown']:.0f} steps shown, {m['late_frames']:.0f} frames late")
    print(f"  the series' p99 frame is {rows[1]['p99_ratio']:.3f}x the still step's")
    from multigpu.scene.models import cache_dir

    cache = str(cache_dir())  # the walks' own: every step built already
    mib = {}
    for arm in ("still", "series"):
        mib[arm] = measure(4, 0, cache, frames, scene=_flags(data, arm, frames, lo, hi)[:-4])["peak_pss_host"] / 2**20
    step_mib = _step_mib(data, frames, lo, hi)
    extra = (mib["series"] - mib["still"]) / step_mib
    rows.append({"part": "memory", "arm": "series", "triangles": tris, "steps": steps, "still_mib": mib["still"],
                 "series_mib": mib["series"], "step_mib": step_mib, "extra_steps": extra})
    print(f"  memory (peak PSS, host): series {mib['series']:.0f} MiB against {mib['still']:.0f} MiB still: "
          f"{extra:+.2f} steps' worth (a step: {step_mib:.0f} MiB of cached scene and GL buffers)")
    rows += against_paraview(data, frames, lo, hi, rounds)
    rows += [row for latency in (0, 1) for row in live(300 if quick else 900, latency)]
    OUT.mkdir(parents=True, exist_ok=True)
    keys = sorted({k for r in rows for k in r}, key=lambda k: (k not in ("part", "arm"), k))
    write_csv(OUT / "series.csv", [{k: r.get(k, "") for k in keys} for r in rows])
    print(f"results in {OUT}/series.csv")
    return rows


def against_paraview(data: Path, frames: int, lo: float, hi: float, rounds: int, ranks: int = 4,
                     size: tuple[int, int] = (512, 512)) -> list[dict]:
    """Part 3: ParaView and multigpu playing the same series, alternated (none where ParaView or
    Open MPI is missing: said in a line)."""
    import json
    import subprocess
    import sys
    import tempfile

    from multigpu.display.xvfb import start_xvfb, stop_xvfb
    from multigpu.errors import InputError
    from multigpu.studies.peer import _tools, multigpu, paraview

    try:
        pvbatch, mpiexec = _tools()
    except InputError as exc:
        print(f"  against ParaView: not measured ({exc})")
        return []
    files = [str(p.resolve()) for p in sorted(data.glob("step_*.vtu"))]
    scene = ["--model", str(data.resolve() / "step_*.vtu"), "--color-by", "height", f"--range={lo!r},{hi!r}",
             "--steps-per-second", str(RATE), "--late-step", "wait"]
    got: dict = {"paraview": [], "multigpu": []}
    env = {"LP_NUM_THREADS": "1"}
    xvfb, display = start_xvfb((size[0] + 16, size[1] + 16))  # Debian's ParaView draws through GLX only
    try:
        with tempfile.TemporaryDirectory(prefix="multigpu-series-peer-") as tmp:
            cams, steps = Path(tmp) / "cameras.json", Path(tmp) / "steps.json"
            steps.write_text(json.dumps(files))
            made = subprocess.run([sys.executable, "-m", "multigpu", "path", "make", "orbit", "--model", files[0],
                                   "--frames", str(frames), "--out", str(cams)], capture_output=True, text=True,
                                  timeout=1800)
            if made.returncode != 0:
                raise RuntimeError(f"bench series: the camera path could not be made\n{made.stderr[-1500:]}")
            for _ in range(rounds):  # alternated
                got["paraview"].append(paraview(pvbatch, mpiexec, ranks, cams, str(steps), size, Path(tmp),
                                                {**env, "DISPLAY": display}, 3600, ("height", lo, hi, RATE)))
                got["multigpu"].append(multigpu(mpiexec, ranks, cams, scene, size, Path(tmp), env, 3600, []))
    finally:
        stop_xvfb(xvfb)
    med = {k: {m: float(np.median([r[m] for r in v])) for m in ("wall_ms", "cpu_ms")} for k, v in got.items()}
    lead = med["paraview"]["wall_ms"] / med["multigpu"]["wall_ms"]
    cpu = med["paraview"]["cpu_ms"] / med["multigpu"]["cpu_ms"]
    print(f"  against ParaView (pvbatch + IceT), {ranks} ranks, {size[0]}x{size[1]}: wall "
          f"{med['paraview']['wall_ms']:.1f} against {med['multigpu']['wall_ms']:.1f} ms a frame ({lead:.2f}x), "
          f"slowest rank's CPU {med['paraview']['cpu_ms']:.1f} against {med['multigpu']['cpu_ms']:.1f} ms ({cpu:.2f}x)")
    return [{"part": "paraview", "arm": arm, "ranks": ranks, "wall_ms": m["wall_ms"], "cpu_ms": m["cpu_ms"],
             "wall_lead": lead, "cpu_lead": cpu} for arm, m in med.items()]


def live(frames: int, latency: int) -> list[dict]:
    """Part 4: the example simulation streamed live to a 2x2 wall at ``--latency latency``; the
    delays from its summary and timings."""
    import subprocess
    import sys
    import tempfile
    import time

    from multigpu.studies.runs import end, walk

    heat = Path(__file__).resolve().parents[2] / "examples" / "simulation" / "heat.py"
    with tempfile.TemporaryDirectory(prefix="multigpu-live-") as tmp:
        sim = subprocess.Popen([sys.executable, str(heat), "--name", f"{tmp}/heat", "--steps", "100000", "--every",
                                "0.1"], cwd=tmp, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
        try:
            for _ in range(600):  # the writer's contact file: the stream is there
                if Path(f"{tmp}/heat.sst").exists():
                    break
                time.sleep(0.05)
            run = walk(Path(tmp) / "wall", (2, 2), (256, 256),
                       ["--model", f"adios2:{tmp}/heat", "--color-by", "temperature", "--range", "0,1", "--frames",
                        str(frames), "--path-kind", "orbit", "--mosaic-every", "0", "--latency", str(latency)], 1800)
        finally:
            end(sim)  # its whole session
    sr = run.summary["series"]
    transfer, kept = (_median_stamped(run.col(c)[:, 0]) for c in ("step_transfer_ms", "step_kept_ms"))
    period, delay = run.summary["frame_ms_median"], sr["delay_ms_median"]
    print(f"  live (SST, heat.py 96x96, a step every 0.1 s, --latency {latency}): {sr['delays']} steps shown; write "
          f"to first frame {delay:.0f} ms median: the transfer {transfer:.1f} ms, the keeping (rank 0 has it made "
          f"for the wall) {kept - transfer:.1f} ms, then {(delay - kept) / period:.1f} frames of {period:.1f} ms "
          f"({(delay - transfer) / period:.1f} after the transfer)")
    return [{"part": "live", "arm": f"sst-latency{latency}", "steps_shown": sr["delays"], "delay_ms": delay,
             "transfer_ms": transfer, "kept_ms": kept, "frame_ms": period,
             "delay_frames_after_transfer": (delay - transfer) / period,
             "delay_frames_after_keeping": (delay - kept) / period}]


def _median_stamped(values: np.ndarray) -> float:
    """The median of a stamped step's figures (0 where no step was stamped)."""
    got = values[values > 0]
    return float(np.median(got)) if got.size else 0.0


def _step_mib(data: Path, frames: int, lo: float, hi: float) -> float:
    """One step's worth: its cached scene and GL buffers file (MiB)."""
    from multigpu.flags import joined_negatives, walk_config, walkthrough_parser
    from multigpu.gpu.buffers import buffers_path
    from multigpu.scene.models import load_scene

    args = ["--grid", "2x2", "--tile", "256x256", *_flags(data, "series", frames, lo, hi)]
    spec = walk_config(walkthrough_parser().parse_args(joined_negatives(args))).scene
    _, info = load_scene(spec)
    cache = Path(info["cache"])
    return (cache.stat().st_size + buffers_path(cache).stat().st_size) / 2**20
