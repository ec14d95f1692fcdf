"""``multigpu bench memory``: peak memory of a walkthrough per rank and per host.

Each case runs a short headless walkthrough of the plant at a size (``--triangles``, ``--copies``
past 10^6 triangles) on K ranks twice: first with no scene cache (rank 0 builds it), then again
(every rank maps the cached file). While it runs, every rank
process's proportional set size (``Pss`` of ``/proc/PID/smaps_rollup``: pages shared between
ranks counted once, split among them) is sampled every 20 ms; the figures are the peak of each
rank and the peak of their sum (one host: this machine). Linux only.
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from multigpu.errors import InputError
from multigpu.studies.tables import Columns


def proc_kib(pid: int, name: str, key: str) -> int:
    """The kiB figure on the ``key`` line of ``/proc/PID/NAME`` (0 when the process is gone)."""
    try:
        with open(f"/proc/{pid}/{name}") as fh:
            for line in fh:
                if line.startswith(key):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def _pss(pid: int) -> int:
    """Bytes of ``pid``'s proportional set size (0 when gone)."""
    return proc_kib(pid, "smaps_rollup", "Pss:") * 1024


def _ranks(root: int) -> list[int]:
    """Pids of the rank processes (``-m multigpu walkthrough``) descended from ``root`` (the
    launcher: its proxies may start sessions of their own)."""
    parent = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as fh:
                    parent[int(d)] = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    out = []
    for pid in parent:
        p, seen = pid, 0
        while p in parent and p != root and seen < 64:
            p, seen = parent[p], seen + 1
        if p != root or pid == root:
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                argv = fh.read().split(b"\0")
        except OSError:
            continue
        if b"multigpu" in argv and b"walkthrough" in argv:
            out.append(pid)
    return out


def scene_flags(triangles: int) -> list[str]:
    """The plant asked for ``triangles``: one copy up to 10^6, then copies of ~1.25x10^6 asked
    each (the issue's 4.28 M-triangle case is ``--triangles 5000000 --copies 4``)."""
    copies = max(1, round(triangles / 1_250_000))
    return ["--triangles", str(triangles), "--copies", str(copies)]


