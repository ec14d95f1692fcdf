"""An XDMF time series (one ``.xdmf``/``.xmf`` file whose grid is a temporal collection, as
ParaView, FEniCS/dolfinx and many simulation codes write them, their heavy data in HDF5): its
steps unpacked once into a series of VTU files in the cache (``scene/series.py`` plays them as
any series: each step its own cached scene, the colour range over all of them).

The unpacking runs once per file version (its path, size and modification time name the cache
entry) through meshio's ``TimeSeriesReader``: the mesh once, each step's point and cell data with
its time. HDF5 data needs ``h5py``. A file that meshio cannot read, or one with no step, is one
line naming the file. Pure: no MPI, no GL.
"""

from __future__ import annotations

import hashlib
import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path

from multigpu.errors import InputError
from multigpu.scene.cachedir import cache_dir

#: the suffixes of XDMF files
SUFFIXES = (".xdmf", ".xmf")


def is_temporal(path: str) -> bool:
    """Whether ``path`` is an XDMF file whose grid is a temporal collection (a time series); a
    file that cannot be parsed is not (the model loader says why)."""
    if not str(path).lower().endswith(SUFFIXES) or not Path(path).is_file():
        return False
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        return False
    return any(g.get("CollectionType", "").lower() == "temporal" for g in root.iter("Grid"))


def unpack(path: Path) -> tuple[list[Path], list[float]]:
    """The step files (VTU, in the cache) and times of the XDMF time series at ``path``, made at
    its first use."""
    path = Path(path).expanduser()
    st = path.stat()
    key = hashlib.sha1(f"{path.resolve()}\0{st.st_size}\0{st.st_mtime_ns}".encode()).hexdigest()[:16]
    where = cache_dir() / f"xdmf-{key}"
    index = where / "steps.json"
    if index.is_file():
        doc = json.loads(index.read_text())
        return [where / n for n in doc["files"]], [float(t) for t in doc["times"]]
    import meshio

    where.mkdir(parents=True, exist_ok=True)
    files, times = [], []
    try:
        with meshio.xdmf.TimeSeriesReader(str(path)) as reader:
            points, cells = reader.read_points_cells()
            for k in range(reader.num_steps):  # steps, each written whole
                t, point_data, cell_data = reader.read_data(k)
                name = f"step_{k:06d}.vtu"
                tmp = where / f".{name}-{os.getpid()}.vtu"
                meshio.write(tmp, meshio.Mesh(points, cells, point_data=point_data, cell_data=cell_data), binary=True)
                tmp.replace(where / name)
                files.append(name)
                times.append(float(t))
    except ModuleNotFoundError as exc:
        raise InputError.of("model", f"{path}: its HDF5 data needs h5py (pip install h5py): {exc}") from None
    except Exception as exc:  # noqa: BLE001 (meshio raises what its readers raise, a line each)
        raise InputError.of("model", f"{path}: not a readable XDMF time series ({exc.__class__.__name__}: "
                                     f"{str(exc).strip().splitlines()[-1] if str(exc).strip() else ''})") from None
    if not files:
        raise InputError.of("model", f"{path}: an XDMF time series with no step")
    tmp = where / f".steps-{os.getpid()}.json"
    tmp.write_text(json.dumps({"source": str(path), "files": files, "times": times}))
    tmp.replace(index)
    return [where / n for n in files], times
