"""A simulation's time series: its step files, their times, the step a scene time shows, and the
colour range over every step.

``--model`` names a series as a glob (``'run/step_*.vtu'``: the files in natural order, numbers by
value), ParaView's ``.pvd`` collection (its ``DataSet`` entries: ``timestep`` and ``file``, one
file a step; a step's further parts are named in a warning) or an XDMF time series (one file, its
steps unpacked once into the cache: ``scene/xdmf_series.py``). Each step is read as one model file
(``scene/simulation.py``), cached as its own scene. A step plays at ``--steps-per-second`` of scene
time (``core.motion.scene_time``: the frame's, so every rank, a replay and a restart agree), looping
or holding the last step at the end (``--at-end``). The colour range of ``--color-by`` is taken over
the whole series once (never per step, so colours compare across time) and kept beside the cache.
Pure: no MPI, no GL.
"""

from __future__ import annotations

import functools
import glob
import hashlib
import json
import math
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multigpu.errors import InputError

#: what ``--at-end`` may say: start again, keep showing the last step, or end the run once it was shown
ENDS = ("loop", "hold", "stop")
#: the characters that make ``--model`` a glob
GLOB = re.compile(r"[*?\[]")


@dataclass(frozen=True)
class Series:
    """A series' step files in order, each step's own time (the PVD's ``timestep``, else its
    index), where it came from (``glob`` or the ``.pvd``) and warnings for ``scene info``."""

    paths: tuple[Path, ...]
    times: tuple[float, ...]
    source: str
    warnings: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.paths)

    @property
    def name(self) -> str:
        """The series' name in titles: the ``.pvd``'s or XDMF file's stem, or the glob's file pattern."""
        kind, _, where = self.source.partition(" ")
        return Path(where).stem if kind in ("pvd", "xdmf") else Path(where).name


def is_series(model: str | None) -> bool:
    """Whether ``--model`` names a series (a glob, a ``.pvd`` or an XDMF time series), not one file."""
    from multigpu.scene.xdmf_series import is_temporal

    return model is not None and (bool(GLOB.search(str(model))) or str(model).lower().endswith(".pvd")
                                  or is_temporal(str(model)))


def _natural(path: str) -> list:
    """Sort key: the name's numbers by value (``step_10`` after ``step_9``)."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path)]


def find_series(model: str) -> Series:
    """The series ``--model`` names, or one line saying why there is none: no file matches the
    glob, a ``.pvd`` is missing, unreadable, or lists no step."""
    text = str(model)
    if text.lower().endswith(".pvd") and not GLOB.search(text):
        return _pvd(Path(text).expanduser())
    from multigpu.scene.xdmf_series import is_temporal, unpack

    if is_temporal(text):
        paths, times = unpack(Path(text))
        return Series(tuple(paths), tuple(times), f"xdmf {text}")
    found = sorted((p for p in glob.glob(str(Path(text).expanduser())) if Path(p).is_file()), key=_natural)
    if not found:
        raise InputError.of("model", f"{text}: no file matches this series pattern")
    return Series(tuple(Path(p) for p in found), tuple(float(i) for i in range(len(found))), f"glob {text}")


def _pvd(path: Path) -> Series:
    """A ParaView collection's steps in timestep order (its files relative to the ``.pvd``)."""
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise InputError.of("model", f"{path}: no such file") from None
    except (OSError, ET.ParseError) as exc:
        raise InputError.of("model", f"{path}: not a readable ParaView collection ({exc})") from None
    sets = root.findall("./Collection/DataSet")
    if root.tag != "VTKFile" or not sets:
        raise InputError.of("model", f"{path}: not a ParaView collection: no VTKFile/Collection/DataSet entries")
    steps: dict[float, list[str]] = {}
    for d in sets:
        name = d.get("file")
        try:
            t = float(d.get("timestep", len(steps)))
        except ValueError:
            raise InputError.of("model", f"{path}: a DataSet's timestep is not a number: "
                                         f"'{d.get('timestep')}'") from None
        if not name or not math.isfinite(t):
            raise InputError.of("model", f"{path}: a DataSet without a file or with a non-finite timestep")
        steps.setdefault(t, []).append(name)
    times = sorted(steps)
    warnings = ()
    parts = sum(len(v) - 1 for v in steps.values())
    if parts:
        warnings = (f"{parts} further parts of steps not drawn (the first DataSet of each timestep is)",)
    return Series(tuple((path.parent / steps[t][0]) for t in times), tuple(times), f"pvd {path}", warnings)


