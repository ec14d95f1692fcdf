"""Scenes from names and files: the built-in scenes, users' models (``scene/files.py``), the cache.

Objects (``--split``): ``auto`` (default) takes one object per node instance of a scene graph
(glTF/GLB, multi-object OBJ; transforms applied) and the connected components of a single
mesh; ``components`` and ``grid:N`` (N cells along the longest axis, the paper's future-work
idea) apply to any file, scene graphs included. With components, pieces under ``merge_below``
triangles are merged by grid cell so object counts stay sane. Then, for the wall the scene is
loaded for (``ranks``), objects too big to balance are cut into spatial clusters
(``cluster.auto_cluster``: no object above 1/(4K) of the triangles, at least 8 objects per
rank, and on walls of 9+ ranks no object above 1/(64K)), unless ``--cluster N`` (explicit
size, 0 = never) says otherwise. ``meta['objects']`` records what was done and why. Faces
with non-finite vertices and degenerate faces are dropped and counted
(``scene.meta['warnings']``); a file shorter than its header promises is refused.

Up axis (``meta['up']``, used by generated camera paths): ``--up`` if given; glTF's +Y by its
specification; for a flat scene (smallest extent under 0.35 of the largest: a city, a track) its thin axis; else
the format's usual convention: +Y for OBJ and PLY (Blender/Maya exports, scanned data), +Z for
STL and OFF (CAD, 3-D printing). ``meta['up_source']`` says which rule decided.

Loaded and generated scenes are cached as ``.npz`` in ``$MULTIGPU_CACHE`` (default
``~/.cache/multigpu``), keyed by source path, size, mtime (the texture images' too) and options.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
import re
import time
from dataclasses import dataclass
from pathlib import Path

from multigpu.errors import InputError, check_file
from multigpu.options import check, option, register
from multigpu.scene import lod as scene_lod
from multigpu.scene import parts as scene_parts
from multigpu.scene.cachedir import cache_dir  # noqa: F401 (the cache's folder, read from here too)
from multigpu.scene.files import FORMATS, axis_name, axis_vector, load_model
from multigpu.scene.layout import FORMAT_VERSION, Scene
from multigpu.scene.series import ENDS, find_series, is_series, series_range
from multigpu.scene.series import describe as describe_series
from multigpu.scene.simulation import FORMATS as SIMULATION
from multigpu.scene.simulation import Coloring
from multigpu.scene.stream_mesh import PREFIX as STREAM
from multigpu.scene.textures import image_files

__all__ = ["BUILTIN", "FORMATS", "SceneSpec", "axis_name", "axis_vector", "cache_dir", "load_model", "load_scene"]



def read_cluster(text: str) -> int | None:
    """``--cluster``: ``auto`` (None) or a number of triangles."""
    if str(text).strip() == "auto":
        return None
    try:
        return int(text)
    except ValueError:
        raise InputError(f"must be 'auto' or a number of triangles (0: never), got '{text}'") from None


def read_range(text: str) -> tuple[float, float]:
    """``--range MIN,MAX``: two finite numbers, the first below the second."""
    try:
        lo, hi = (float(v) for v in str(text).split(","))
    except ValueError:
        raise InputError(f"must be MIN,MAX (two numbers), got '{text}'") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise InputError(f"must be two finite numbers, MIN below MAX, got '{text}'")
    return lo, hi


@dataclass(frozen=True)
class SceneSpec:
    """What to load: a built-in scene by name or a model file, and how to split it; each
    setting declared once with its flag (``options.py``)."""

    scene: str = option("plant", group="scene", metavar=lambda: "|".join(BUILTIN), help="a built-in scene")
    model: str | None = option(None, group="scene", metavar="FILE|'GLOB'|SERIES.pvd|adios2:NAME",
                               help="model file (OBJ, PLY, STL, OFF, glTF/GLB; a simulation's VTU, VTP, VTK, XDMF, "
                                    "Exodus, Gmsh, ... through meshio) instead of --scene; a simulation's time "
                                    "series as a quoted glob of its step files, ParaView's .pvd or an XDMF time "
                                    "series; a running "
                                    "code's steps as adios2:STREAM (SST) or adios2:FILE.bp (BP5, followed as it "
                                    "grows)")
    split: str = option("auto", group="scene", metavar="auto|components|grid:N",
                        valid=lambda v: re.fullmatch(r"auto|components|grid:[1-9][0-9]*", v) is not None,
                        must="must be 'auto', 'components' or 'grid:N' with N >= 1", help=(
        "objects of a model: scene-graph nodes (else connected components), connected components, or an N^3 grid "
        "of cells (any file)"))
    merge_below: int = option(64, group="scene", metavar="N", type=int, help="merge components under this many "
                                                                            "triangles")
    triangles: int = option(100_000, group="scene", metavar="N", type=int, valid=lambda v: v >= 1000,
                            must="must be >= 1000", help="built-in scene size in triangles")
    copies: int = option(1, group="scene", metavar="N", type=int, valid=lambda v: v >= 1, must="must be >= 1",
                         help="built-in scenes side by side (the paper used 6..20 plants)")
    seed: int = option(0, group="scene", metavar="N", type=int, valid=lambda v: v >= 0, must="must be >= 0",
                       help="built-in scenes: the random seed")
    # cut objects above N triangles into clusters (0: never; None: auto)
    cluster: int | None = option(None, group="scene", metavar="auto|N|0", read=read_cluster, text="auto",
                                 valid=lambda v: v is None or v >= 0, must="must be >= 0 (0 keeps objects whole)",
                                 help=("cut objects above N triangles into spatial clusters of at most N (auto: when "
                                       "an object is too big to balance on the wall; 0: keep objects as modelled)"))
    ranks: int = 4  # the wall the scene is prepared for (automatic clustering)
    up: str | None = option(None, group="scene", metavar="x|y|z|-x|-y|-z",
                            valid=lambda v: v is None or re.fullmatch(r"[+-]?[xyz]", v) is not None,
                            must="must be one of x, y, z, -x, -y, -z",
                            help="up axis of the model (default: the format's convention, see scene info)")
    # -- a simulation's colours (``scene/simulation.py``): a part of the cached scene
    color_by: str | None = option(None, group="scene", metavar="FIELD[:magnitude|:x|:y|:z|:K]", help=(
        "colour a simulation's surface by this point or cell field (a vector's magnitude, or a component); "
        "scene info lists the fields"))
    colormap: str = option("viridis", group="scene", metavar="NAME", help="the colour map of --color-by "
                                                                           "(matplotlib's names)")
    color_range: tuple[float, float] | None = option(None, group="scene", metavar="MIN,MAX", flag="--range",
                                                     read=read_range, help=(
        "the --color-by values at the colour map's ends (default: the field's own range)"))
    color_bar: bool = option(False, group="scene", switch=True, help=(
        "show the --color-by colour bar on the wall too (bottom left; the annotated mosaics always carry it)"))
    lods: bool = True  # build (and cache, and hold) levels of detail: only where the run can draw them
    # -- what moves (``scene/moves.py``): no part of the cached scene, only of its motion
    moving: float = option(0.0, group="scene", metavar="FRACTION", type=float,
                           valid=lambda v: 0.0 <= v <= 1.0, must="must be in 0..1", help=(
        "this share of the scene's objects move as machinery does: turning, sliding or orbiting"))
    animation: str = option("all", group="scene", metavar="NAME|all|none", help=(
        "a glTF model's animations played, looped over the path: all, none, or the one of this name"))
    anim_speed: float = option(1.0, group="scene", metavar="S", type=float, valid=lambda v: abs(v) <= 1000.0,
                               must="must be a number in -1000..1000", help=(
        "scene time runs at S seconds a second of the path (frames at 30 a second; 0 holds the scene at rest, "
        "below 0 plays it backwards)"))

    # -- a time series (``scene/series.py``): how its steps play
    steps_per_second: float = option(10.0, group="scene", metavar="R", type=float,
                                     valid=lambda v: 0.0 < v <= 1000.0, must="must be in (0, 1000]", help=(
        "a series' steps a second of scene time (--anim-speed scales it; the panel pauses, steps and scrubs)"))
    at_end: str = option("loop", group="scene", metavar="|".join(ENDS), valid=lambda v: v in ENDS,
                         must=f"must be one of {', '.join(ENDS)}", help=(
        "after a series' last step (a stream's end): play it again from the first (a file series), hold the "
        "last, or stop the run once it was shown"))
    late_step: str = option("hold", group="scene", metavar="hold|wait", valid=lambda v: v in ("hold", "wait"),
                            must="must be 'hold' or 'wait'", help=(
        "a series' step not read in time: the wall holds the step it shows (a live wall never waits), or waits "
        "for it (every step at its own frames: recordings, videos)"))
    step: int = 0  # the step of a series this spec loads (the frame loop's reader asks for each)
    live: bool = False  # the series is a live stream's, growing as the run goes (``rank/spool.py``)

    def __post_init__(self):
        if self.model is None and self.scene not in BUILTIN:
            known = ", ".join(BUILTIN)
            raise InputError.of("scene", f"must be one of {known} (or give a model file), got '{self.scene}'")
        check(self)
        if self.ranks < 1:
            raise InputError(f"ranks must be >= 1, got {self.ranks}")


register(SceneSpec)


def _key(*parts) -> str:
    """The cache key: the format, the part size and levels of detail (the cached layout), the spec."""
    shape = (FORMAT_VERSION, scene_parts.PART_TRIS, scene_lod.LEVELS, scene_lod.RATIO, scene_lod.MIN_TRIS)
    return hashlib.sha1(repr(shape + parts).encode()).hexdigest()[:16]


def load_scene(spec: SceneSpec, use_cache: bool = True) -> tuple[Scene, dict]:
    """The scene for ``spec`` and load facts (seconds, whether the cache was hit): of a series
    (``scene/series.py``), its step ``spec.step``, coloured over every step (a bad input's line
    names the step)."""
    if str(spec.model).startswith(STREAM):
        raise InputError.of("model", f"{spec.model}: a stream is read by a walkthrough's rank 0 as it runs "
                                     "(its kept steps, steps/step_*.vtu in the run's outputs, are a series)")
    if not is_series(spec.model):
        return _load_scene(spec, use_cache)
    series = find_series(spec.model)
    k = spec.step
    if not 0 <= k < len(series):
        raise InputError.of("model", f"{spec.model}: no step {k} (the series has {len(series)})")
    fixed, left_out = spec.color_range, []
    if spec.color_by is not None and fixed is None:  # over the whole series, never per step
        lo, hi, left_out = series_range(series, spec.color_by, cache_dir() if use_cache else None)
        fixed = (lo, hi)
    try:
        scene, info = load_step_file(dataclasses.replace(spec, color_range=fixed), series.paths[k], series.paths[0],
                                     use_cache)
    except InputError as exc:
        raise InputError.of(exc.field or "model", f"step {k} of the series: {exc.message}") from None
    scene.meta["series"] = {**describe_series(series), "step": k, "time": series.times[k]}
    scene.meta["warnings"] = [*scene.meta.get("warnings", []), *series.warnings, *left_out]
    scene.name = series.name
    return scene, info


def load_step_file(spec: SceneSpec, path, first, use_cache: bool = True) -> tuple[Scene, dict]:
    """The step of a series in file ``path`` whose first step is file ``first``, coloured over
    ``spec``'s range (the series'): where its cells are the first step's, that step's layout with
    this step's points and colours (``scene/same_cells.py``), else built alone; cached either way."""
    alone = dataclasses.replace(spec, model=str(path), step=0)
    src = Path(path)
    if Path(first) == src or src.suffix.lower() not in SIMULATION:
        return _load_scene(alone, use_cache)
    t0 = time.perf_counter()
    base, base_info = first_step(spec, first, use_cache)
    st = check_file(path, "model", "model file").stat()
    key = _key(str(src.resolve()), st.st_size, st.st_mtime_ns, "cells of", base_info.get("cache") or str(first))
    cache = cache_dir() / f"{src.stem}-{key}.npz"
    marker = cache.with_suffix(".alone")  # its cells differ: built alone (found without reading it again)
    if use_cache and marker.is_file():
        return _load_scene(alone, use_cache)

    def make() -> Scene | None:
        from multigpu.scene.same_cells import derive
        from multigpu.scene.simulation import cells_key, read

        mesh = read(src)
        same = base.meta.get("simulation", {}).get("cells") == cells_key(mesh)
        return derive(base, mesh, Coloring(spec.color_by, spec.colormap, spec.color_range), src) if same else None
    scene, cached = _through_cache(cache, make, use_cache)
    if scene is None:
        if use_cache:
            marker.touch()
        return _load_scene(alone, use_cache)
    if spec.up is not None:
        scene.meta["up"], scene.meta["up_source"] = axis_vector(spec.up), "--up"
    return scene, {"seconds": time.perf_counter() - t0, "cached": cached, "cache": str(cache) if use_cache else None}


