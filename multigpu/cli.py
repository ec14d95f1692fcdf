"""The ``multigpu`` command line: one entry point, argparse subcommands.

    mpiexec -n K multigpu walkthrough [...]   the parallel renderer (MPI)
    multigpu scene info SCENE_OR_FILE          objects, triangles, bounds, memory, load time
    multigpu path make KIND --out FILE         write a camera path file
    multigpu tree RxC                          print the GPU tree and each rank's ParInfo
    multigpu bench balance|scene|render        benchmarks (speed and memory figures)
    multigpu experiment NAME|all [--quick]     the paper's evaluation: CSV, plots, Markdown
    multigpu accuracy [--quick]                speed-for-accuracy trades: CSV + ACCURACY.md

Bad input prints ``multigpu: error: ...`` (one line) and exits 2.
"""

from __future__ import annotations

import argparse
import sys

from .errors import InputError
from .memory import keep_heap


def _scene_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scene")
    g.add_argument("--scene", default="plant", help="built-in scene name (default: plant)")
    g.add_argument("--model", help="model file (OBJ, PLY, STL, OFF, glTF/GLB) instead of --scene")
    g.add_argument("--split", default="components", help="split one mesh into objects: components | grid:N")
    g.add_argument("--merge-below", type=int, default=64, help="merge components under this many triangles")
    g.add_argument("--triangles", type=int, default=100_000, help="plant size in triangles (default 100000)")
    g.add_argument("--copies", type=int, default=1, help="plants side by side (the paper used 6..20)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--cluster", type=int, default=0,
                   help="split objects above N triangles into spatial clusters of at most N (0: as modelled)")


