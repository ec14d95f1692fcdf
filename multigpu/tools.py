"""The tool subcommands: scene info and scan, path make, wall check and test, the operator's
view on a PC of its own, tree and depth (each set on its parser in ``cli.build_parser``)."""

from __future__ import annotations

from multigpu.errors import InputError
from multigpu.flags import spec


def wall_test(a) -> int:
    from multigpu.rank.walltest import main as wall_test

    return wall_test(a.file, a.frames, a.blend == "on")


def monitor_view(a) -> int:
    import re
    import sys

    from multigpu.display.remote import serve

    token = sys.stdin.readline().strip()  # the launcher's, on standard input (not on a command line)
    if not token:
        print("multigpu monitor-view: error: no token on standard input (the launcher writes one)",
              file=sys.stderr)
        return 2
    m = re.fullmatch(r"\s*(\d{1,6})\s*x\s*(\d{1,6})\s*", str(a.position))  # a window's place: pixels >= 0
    if not m:
        raise InputError(f"--position must look like XxY with pixels >= 0 (e.g. 0x0), got '{a.position}'")
    serve(a.display, (int(m.group(1)), int(m.group(2))), token, a.port, a.listen)
    return 0


def view(a) -> int:
    from multigpu.config import read_panel
    from multigpu.errors import InputError
    from multigpu.panel.finished import serve

    try:
        address, port = read_panel(a.panel)
    except InputError as exc:
        raise InputError(f"--panel {exc}") from None
    return serve(a.out, address, port)


def depth(a) -> int:
    from pathlib import Path

    from multigpu.config import parse_pair
    from multigpu.gpu import depth
    from multigpu.scene.models import load_scene
    from multigpu.scene.paths import generate

    size = parse_pair(a.size, "--size")
    scene, _ = load_scene(spec(a))
    path = generate(a.path_kind, scene, a.frames)
    if not 0 <= a.frame < len(path):
        raise InputError.of("frame", f"must be in 0..{len(path) - 1}, got {a.frame}")
    s = depth.run(scene, path.camera(a.frame), size, Path(a.out))
    print(f"{scene.name} frame {a.frame} at {size[0]}x{size[1]}: coverage {s.get('coverage', 0):.1%}, "
          f"mean depth complexity d = {s['mean_d']:.2f} (max {s['max_d']}), measured overdraw o = {s['mean_o']:.2f}, "
          f"model o(d) = 1 + 1/2 + ... + 1/d: {s['model_o']:.2f}")
    print(f"images and depth.json in {a.out}/")
    return 0


def scene_scan(a) -> int:
    from pathlib import Path

    from multigpu.scene.scan import MIN_TRIANGLES, write_scan

    out = Path(a.out)
    if a.triangles < MIN_TRIANGLES:
        raise InputError.of("triangles", f"a scan needs at least {MIN_TRIANGLES}, got {a.triangles}")
    if out.suffix.lower() != ".ply":
        raise InputError(f"scene scan writes PLY: name the file *.ply, got '{out}'")
    if not out.parent.is_dir():
        raise InputError(f"scene scan: directory '{out.parent}' does not exist")
    write_scan(out, a.triangles, a.seed)
    print(f"wrote {out} ({out.stat().st_size / 2**20:.1f} MiB); walk it: launch/walkthrough --model {out} "
          f"--split grid:8 --path-kind orbit")
    return 0