def _through_cache(path, make, use_cache: bool) -> tuple[Scene | None, bool]:
    """(the scene cached at ``path``, True), else (``make()``'s, False), saved there and mapped back
    (the built arrays go; the file's pages are shared per host): a damaged file is made again, a
    read-only cache only costs time; (None, False) where ``make`` gives none."""
    if use_cache and path.is_file():
        try:
            return Scene.load(path), True
        except InputError:
            path.unlink(missing_ok=True)  # stale or damaged: made again
    scene = make()
    if scene is not None and use_cache:
        try:
            scene.save(path)
            scene = Scene.load(path)
        except OSError:
            pass
    return scene, False


def step_changes(spec: SceneSpec, mesh, path, first) -> tuple[dict, dict] | None:
    """What the step ``mesh`` (written to ``path``; the series' first step is file ``first``)
    changes of the first step's scene (``same_cells.changes``: made in memory, no file read), or
    None where its cells are not the first step's (it is then built alone: ``load_step_file``)."""
    from multigpu.scene.same_cells import changes
    from multigpu.scene.simulation import cells_key

    base, _ = first_step(spec, first)
    if base.meta.get("simulation", {}).get("cells") != cells_key(mesh):
        return None
    got = changes(base, mesh, Coloring(spec.color_by, spec.colormap, spec.color_range), Path(path))
    if got is not None and spec.up is not None:
        got[1]["up"], got[1]["up_source"] = axis_vector(spec.up), "--up"
    return got