def step_at(t: float, rate: float, n: int, end: str = "loop") -> int:
    """The step scene time ``t`` shows at ``rate`` steps a second: looping, or holding the last
    (and the first before time 0)."""
    k = math.floor(t * rate + 1e-9)
    if end == "loop":
        return k % n
    return min(max(k, 0), n - 1)


def after(k: int, n: int, end: str = "loop") -> int | None:
    """The step played after ``k`` (None: the last of a held series)."""
    if k + 1 < n:
        return k + 1
    return 0 if end == "loop" and n > 1 else None


def on_the_way(shown: int, ready: int, want: int, n: int, end: str = "loop") -> bool:
    """Whether showing ``ready`` now moves the wall from ``shown`` towards ``want`` without passing
    it: the wanted step itself, or one between (forward, round the loop where it loops)."""
    if ready == shown:
        return False
    if ready == want:
        return True
    if end == "loop":
        ahead, goal = (ready - shown) % n, (want - shown) % n
        return 0 < ahead < goal
    return min(shown, want) < ready < max(shown, want)


def _range_key(series: Series, field: str) -> str:
    stats = [(str(p.resolve()), p.stat().st_size, p.stat().st_mtime_ns) for p in series.paths]
    return hashlib.sha1(repr((stats, field)).encode()).hexdigest()[:16]


def series_range(series: Series, field: str, cache: Path | None = None) -> tuple[float, float, list[str]]:
    """The least and greatest finite value of ``--color-by field`` over every step (read once and
    kept in ``cache``, keyed by the files and the field), and a line for each later step left out
    (it cannot be read, or lacks the field: the run holds the step before it there). The first
    step that cannot be read, or lacks the field, is the one line of an ``InputError``."""
    from multigpu.scene import simulation

    where = None if cache is None else cache / f"series-range-{_range_key(series, field)}.json"
    if where is not None and where.is_file():
        try:
            got = json.loads(where.read_text())
            return float(got["range"][0]), float(got["range"][1]), [str(w) for w in got.get("left_out", [])]
        except (OSError, ValueError, KeyError, TypeError, IndexError):
            pass
    lo, hi, left_out = math.inf, -math.inf, []
    for k, path in enumerate(series.paths):
        try:
            mesh = simulation.read(path)
            values, _, _ = simulation.field(mesh, field, path)
        except InputError as exc:
            if k == 0:
                raise InputError.of(exc.field or "model", f"step 0 of the series: {exc.message}") from None
            left_out.append(f"step {k} of the series: {exc.message} (left out of the colour range)")
            continue
        finite = values[np.isfinite(values)]
        if finite.size:
            lo, hi = min(lo, float(finite.min())), max(hi, float(finite.max()))
    if not lo <= hi:
        lo, hi = 0.0, 1.0
    if where is not None:
        try:
            where.parent.mkdir(parents=True, exist_ok=True)
            tmp = where.with_suffix(f".tmp-{os.getpid()}")
            tmp.write_text(json.dumps({"range": [lo, hi], "field": field, "steps": len(series), "left_out": left_out}))
            tmp.replace(where)
        except OSError:
            pass  # a read-only cache only costs time
    return lo, hi, left_out


def first_range(path: Path, field: str) -> tuple[float, float]:
    """The finite values' range of ``field`` in one step's file (a live stream's first step: the
    colours of the steps to come compare with it); read once while the file stays as it is (rank
    0 asks twice at a stream's setup)."""
    try:
        st = Path(path).stat()
    except OSError:  # (the reader says why, in its line)
        return _first_range.__wrapped__(str(path), field, None)
    return _first_range(str(path), field, (st.st_size, st.st_mtime_ns))


@functools.lru_cache(maxsize=4)
def _first_range(path: str, field: str, version: tuple) -> tuple[float, float]:
    from multigpu.scene import simulation

    mesh = simulation.read(Path(path))
    values, _, _ = simulation.field(mesh, field, path)
    return simulation.value_range(values, None)


def describe(series: Series) -> dict:
    """What ``scene info`` says of a series: its steps, their times, where it came from."""
    return {"steps": len(series), "source": series.source, "times": [series.times[0], series.times[-1]],
            "first": str(series.paths[0]), "last": str(series.paths[-1]), "warnings": list(series.warnings)}