def _spec(a):
    from .models import SceneSpec

    return SceneSpec(scene=a.scene, model=a.model, split=a.split, merge_below=a.merge_below,
                     triangles=a.triangles, copies=a.copies, seed=a.seed, cluster=a.cluster)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="multigpu", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)

    w = sub.add_parser("walkthrough", help="render a camera path on a display wall (run under mpiexec)")
    _scene_args(w)
    w.add_argument("--path", help="camera path JSON file (default: generated walkthrough)")
    w.add_argument("--path-kind", default="walkthrough", help="generated path: walkthrough | orbit")
    w.add_argument("--frames", type=int, help="frames to render (default: the whole path, 1200)")
    w.add_argument("--grid", default="2x2", help="display wall ROWSxCOLS (ranks = rows*cols)")
    w.add_argument("--tile", default="256x256", help="pixels per display tile WxH")
    w.add_argument("--strips", type=int, default=2048, help="strips per split axis (>= 2)")
    w.add_argument("--balance", default="strips", help="balancing strategy: strips | cost | time | adaptive | none")
    w.add_argument("--bounds", default="box", help="object bounds: box (8 corners) | sphere")
    w.add_argument("--out", default="out", help="output directory")
    w.add_argument("--mosaic-every", type=int, default=100, help="write the full wall every N frames (0: never)")
    w.add_argument("--no-overlay", action="store_true", help="do not write partition overlay images")
    w.add_argument("--video", action="store_true", help="write mosaic.mp4 of every frame (needs imageio-ffmpeg)")
    w.add_argument("--subfrustum", default="auto",
                   help="how a rank renders its region: auto | viewport | scissor | offaxis (docs/ACCURACY.md)")
    w.add_argument("--partition", default="redundant",
                   help="who computes the partition: redundant (every rank) | broadcast (rank 0, then MPI_Bcast)")
    w.add_argument("--offset", default="0,0,0", help="move scene and path by X,Y,Z world units (e.g. 1e8,0,0)")
    w.add_argument("--device", type=int, help="EGL device index (default: local rank modulo device count)")
    w.add_argument("--timeout", type=float, default=120.0, help="seconds any rank waits for the others")
    w.add_argument("--no-progress", action="store_true")

    s = sub.add_parser("scene", help="scene tools")
    ssub = s.add_subparsers(dest="scmd", required=True)
    si = ssub.add_parser("info", help="print objects, triangles, bounds, memory and load time")
    si.add_argument("source", nargs="?", default="plant", help="built-in scene name or model file")
    _scene_args(si)
    si.add_argument("--no-cache", action="store_true")

    p = sub.add_parser("path", help="camera path tools")
    psub = p.add_subparsers(dest="pcmd", required=True)
    pm = psub.add_parser("make", help="write a camera path file")
    pm.add_argument("kind", help="walkthrough | orbit")
    _scene_args(pm)
    pm.add_argument("--frames", type=int)
    pm.add_argument("--fov", type=float, default=60.0)
    pm.add_argument("--out", required=True, help="path file to write (JSON)")

    t = sub.add_parser("tree", help="print the GPU tree of a ROWSxCOLS wall")
    t.add_argument("grid")

    dp = sub.add_parser("depth", help="depth complexity and overdraw of one frame (images + stats)")
    _scene_args(dp)
    dp.add_argument("--path-kind", default="walkthrough", help="generated path: walkthrough | orbit")
    dp.add_argument("--frames", type=int, default=None, help="frames of the generated path")
    dp.add_argument("--frame", type=int, default=0, help="which frame of the path")
    dp.add_argument("--size", default="1024x1024", help="display WxH in pixels")
    dp.add_argument("--out", default="out/depth", help="output directory")
    e = sub.add_parser("experiment", help="the paper's evaluation: tables, plots, Markdown")
    e.add_argument("name", help="all | gpus | resolution | balance | strips | orbit | overlap | cost | speedup")
    e.add_argument("--quick", action="store_true", help="tiny sizes: the same code in a few minutes")
    e.add_argument("--out", default="out/experiments", help="output directory")
    e.add_argument("--results", default=None, help="results page written by 'all' (default OUT/RESULTS.md)")
    ac = sub.add_parser("accuracy", help="measure every speed-for-accuracy trade (tables for docs/ACCURACY.md)")
    ac.add_argument("--quick", action="store_true", help="tiny sizes: the same code in under a minute")
    ac.add_argument("--out", default="out/accuracy", help="directory for the CSV tables")
    ac.add_argument("--page", default=None, help="Markdown page to write (default OUT/ACCURACY.md)")
    b = sub.add_parser("bench", help="benchmarks: print speed and memory figures")
    b.add_argument("what", help="balance | scene | render")
    b.add_argument("--quick", action="store_true", help="small sizes, a few seconds")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    keep_heap()  # per-frame temporaries stay in the heap (see memory.py)
    try:
        if args.cmd == "walkthrough":
            return _walkthrough(args)
        if args.cmd == "scene":
            return _scene_info(args)
        if args.cmd == "path":
            return _path_make(args)
        if args.cmd == "tree":
            return _tree(args)
        if args.cmd == "depth":
            return _depth(args)
        if args.cmd == "experiment":
            from . import experiments

            return experiments.run(args.name, args.out, quick=args.quick, results=args.results)
        if args.cmd == "accuracy":
            from . import accuracy

            return accuracy.run(args.out, args.page, quick=args.quick)
        if args.cmd == "bench":
            from . import bench

            return bench.main(args.what, quick=args.quick)
    except InputError as exc:
        print(f"multigpu: error: {exc}", file=sys.stderr)
        return 2
    return 0


def _depth(a) -> int:
    from pathlib import Path

    from . import depth
    from .config import parse_pair
    from .models import SceneSpec, load_scene
    from .paths import orbit, walkthrough

    size = parse_pair(a.size, "--size")
    if a.path_kind not in ("walkthrough", "orbit"):
        raise InputError(f"--path-kind must be walkthrough or orbit, got '{a.path_kind}'")
    scene, _ = load_scene(SceneSpec(scene=a.scene, model=a.model, split=a.split, merge_below=a.merge_below,
                                    triangles=a.triangles, copies=a.copies, seed=a.seed, cluster=a.cluster))
    gen = walkthrough if a.path_kind == "walkthrough" else orbit
    path = gen(scene, frames=a.frames or (1200 if a.path_kind == "walkthrough" else 300))
    if not 0 <= a.frame < len(path):
        raise InputError(f"--frame must be in 0..{len(path) - 1}, got {a.frame}")
    s = depth.run(scene, path.camera(a.frame), size, Path(a.out))
    print(f"{scene.name} frame {a.frame} at {size[0]}x{size[1]}: coverage {s.get('coverage', 0):.1%}, "
          f"mean depth complexity d = {s['mean_d']:.2f} (max {s['max_d']}), measured overdraw o = {s['mean_o']:.2f}, "
          f"model o(d) = 1 + 1/2 + ... + 1/d: {s['model_o']:.2f}")
    print(f"images and depth.json in {a.out}/")
    return 0