def first_step(spec: SceneSpec, first, use_cache: bool = True) -> tuple[Scene, dict]:
    """The scene of a series' first step, file ``first`` (held while its later steps are made)."""
    fst = check_file(first, "model", "model file").stat()
    return _first_step(dataclasses.replace(spec, model=str(first), step=0, up=None), use_cache,
                       (fst.st_size, fst.st_mtime_ns))


@functools.lru_cache(maxsize=1)
def _first_step(spec: SceneSpec, use_cache: bool, version: tuple) -> tuple[Scene, dict]:
    """A series' first step (``load_step_file``), kept while its later steps load (``version``: its
    file's size and time)."""
    return _load_scene(spec, use_cache)


def _load_scene(spec: SceneSpec, use_cache: bool) -> tuple[Scene, dict]:
    """``load_scene`` of a built-in scene or one model file."""
    t0 = time.perf_counter()
    cluster = "auto" if spec.cluster is None else spec.cluster
    wall = spec.ranks if spec.cluster is None else None  # the automatic choice depends on the wall
    if spec.model is not None:
        src = check_file(spec.model, "model", "model file")
        if src.suffix.lower() not in FORMATS:
            known = ", ".join(sorted(FORMATS))
            raise InputError.of("model", f"{src}: unsupported extension '{src.suffix}' (use {known})")
        st = src.stat()
        images = tuple((str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in image_files(src) if p.is_file())
        coloring = Coloring(spec.color_by, spec.colormap, spec.color_range)
        key = _key(str(src.resolve()), st.st_size, st.st_mtime_ns, spec.split, spec.merge_below, cluster, wall, images,
                   *(() if spec.lods else ("no levels of detail",)),
                   *(() if src.suffix.lower() not in SIMULATION else (coloring,)))
        name = f"{src.stem}-{key}.npz"
        make = lambda: load_model(src, spec.split, spec.merge_below, coloring)
    else:
        key = _key(spec.scene, spec.triangles, spec.copies, spec.seed, cluster, wall,
                   *(() if spec.lods else ("no levels of detail",)))
        name = f"{spec.scene}-{key}.npz"
        make = lambda: BUILTIN[spec.scene](spec)

    def build() -> Scene:
        from multigpu.scene.cluster import auto_cluster, split_objects
        from multigpu.scene.parts import with_parts

        scene = make()
        modelled = scene.n_objects
        if spec.cluster is None:
            size, why = auto_cluster(scene.tris, spec.ranks)
        else:
            size, why = spec.cluster, ("--cluster 0: objects kept as modelled" if spec.cluster == 0
                                       else f"--cluster {spec.cluster}: objects above it cut into clusters")
        if size:
            scene = split_objects(scene, size)
        scene.meta["objects"] = {"split": scene.meta.get("split", spec.split), "modelled": modelled,
                                 "objects": scene.n_objects, "cluster": int(size), "why": why}
        scene = with_parts(scene)  # parts for culling, then levels of detail where the run can use them
        return scene_lod.with_lods(scene) if spec.lods else scene
    path = cache_dir() / name
    scene, cached = _through_cache(path, build, use_cache)
    if spec.up is not None:
        scene.meta["up"], scene.meta["up_source"] = axis_vector(spec.up), "--up"
    info = {"seconds": time.perf_counter() - t0, "cached": cached, "cache": str(path) if use_cache else None}
    return scene, info


def _plant(spec: SceneSpec) -> Scene:
    from multigpu.scene.plant import generate_plant

    return generate_plant(spec.triangles, spec.copies, spec.seed)


def _fill(spec: SceneSpec) -> Scene:
    from multigpu.scene.fill import generate_fill

    return generate_fill(spec.triangles, panels=24 * spec.copies, seed=spec.seed)


def _swarm(spec: SceneSpec) -> Scene:
    from multigpu.scene.swarm import generate_swarm

    return generate_swarm(spec.triangles, spec.seed)


def _city(spec: SceneSpec) -> Scene:
    from multigpu.scene.city import generate_city

    return generate_city(spec.triangles, spec.seed)


# built-in scenes: the plant (triangle-bound, the paper's kind), a fill-bound contrast, a
# city of many small objects on big ground pieces (per-frame overhead) and a swarm whose load
# moves across the wall (``scene/swarm.py``); for ``fill``, ``--copies`` multiplies the 24
# panels (depth complexity)
BUILTIN = {"plant": _plant, "fill": _fill, "city": _city, "swarm": _swarm}