def measure(ranks: int, triangles: int, cache: str, frames: int = 8, timeout: float = 1800, extra=(),
            scene: list[str] | None = None, env: dict | None = None) -> dict:
    """Peak PSS per rank and summed, for one walkthrough of ``triangles`` on ``ranks`` ranks
    (``extra``: more walkthrough flags, e.g. ``--lod-error 1``: levels of detail held; ``scene``:
    the scene's flags, e.g. ``--model FILE``, instead of the plant of ``triangles``; ``env``: more
    environment for the job), with the
    run's scene load time and median emulated frame (per-rank CPU time) from its summary."""
    from multigpu.studies.runs import end, start

    rows, cols = (1, ranks) if ranks < 4 else (2, ranks // 2)
    out = tempfile.mkdtemp(prefix="mem-")
    args = ["walkthrough", *(scene_flags(triangles) if scene is None else scene), "--frames", str(frames),
            "--grid", f"{rows}x{cols}",
            "--tile", "256x256", "--mosaic-every", "0", "--no-progress", "--out", out, *extra]
    proc = start(ranks, args, {"MULTIGPU_CACHE": cache, **(env or {})}, as_users=True)  # as users launch
    peak_each: dict[int, int] = {}
    peak_sum = 0
    stop = threading.Event()

    def sample():
        nonlocal peak_sum
        while not stop.is_set():
            pss = {pid: _pss(pid) for pid in _ranks(proc.pid)}
            for pid, v in pss.items():
                peak_each[pid] = max(peak_each.get(pid, 0), v)
            peak_sum = max(peak_sum, sum(pss.values()))
            time.sleep(0.02)

    t = threading.Thread(target=sample, daemon=True)
    t.start()
    t0 = time.perf_counter()
    try:
        _, err = proc.communicate(timeout=timeout)
    finally:
        stop.set()
        t.join()
        end(proc)
        summary = Path(out) / "summary.json"
        got = json.loads(summary.read_text()) if summary.exists() else {"config": {"scene": {}}}
        subprocess.run(["rm", "-rf", out], check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"bench memory: the {ranks}-rank run of {triangles} triangles failed: "
                           f"{err.strip().splitlines()[-1] if err.strip() else proc.returncode}")
    return {"ranks": ranks, "triangles_target": triangles, "triangles": got["config"]["scene"].get("triangles", 0),
            "seconds": round(time.perf_counter() - t0, 1), "load_seconds": got["config"]["scene"].get("load_seconds"),
            "frame_ms_median": got.get("emulated_frame_ms_median"),
            "peak_pss_rank_max": max(peak_each.values(), default=0), "peak_pss_host": peak_sum}


def bench_memory(quick: bool) -> list[dict]:
    """Peak PSS per rank and per host at 2, 4 and 8 ranks, 10^5 to 2x10^7 triangles: the first
    run (rank 0 builds the scene cache) and a second run (every rank maps the cached scene)."""
    if not os.path.exists("/proc/self/smaps_rollup"):
        raise InputError("bench memory needs Linux's /proc/PID/smaps_rollup")
    sizes = [100_000, 1_000_000] if quick else [100_000, 1_000_000, 5_000_000, 25_000_000]
    ranks = [2, 4] if quick else [2, 4, 8]
    rows = []
    table = Columns(("ranks", "ranks", "5d"), ("triangles", "triangles", "10d"), ("run", "run", ">6"),
                    ("rank_mib", "peak PSS/rank MiB", "18.0f"), ("host_mib", "peak PSS/host MiB", "18.0f"),
                    ("host_per_tri", "host B/tri", "10.0f"), ("seconds", "seconds", "8.1f"))
    print(table.header(), flush=True)
    for n in sizes:
        for k in ranks:
            with tempfile.TemporaryDirectory() as cache:  # each case's first run builds its own cache
                for run in ("first", "cached"):
                    d = {**measure(k, n, cache), "run": run}
                    rows.append(d)
                    print(table.row({**d, "ranks": k, "rank_mib": d["peak_pss_rank_max"] / 2**20,
                                     "host_mib": d["peak_pss_host"] / 2**20,
                                     "host_per_tri": d["peak_pss_host"] / max(d["triangles"], 1)}), flush=True)
    return rows


def _anonymous_mib() -> float:
    with open("/proc/self/smaps_rollup") as fh:
        for line in fh:
            if line.startswith("Anonymous:"):
                return int(line.split()[1]) / 1024
    return 0.0


def bench_memory_steps(quick: bool) -> list[tuple[str, float]]:
    """One rank's anonymous memory after each step of its setup and first frames, in this
    process: the cached plant (``--triangles 5000000 --copies 4``, 4.28 M triangles; 10^6 with
    ``--quick``) loaded mapped, an EGL context, the GL upload, the compiled kernel, then three
    frames of the whole scene into a 512x512 region, with llvmpipe's raster thread
    (``LP_NUM_THREADS=1``) and without it (``0``: what ranks filling a host's cores use), and
    without it with the GL buffers drawn from the host's shared buffers file (what a walkthrough
    rank does; the file written beforehand, here), each in a fresh process."""
    import sys

    from multigpu.scene.models import SceneSpec, load_scene

    if not os.path.exists("/proc/self/smaps_rollup"):
        raise InputError("bench memory-steps needs Linux's /proc/PID/smaps_rollup")
    spec = SceneSpec(triangles=1_000_000) if quick else SceneSpec(triangles=5_000_000, copies=4)
    _, info = load_scene(spec)  # the cache exists before the measured load
    from multigpu.gpu.buffers import ensure_buffers

    ensure_buffers(info["cache"], load_scene(spec)[0])  # and its buffers file: the measured rank maps it, as a
    # walkthrough's ranks but the one that wrote it do (writing it packs the vertices: compiled, numba's runtime)
    steps = []
    for threads, shared in (("1", False), ("0", False), ("0", True)):
        code = (f"from multigpu.studies.memory_bench import _steps; "
                f"_steps({spec.triangles}, {spec.copies}, {shared})")
        env = {**os.environ, "LP_NUM_THREADS": threads}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=1800, env=env)
        if out.returncode != 0:
            raise RuntimeError(f"bench memory-steps: {out.stderr.strip().splitlines()[-1:]}")
        how = f"{threads} raster thread{'s' if threads != '1' else ''}" + (", shared file" if shared else "")
        for line in out.stdout.splitlines():
            name, mib = line.rsplit(" ", 1)
            first_run = threads == "1"
            if name.startswith("frame"):
                steps.append((f"{name} ({how})", float(mib)))
            elif first_run or (shared and name.startswith("GL")):
                steps.append((name, float(mib)))
    table = Columns(("step", "step", "<44"), ("mib", "anonymous MiB", "14.0f"))
    print(table.header())
    for name, mib in steps:
        print(table.row({"step": name, "mib": mib}))
    return steps