def scene_info(a) -> int:
    import resource
    from pathlib import Path

    from multigpu.scene.models import axis_name, load_scene

    src = a.source
    is_file = Path(src).suffix != "" or Path(src).exists()
    wanted = spec(a, scene=a.scene if is_file else src, model=src if is_file else a.model)
    scene, info = load_scene(wanted, use_cache=not a.no_cache)
    lo, hi = scene.bounds
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tris = scene.tris
    print(f"scene      {scene.name}")
    series = scene.meta.get("series")
    if series:  # a time series (``scene/series.py``): what follows is its first step's
        t0, t1 = series["times"]
        print(f"series     {series['steps']} steps ({series['source']}), times {t0:g} .. {t1:g}; step "
              f"{series['step']} below ({Path(series['first']).name} .. {Path(series['last']).name})")
    print(f"objects    {scene.n_objects}")
    median = int(sorted(tris)[len(tris) // 2]) if len(tris) else 0
    print(f"triangles  {scene.n_triangles} (per object: min {tris.min()}, median {median}, max {tris.max()})")
    print(f"vertices   {scene.vertices.shape[0]}")
    print(f"bounds     {lo.round(3).tolist()} .. {hi.round(3).tolist()}")
    print(f"up         {axis_name(scene.meta.get('up', [0, 0, 1]))} ({scene.meta.get('up_source', 'as generated')})")
    objs = scene.meta.get("objects", {})
    if objs:
        print(f"split      {objs['split']}: {objs['modelled']} objects as modelled -> {objs['objects']}; {objs['why']}")
    look = scene.meta.get("look")
    if look:
        per_vertex = "kept per vertex" if look.get("vertex_colors") else "one per object"
        print(f"colours    {look['colors']} ({look['materials']} materials; {per_vertex})"
              if look["colors"] != "none" else "colours    none in the file: one neutral grey (--colors objects: "
                                               "a colour per object)")
        tex = look.get("textures") or {"count": 0}
        if tex["count"]:
            print(f"textures   {tex['count']} ({tex['pixels']:,} pixels, the largest {tex['largest'][0]}x"
                  f"{tex['largest'][1]}; {tex['mib']:.2f} MiB with their mip levels)")
        print(f"normals    {look['normals']}")
        a = look.get("alpha") or {}
        if a.get("mask") or a.get("blend_drawn_opaque"):
            print(f"alpha      MASK: {a['mask']} parts, {a['masked_faces']} faces below the cutoff left out; "
                  f"BLEND: {a['blend_drawn_opaque']} parts drawn opaque")
    sim = scene.meta.get("simulation")
    if sim:  # a simulation's fields (``scene/simulation.py``) and what colours the surface
        for f in sim["fields"]:
            lo, hi = f["range"]
            parts = f"{f['components']} components, magnitude" if f["components"] > 1 else "1 component"
            print(f"field      {f['name']}: per {f['where']}, {parts} {lo:.6g} .. {hi:.6g}")
        cb = sim.get("color_by")
        print(f"colour by  {cb['field']} (per {cb['where']}), {cb['colormap']} over {cb['range'][0]:.6g} .. "
              f"{cb['range'][1]:.6g}" if cb else "colour by  nothing (--color-by FIELD colours the surface)")
    per_tri = scene.nbytes / max(scene.n_triangles, 1)
    lods = scene.meta.get("lods")
    if lods:
        borders = "locked" if lods["locked_borders"] else "free"
        print(f"levels     {lods['levels']} of detail: {lods['objects']} objects simplified, the coarsest "
              f"{lods['coarsest_triangles']} triangles in all (borders {borders})")
    print(f"memory     {scene.nbytes / 2**20:.1f} MiB in arrays ({per_tri:.1f} B/triangle), peak RSS {peak:.0f} MiB")
    where = ", " + info["cache"] if info["cache"] else ""
    print(f"load       {info['seconds']:.3f} s ({'cache hit' if info['cached'] else 'built'}{where})")
    for w in scene.meta.get("warnings", []):
        print(f"warning    {w}")
    return 0


def path_make(a) -> int:
    from multigpu.scene.models import load_scene
    from multigpu.scene.paths import GENERATORS, generate

    if a.kind not in GENERATORS:
        raise InputError(f"path kind must be one of {', '.join(GENERATORS)}, got '{a.kind}'")
    if a.frames is not None and a.frames < 1:
        raise InputError.of("frames", f"must be >= 1, got {a.frames}")
    scene, _ = load_scene(spec(a))
    path = generate(a.kind, scene, a.frames, fov=a.fov)
    path.save(a.out)
    print(f"wrote {a.out}: {len(path)} frames ({a.kind} of {scene.name})")
    return 0


def wall_check(a) -> int:
    from multigpu.wall_check import check_command

    print(check_command(a.file, a.grid_only, a.hosts_only, a.offline))
    return 0


def tree(a) -> int:
    from multigpu.config import parse_pair
    from multigpu.core.tree import GpuTree

    rows, cols = parse_pair(a.grid, "grid")
    t = GpuTree(rows, cols)
    print(t.describe())
    for label in range(t.size):
        info = ", ".join(f"({i.method}, {i.nc_l}, {i.nc_r}, {i.side})" for i in t.parinfo[label])
        print(f"GPU{label} tile{t.tile_of(label)} depth {t.depth(label)}: {info}")
    return 0



def warp_make(a) -> int:
    from pathlib import Path

    from multigpu.warp import make, mpcdi
    from multigpu.warp.rig import flat_rig

    if not 2 <= a.projectors <= 16:
        raise InputError.of("projectors", f"must be 2..16, got {a.projectors}")
    if not 0.0 < a.overlap < 0.5:
        raise InputError.of("overlap", f"must be above 0 and below 0.5, got {a.overlap}")
    try:
        w, h = (int(v) for v in a.size.lower().split("x"))
    except ValueError:
        raise InputError.of("size", f"must be WxH in pixels, got '{a.size}'") from None
    if not (16 <= w <= 16384 and 16 <= h <= 16384):
        raise InputError.of("size", f"must be 16..16384 pixels each way, got {w}x{h}")
    canvas = None
    if a.canvas is not None:
        try:
            canvas = tuple(int(v) for v in a.canvas.lower().split("x"))
            assert len(canvas) == 2 and min(canvas) >= 16
        except (ValueError, AssertionError):
            raise InputError.of("canvas", f"must be WxH in pixels (16 and more), got '{a.canvas}'") from None
    try:
        rig = flat_rig(a.projectors, a.overlap, (w, h), kind=a.screen,
                       aspect=None if canvas is None else canvas[0] / canvas[1])
    except ValueError as exc:
        raise InputError.of("canvas", str(exc)) from None
    buffer = canvas or make.buffer_size(rig)
    out = mpcdi.write(Path(a.out), buffer, make.outputs(rig, buffer))
    print(f"wrote {out}: {a.projectors} projectors of {w}x{h} on a {a.screen} screen, {a.overlap:.0%} overlap")
    return 0


def warp_check(a) -> int:
    from pathlib import Path

    import numpy as np

    from multigpu.errors import check_file
    from multigpu.warp import mpcdi

    size, outs = mpcdi.read(check_file(a.file, None, "MPCDI file"))
    print(f"buffer     {size[0]}x{size[1]}, {len(outs)} regions ({Path(a.file).name})")
    for o in outs:
        x, y, w, h = o.area
        finite = o.warp[np.isfinite(o.warp).all(axis=-1)]
        lo, hi = (finite.min(axis=0), finite.max(axis=0)) if len(finite) else ((np.nan,) * 2, (np.nan,) * 2)
        print(f"region     {o.name}: {o.size[0]}x{o.size[1]} pixels at x {x:.4f} y {y:.4f}, {w:.4f} x {h:.4f} of "
              f"the buffer")
        print(f"  warp     {o.warp.shape[1]}x{o.warp.shape[0]} samples, x {lo[0]:.3f}..{hi[0]:.3f}, "
              f"y {lo[1]:.3f}..{hi[1]:.3f}, {100 * (1 - len(finite) / max(o.warp[..., 0].size, 1)):.1f} % NaN")
        for name, m in (("alpha", o.alpha), ("beta", o.beta)):
            print(f"  {name:<8} " + ("none" if m is None else f"{m.min():.4f}..{m.max():.4f} (linear)"))
        for note in o.notes:
            print(f"  note     {note}")
    return 0
