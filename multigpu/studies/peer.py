"""``multigpu bench peer``: multigpu beside ParaView (``pvbatch``, IceT compositing) on the same
model, cameras and image size, both under the same Open MPI, alternated, so the comparison is
made in one run on one machine.

ParaView runs ``pvbatch --symmetric`` (every rank runs the script and times its own CPU) over
the model read, spread over the ranks (``RedistributeDataSet``) and shown with ParaView's
default lights in a W x H view; each frame sets the camera of the path file and calls ``Render`` (IceT composites
on every render in parallel). multigpu runs the walkthrough over the same path file: one rank a
1x1 wall of W x H, four ranks a 2x2 wall of W/2 x H/2 tiles (the same canvas). Figures per
frame: wall time (ParaView: rank 0's loop; multigpu: the frame period) and the slowest rank's
CPU time (ParaView: process time of its loop; multigpu: the emulated frame). Both run unbound
(``--bind-to none``: llvmpipe's rasterizer thread gets a core of its own). Needs ParaView's
``pvbatch`` and Open MPI's ``mpiexec`` (Debian: ``apt install paraview openmpi-bin``); never a
dependency of the project.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from multigpu.errors import InputError
from multigpu.studies.tables import Columns

#: the ParaView side: run by ``pvbatch --symmetric SCRIPT CAMERAS MODEL W H OUT`` on every rank
PVBATCH_SCRIPT = r'''
import json, sys, time
from paraview.simple import *
from paraview.modules.vtkRemotingCore import vtkProcessModule

cams_file, model, W, H, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
rank = vtkProcessModule.GetProcessModule().GetPartitionId()
cams = json.load(open(cams_file))["cameras"]
reader = OpenDataFile(model)
data = RedistributeDataSet(Input=reader)
view = CreateView("RenderView")
view.ViewSize = [W, H]
view.OrientationAxesVisibility = 0
Show(data, view)
cam = view.GetActiveCamera()

def put(c):
    cam.SetPosition(*c["position"]); cam.SetFocalPoint(*c["target"]); cam.SetViewUp(*c["up"])
    cam.SetViewAngle(c["fov"]); cam.SetClippingRange(c["near"], c["far"])

put(cams[0]); Render(view)  # the first frame builds what later frames reuse
w0, c0 = time.perf_counter(), time.process_time()
for c in cams:
    put(c)
    Render(view)
wall, cpu = time.perf_counter() - w0, time.process_time() - c0
json.dump({"rank": rank, "frames": len(cams), "wall_ms": 1e3 * wall / len(cams), "cpu_ms": 1e3 * cpu / len(cams)},
          open(f"{out}.rank{rank}.json", "w"))
'''


#: ParaView playing a series (``bench series``): ``pvbatch --symmetric SCRIPT CAMERAS STEPS W H OUT FIELD LO HI
#: RATE``, STEPS a JSON list of the step files (one reader, a step per time), coloured by FIELD over LO..HI
#: (matplotlib's viridis); frame f shows the step multigpu's ``--steps-per-second RATE`` shows (30 frames a
#: second of scene time, looping), every step read when its frame comes (as ``--late-step wait``)
PVBATCH_SERIES_SCRIPT = r'''
import json, math, sys, time
from paraview.simple import *
from paraview.modules.vtkRemotingCore import vtkProcessModule

cams_file, steps_file, W, H, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
field, lo, hi, rate = sys.argv[6], float(sys.argv[7]), float(sys.argv[8]), float(sys.argv[9])
rank = vtkProcessModule.GetProcessModule().GetPartitionId()
cams = json.load(open(cams_file))["cameras"]
files = json.load(open(steps_file))
reader = XMLUnstructuredGridReader(FileName=files)
times = list(reader.TimestepValues) if len(files) > 1 else [0.0]
data = RedistributeDataSet(Input=reader)
view = CreateView("RenderView")
view.ViewSize = [W, H]
view.OrientationAxesVisibility = 0
shown = Show(data, view)
ColorBy(shown, ("POINTS", field))
lut = GetColorTransferFunction(field)
lut.ApplyPreset("Viridis (matplotlib)", True)
lut.RescaleTransferFunction(lo, hi)
cam = view.GetActiveCamera()

def put(c):
    cam.SetPosition(*c["position"]); cam.SetFocalPoint(*c["target"]); cam.SetViewUp(*c["up"])
    cam.SetViewAngle(c["fov"]); cam.SetClippingRange(c["near"], c["far"])

def at(f):
    return times[int(math.floor(f / 30.0 * rate + 1e-9)) % len(times)]

put(cams[0]); view.ViewTime = at(0); Render(view)  # the first frame builds what later frames reuse
w0, c0 = time.perf_counter(), time.process_time()
for f, c in enumerate(cams):
    put(c)
    view.ViewTime = at(f)
    Render(view)
wall, cpu = time.perf_counter() - w0, time.process_time() - c0
json.dump({"rank": rank, "frames": len(cams), "wall_ms": 1e3 * wall / len(cams), "cpu_ms": 1e3 * cpu / len(cams)},
          open(f"{out}.rank{rank}.json", "w"))
'''


def _tools():
    """(pvbatch, Open MPI's mpiexec) or a one-line error naming what is missing."""
    from multigpu.launcher.mpirun import openmpi_on_path

    pvbatch = shutil.which("pvbatch")
    if pvbatch is None:
        raise InputError("bench peer: ParaView's pvbatch is not installed (Debian: apt install paraview); "
                         "nothing measured")
    mpiexec = openmpi_on_path()
    if mpiexec is None:
        raise InputError("bench peer: no Open MPI mpiexec (Debian: apt install openmpi-bin); nothing measured")
    return pvbatch, mpiexec


def paraview(pvbatch: str, mpiexec: str, ranks: int, cams: Path, model: str, size: tuple[int, int], out: Path,
             env: dict, timeout: float, series: tuple | None = None) -> dict:
    """One ParaView run: rank 0's wall ms per frame, the slowest rank's CPU ms per frame. ``series``:
    (field, lo, hi, rate) to play ``model``, then a JSON list of step files (``PVBATCH_SERIES_SCRIPT``)."""
    script = out / ("pvbatch_series.py" if series else "pvbatch_peer.py")
    script.write_text(PVBATCH_SERIES_SCRIPT if series else PVBATCH_SCRIPT)
    stem = out / f"paraview-{ranks}-{time.monotonic_ns()}"
    cmd = [mpiexec, "--oversubscribe", "--bind-to", "none", *(["--allow-run-as-root"] if os.geteuid() == 0 else []),
           "-n", str(ranks),
           pvbatch, "--symmetric", "--force-offscreen-rendering", str(script), str(cams), model, str(size[0]),
           str(size[1]), str(stem), *(str(v) for v in series or ())]
    clean = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    job = subprocess.run(cmd, env={**clean, **env}, capture_output=True, text=True, timeout=timeout)
    got = [json.loads(p.read_text()) for p in sorted(out.glob(f"{stem.name}.rank*.json"))]
    if job.returncode != 0 or len(got) != ranks:
        tail = "\n".join((job.stdout + job.stderr).strip().splitlines()[-5:])
        raise RuntimeError(f"bench peer: pvbatch failed (exit {job.returncode})\n{tail}")
    return {"wall_ms": next(g["wall_ms"] for g in got if g["rank"] == 0), "cpu_ms": max(g["cpu_ms"] for g in got)}


def multigpu(mpiexec: str, ranks: int, cams: Path, scene: list[str], size: tuple[int, int], out: Path, env: dict,
             timeout: float, extra: list[str]) -> dict:
    """One multigpu run over the same cameras: the frame period and the emulated frame (ms)."""
    from multigpu.launcher.mpirun import launcher_for
    from multigpu.studies.runs import walk

    grid = (1, 1) if ranks == 1 else (2, ranks // 2)
    tile = (size[0] // grid[1], size[1] // grid[0])
    dest = out / f"multigpu-{ranks}-{time.monotonic_ns()}"
    args = [*scene, "--path", str(cams), "--mosaic-every", "0", *extra]
    s = walk(dest, grid, tile, args, timeout, env=env, launcher=launcher_for(mpiexec)).summary
    return {"wall_ms": s["frame_ms"], "cpu_ms": s["emulated_frame_ms"]}


def bench_peer(model: str, split: str = "grid:8", ranks: tuple[int, ...] = (1, 4), frames: int = 150,
               size: tuple[int, int] = (1024, 1024), rounds: int = 2, out: str = "out/peer",
               extra: tuple[str, ...] = (), timeout: float = 1800) -> list[dict]:
    """Alternate ParaView and multigpu ``rounds`` times at each rank count; print and return the
    medians (wall and slowest rank's CPU ms per frame) and multigpu's lead."""
    pvbatch, mpiexec = _tools()
    if not Path(model).is_file():
        raise InputError.of("model", f"{model}: model file not found")
    dest = Path(out)
    dest.mkdir(parents=True, exist_ok=True)
    cams = dest / "cameras.json"
    scene = ["--model", str(Path(model).resolve()), "--split", split]
    made = subprocess.run([sys.executable, "-m", "multigpu", "path", "make", "orbit", *scene, "--frames", str(frames),
                           "--out", str(cams)], capture_output=True, text=True, timeout=timeout)
    if made.returncode != 0:
        raise RuntimeError(f"bench peer: the camera path could not be made\n{made.stderr[-1500:]}")
    env = {"LP_NUM_THREADS": "1"}  # one llvmpipe rasterizer thread per process, both sides
    from multigpu.display.xvfb import start_xvfb, stop_xvfb

    xvfb, display = start_xvfb((size[0] + 16, size[1] + 16))  # Debian's ParaView draws through GLX only
    try:
        with tempfile.TemporaryDirectory(prefix="multigpu-peer-") as tmp:  # the runs' own outputs: not kept
            rows = _rounds(pvbatch, mpiexec, ranks, rounds, cams, scene, model, size, Path(tmp), env, display, timeout,
                           extra)
    finally:
        stop_xvfb(xvfb)
    (dest / "peer.json").write_text(json.dumps({"model": model, "split": split, "frames": frames, "size": size,
                                                "extra": list(extra), "rows": rows}, indent=1))
    _csv(dest / "peer.csv", rows, Path(model).name, frames, size)
    _print(rows, model, frames, size, rounds)
    return rows


def _rounds(pvbatch, mpiexec, ranks, rounds, cams, scene, model, size, dest, env, display, timeout, extra) -> list:
    import numpy as np

    rows = []
    for k in ranks:
        runs = {"paraview": [], "multigpu": []}
        for _ in range(rounds):  # alternated: the machine's drift falls on both alike
            runs["paraview"].append(paraview(pvbatch, mpiexec, k, cams, str(Path(model).resolve()), size, dest,
                                             {**env, "DISPLAY": display}, timeout))
            runs["multigpu"].append(multigpu(mpiexec, k, cams, scene, size, dest, env, timeout, list(extra)))
        med = {name: {m: float(np.median([r[m] for r in got])) for m in ("wall_ms", "cpu_ms")}
               for name, got in runs.items()}
        rows.append({"ranks": k, **med, "wall_lead": med["paraview"]["wall_ms"] / med["multigpu"]["wall_ms"],
                     "cpu_lead": med["paraview"]["cpu_ms"] / med["multigpu"]["cpu_ms"], "rounds": rounds})
    return rows


def _csv(path: Path, rows: list, model: str, frames: int, size) -> None:
    """The medians as a results CSV (docs/results/peer/peer.csv for the docs' figures)."""
    import csv

    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["model", "frames", "size", "ranks", "paraview_wall_ms", "multigpu_wall_ms", "wall_lead",
                    "paraview_cpu_ms", "multigpu_cpu_ms", "cpu_lead", "rounds"])
        for r in rows:
            p, m = r["paraview"], r["multigpu"]
            w.writerow([model, frames, f"{size[0]}x{size[1]}", r["ranks"], f"{p['wall_ms']:.2f}", f"{m['wall_ms']:.2f}",
                        f"{r['wall_lead']:.3f}", f"{p['cpu_ms']:.2f}", f"{m['cpu_ms']:.2f}", f"{r['cpu_lead']:.3f}",
                        r["rounds"]])


def _print(rows: list, model: str, frames: int, size, rounds: int) -> None:
    print(f"{Path(model).name}, {frames} orbit cameras, {size[0]}x{size[1]}, LP_NUM_THREADS=1, Open MPI, "
          f"{rounds} alternated rounds, medians (ms per frame):")
    table = Columns(("ranks", "ranks", "5d"), ("p_wall", "ParaView wall", "13.1f"),
                    ("m_wall", "multigpu wall", "13.1f"), ("wall_lead", "lead", ">6"),
                    ("p_cpu", "ParaView CPU", "12.1f"), ("m_cpu", "multigpu CPU", "12.1f"), ("cpu_lead", "lead", ">6"))
    print(table.header())
    for r in rows:
        p, m = r["paraview"], r["multigpu"]
        print(table.row({"ranks": r["ranks"], "p_wall": p["wall_ms"], "m_wall": m["wall_ms"], "p_cpu": p["cpu_ms"],
                         "m_cpu": m["cpu_ms"], "wall_lead": f"{r['wall_lead']:5.2f}x",
                         "cpu_lead": f"{r['cpu_lead']:5.2f}x"}))
    sys.stdout.flush()