#: what a run says where its GL cannot share the buffers file (the test skips only then)
NO_PIN = "this GL cannot draw from host memory"


def _steps(triangles: int, copies: int, shared: bool = False) -> None:
    """The measured process of ``bench_memory_steps`` (a fresh one per setting): the GL
    buffers uploaded, or (``shared``) drawn from the host's buffers file as the walkthrough's are."""
    import numpy as np

    from multigpu import kernels
    from multigpu.core.camera import frame_matrices
    from multigpu.gpu.buffers import can_pin, ensure_buffers
    from multigpu.gpu.render import RegionRenderer, create_context
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import generate

    scene, info = load_scene(SceneSpec(triangles=triangles, copies=copies))
    path = ensure_buffers(info["cache"], scene) if shared else None
    ctx, _ = create_context(None, local_rank=0)
    print(f"scene loaded (mapped) + EGL context {_anonymous_mib():.1f}")
    r = RegionRenderer(ctx, scene, (512, 512), "auto", path)
    scene = scene.without_geometry()  # as the walkthrough does
    if shared and not r.storage.startswith("shared"):
        why = can_pin(ctx)  # a GL that cannot draw from host memory (NVIDIA's) shares nothing, by design
        raise RuntimeError(f"the GL buffers were not shared: {r.storage}"
                           + (f" ({NO_PIN}: {why})" if why else " (this GL can draw from host memory: a failure)"))
    print(f"{'GL buffers drawn from the shared file' if shared else 'GL upload'} {_anonymous_mib():.1f}")
    kernels.warm()
    print(f"compiled kernel loaded {_anonymous_mib():.1f}")
    path = generate("walkthrough", scene, 10)
    for f in range(3):
        view, proj, _ = frame_matrices(path.camera(f), (512, 512))
        r.render(view, proj, np.array([0.0, 0.0, 1.0]), (0, 0, 512, 512), None)
        print(f"frame {f} {_anonymous_mib():.1f}")


#: this process's peak resident set (VmHWM: unlike ru_maxrss, not inherited through fork + exec)
_HWM = "int([l for l in open('/proc/self/status') if l.startswith('VmHWM')][0].split()[1]) * 1024"

_MODEL_CHILD = """
import json, sys, time
import trimesh
from multigpu.scene.models import SceneSpec, load_scene
what, path = sys.argv[1], sys.argv[2]
t = time.perf_counter()
if what == "trimesh":
    n = len(trimesh.load(path, process=False).faces)
else:
    n = load_scene(SceneSpec(model=path, ranks=4))[0].n_triangles
print(json.dumps({"triangles": n, "seconds": time.perf_counter() - t,
                  "peak_rss": HWM}))
""".replace("HWM", _HWM)


def bench_model_load(quick: bool) -> list[dict]:
    """Peak memory of loading a big model file into the scene cache: a PLY of one icosphere
    (5.24 M triangles; 0.33 M with ``--quick``) read by trimesh alone, then by ``load_scene``
    for a 4-rank wall (components, normals, bounds, clusters, the cache written), each in a
    fresh process (peak RSS), against the interpreter with the imports alone."""
    import json
    import sys

    import trimesh

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "sphere.ply")
        trimesh.creation.icosphere(subdivisions=7 if quick else 9).export(path)
        size = os.path.getsize(path)
        env = {**os.environ, "MULTIGPU_CACHE": os.path.join(tmp, "cache")}
        base = int(subprocess.run([sys.executable, "-c", f"import trimesh, multigpu.scene.models; print({_HWM})"],
                                  capture_output=True, text=True, check=True, env=env).stdout)
        print(f"PLY of {size / 2**20:.0f} MiB; interpreter + imports peak RSS {base / 2**20:.0f} MiB")
        table = Columns(("load", "load", "<28"), ("triangles", "triangles", "10d"), ("seconds", "seconds", "8.1f"),
                        ("rss_mib", "peak RSS MiB", "13.0f"), ("above", "above imports B/tri", "20.0f"))
        print(table.header())
        for what in ("trimesh", "into the cache", "cached"):
            out = subprocess.run([sys.executable, "-c", _MODEL_CHILD, what, path], capture_output=True, text=True,
                                 check=True, env=env, timeout=1800).stdout
            d = {"load": what, **json.loads(out)}
            rows.append(d)
            print(table.row({**d, "rss_mib": d["peak_rss"] / 2**20, "above": (d["peak_rss"] - base) / d["triangles"]}))
    return rows