def _walkthrough(a) -> int:
    from mpi4py import MPI

    from .config import WalkConfig, parse_pair, parse_vec3

    comm = MPI.COMM_WORLD
    try:
        cfg = WalkConfig(scene=_spec(a), path=a.path, path_kind=a.path_kind, frames=a.frames,
                         grid=parse_pair(a.grid, "--grid"), tile=parse_pair(a.tile, "--tile"), strips=a.strips,
                         balance=a.balance, bounds=a.bounds, out=a.out, mosaic_every=a.mosaic_every,
                         overlay=not a.no_overlay, video=a.video, device=a.device, subfrustum=a.subfrustum, partition=a.partition,
                         offset=parse_vec3(a.offset, "--offset"), timeout=a.timeout,
                         progress=not a.no_progress)
        from .walkthrough import run

        run(cfg, comm)
    except InputError as exc:  # agreed on every rank before any frame: all exit 2
        if comm.Get_rank() == 0:
            print(f"multigpu: error: {exc}", file=sys.stderr, flush=True)
        from .exchange import PeerTimeout, barrier

        try:  # let rank 0 print before any rank's exit ends the job
            barrier(comm, 10.0)
        except PeerTimeout:
            pass
        return 2
    except BaseException as exc:  # one rank failed mid-run: say so once and end the whole job
        print(f"multigpu: rank {comm.Get_rank()}: {exc.__class__.__name__}: {exc}", file=sys.stderr, flush=True)
        if comm.Get_rank() != 0:
            import time

            time.sleep(1.0)  # grace: rank 0 writes the last completed frame's rows before the abort
        comm.Abort(1)
    return 0


def _scene_info(a) -> int:
    import resource
    from pathlib import Path

    from .models import SceneSpec, load_scene

    src = a.source
    is_file = Path(src).suffix != "" or Path(src).exists()
    spec = SceneSpec(scene=a.scene if is_file else src, model=src if is_file else a.model, split=a.split,
                     merge_below=a.merge_below, triangles=a.triangles, copies=a.copies, seed=a.seed, cluster=a.cluster)
    scene, info = load_scene(spec, use_cache=not a.no_cache)
    lo, hi = scene.bounds
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tris = scene.tris
    print(f"scene      {scene.name}")
    print(f"objects    {scene.n_objects}")
    print(f"triangles  {scene.n_triangles} (per object: min {tris.min()}, median {int(sorted(tris)[len(tris) // 2])}, max {tris.max()})")
    print(f"vertices   {scene.vertices.shape[0]}")
    print(f"bounds     {lo.round(3).tolist()} .. {hi.round(3).tolist()}")
    print(f"memory     {scene.nbytes / 2**20:.1f} MiB in arrays ({scene.nbytes / max(scene.n_triangles, 1):.1f} B/triangle), peak RSS {peak:.0f} MiB")
    print(f"load       {info['seconds']:.3f} s ({'cache hit' if info['cached'] else 'built'}{', ' + info['cache'] if info['cache'] else ''})")
    for w in scene.meta.get("warnings", []):
        print(f"warning    {w}")
    return 0


def _path_make(a) -> int:
    from .models import load_scene
    from .paths import orbit, walkthrough

    if a.kind not in ("walkthrough", "orbit"):
        raise InputError(f"path kind must be 'walkthrough' or 'orbit', got '{a.kind}'")
    if a.frames is not None and a.frames < 1:
        raise InputError(f"--frames must be >= 1, got {a.frames}")
    scene, _ = load_scene(_spec(a))
    gen = walkthrough if a.kind == "walkthrough" else orbit
    frames = a.frames or (1200 if a.kind == "walkthrough" else 300)
    path = gen(scene, frames=frames, fov=a.fov)
    path.save(a.out)
    print(f"wrote {a.out}: {len(path)} frames ({a.kind} of {scene.name})")
    return 0


def _tree(a) -> int:
    from .config import parse_pair
    from .tree import GpuTree

    rows, cols = parse_pair(a.grid, "grid")
    t = GpuTree(rows, cols)
    print(t.describe())
    for label in range(t.size):
        info = ", ".join(f"({i.method}, {i.nc_l}, {i.nc_r}, {i.side})" for i in t.parinfo[label])
        print(f"GPU{label} tile{t.tile_of(label)} depth {t.depth(label)}: {info}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
