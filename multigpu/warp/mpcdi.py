"""VESA MPCDI files, 2D media profile: the warp and blend of every projector output of a wall.

An ``.mpcdi`` file is a ZIP of ``mpcdi.xml`` and the maps it names. The XML's ``display`` holds a
``buffer`` (the whole picture, ``xResolution`` x ``yResolution``) cut into ``region``s, one per
projector: where the region lies in the buffer (``x``, ``y``, ``xSize``, ``ySize``, normalized)
and its output's size in pixels (``xResolution``, ``yResolution``). Its ``files`` hold a
``fileset`` per region: the ``geometryWarpFile`` (a PFM of normalized region coordinates for a
grid of output points, output-to-content, NaN where the output shows nothing), the ``alphaMap``
and the ``betaMap`` (PNGs, their ``bitDepth`` and the ``gammaEmbedded`` they were written with).

Here a warp's coordinates are (x right, y down) across the region's content, as the rows of every
image are held top first. ``read`` checks what it reads and refuses, in one line naming the file
and what is wrong, a truncated ZIP, another profile, a region without its files (or files of no
region), a PFM that is no warp; an alpha or beta map of another size than its output is resampled
(as the specification allows) and said so in ``Output.notes``. ``write`` makes such a file.
"""

from __future__ import annotations

import functools
import io
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multigpu.core.warpblend import map_values, resample
from multigpu.errors import InputError
from multigpu.warp import pfm

#: how far beyond its region's edges a warp may reach (normalized): further, it is no region's map
REACH = 0.25


@dataclass
class Output:
    """One projector output of an MPCDI file: its region's ``name``, its ``size`` (w, h) in
    pixels, its ``area`` (x, y, w, h) of the buffer (normalized), its ``warp`` (rows, cols, 2)
    and its linear ``alpha`` and ``beta`` at its size (None: none in the file)."""

    name: str
    size: tuple[int, int]
    area: tuple[float, float, float, float]
    warp: np.ndarray
    alpha: np.ndarray | None = None
    beta: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)


def _bad(path, what: str) -> InputError:
    return InputError(f"{path}: {what}")


def _number(elem, name: str, path, kind=float):
    value = elem.get(name)
    try:
        return kind(value)
    except (TypeError, ValueError):
        raise _bad(path, f"region '{elem.get('id')}': attribute {name}={value!r} is not a number") from None


def read(path: Path) -> tuple[tuple[int, int], list[Output]]:
    """((w, h) of the buffer, its outputs) from an ``.mpcdi`` file; read once per version of the
    file in a process (the wall file, the rank's output, its window and the records all ask: the
    maps of three 1080p outputs take most of a second to read). The outputs are shared: read only."""
    path = Path(path)
    try:
        st = path.stat()
    except OSError:
        return _read(path)
    return _read_cached(path, str(path.resolve()), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=4)
def _read_cached(path: Path, _where: str, _mtime: int, _size: int) -> tuple[tuple[int, int], list[Output]]:
    return _read(path)


def _read(path: Path) -> tuple[tuple[int, int], list[Output]]:
    """``read`` itself."""
    try:
        with zipfile.ZipFile(path) as z:
            files = {n: z.read(n) for n in z.namelist()}
    except (zipfile.BadZipFile, EOFError, OSError) as exc:
        raise _bad(path, f"not a complete MPCDI (ZIP) file: {exc}") from None
    xml = files.get("mpcdi.xml")
    if xml is None:
        raise _bad(path, f"holds no mpcdi.xml (it holds: {', '.join(sorted(files)) or 'nothing'})")
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise _bad(path, f"mpcdi.xml is not XML: {exc}") from None
    if root.tag != "MPCDI":
        raise _bad(path, f"mpcdi.xml's root is <{root.tag}>, not <MPCDI>")
    profile = root.get("profile", "")
    if profile != "2d":
        raise _bad(path, f"profile '{profile}' is not supported (2D media only: profile=\"2d\")")
    buffers = root.findall("./display/buffer")
    if len(buffers) != 1:
        raise _bad(path, f"holds {len(buffers)} display buffers: one is supported")
    buf = buffers[0]
    size = (_number(buf, "xResolution", path, int), _number(buf, "yResolution", path, int))
    regions = {r.get("id"): r for r in buf.findall("region")}
    if not regions:
        raise _bad(path, "its buffer has no regions")
    filesets = {f.get("region"): f for f in root.findall("./files/fileset")}
    for name in filesets:
        if name not in regions:
            raise _bad(path, f"a fileset names region '{name}', which the buffer does not have "
                             f"(its regions: {', '.join(regions)})")
    outputs = []
    for name, region in regions.items():
        if name not in filesets:
            raise _bad(path, f"region '{name}' has no fileset (no warp for it)")
        outputs.append(_output(path, files, region, filesets[name]))
    return size, outputs


def _member(path, files: dict, elem, what: str, region: str) -> tuple[str, bytes]:
    got = elem.findtext("path") if elem is not None else None
    if not got:
        raise _bad(path, f"region '{region}': its {what} names no file (<path>)")
    name = got.strip()
    if name not in files:
        raise _bad(path, f"region '{region}': its {what} '{name}' is not in the file")
    return name, files[name]


def _output(path, files: dict, region, fileset) -> Output:
    name = region.get("id")
    size = (_number(region, "xResolution", path, int), _number(region, "yResolution", path, int))
    area = tuple(_number(region, k, path) for k in ("x", "y", "xSize", "ySize"))
    warp_elem = fileset.find("geometryWarpFile")
    member, data = _member(path, files, warp_elem, "geometryWarpFile", name)
    interp = (warp_elem.findtext("interpolation") or "linear").strip()
    if interp != "linear":
        raise _bad(path, f"region '{name}': warp interpolation '{interp}' is not supported (linear)")
    grid = pfm.read(data, f"{path}:{member}")
    if grid.shape[2] != 3:
        raise _bad(path, f"region '{name}': warp {member} has 1 channel (Pf): a warp is PF, x and y per sample")
    rows, cols = grid.shape[:2]
    if rows < 2 or cols < 2 or rows > size[1] + 1 or cols > size[0] + 1:
        raise _bad(path, f"region '{name}': warp {member} is {cols} x {rows} samples for an output of "
                         f"{size[0]} x {size[1]} (2 to one a pixel each way)")
    warp = grid[..., :2].astype(np.float64)
    finite = warp[np.isfinite(warp)]
    if finite.size and (finite.min() < -REACH or finite.max() > 1 + REACH):
        raise _bad(path, f"region '{name}': warp {member} maps outside the content (coordinates "
                         f"{finite.min():.3g} .. {finite.max():.3g}, not 0..1 across the region)")
    out = Output(name, size, area, warp)
    alpha, beta = fileset.find("alphaMap"), fileset.find("betaMap")
    if alpha is not None:
        out.alpha = _map(path, files, alpha, "alphaMap", name, size, out.notes)
    if beta is not None:
        out.beta = _map(path, files, beta, "betaMap", name, size, out.notes)
    return out


def _map(path, files, elem, what: str, region: str, size, notes: list) -> np.ndarray:
    """An alpha or beta map as linear values at the output's size (resampled and said so)."""
    from PIL import Image

    member, data = _member(path, files, elem, what, region)
    try:
        img = np.asarray(Image.open(io.BytesIO(data)))
    except Exception as exc:  # Pillow raises several kinds for a bad image
        raise _bad(path, f"region '{region}': {what} {member} is not an image Pillow reads ({exc})") from None
    depth = int((elem.findtext("bitDepth") or ("16" if img.dtype == np.uint16 else "8")).strip())
    gamma = float((elem.findtext("gammaEmbedded") or "1.0").strip())
    values = map_values(img[..., :3] if img.ndim == 3 else img, depth, gamma)
    if values.shape[:2] != (size[1], size[0]):
        notes.append(f"{what} {member} of {values.shape[1]} x {values.shape[0]} resampled to the output's "
                     f"{size[0]} x {size[1]}")
        values = resample(values, size)
    return values


def write(path: Path, size: tuple[int, int], outputs: list[Output], gamma_embedded: float = 2.2) -> Path:
    """An ``.mpcdi`` file of ``outputs`` on a buffer of ``size``: each warp as a PFM, each alpha and
    beta as a PNG (16-bit grey, 8-bit colour) with ``gamma_embedded``."""
    from PIL import Image

    root = ET.Element("MPCDI", profile="2d", geometry="1", version="2.0")
    buf = ET.SubElement(ET.SubElement(root, "display"), "buffer", id="buffer", xResolution=str(size[0]),
                        yResolution=str(size[1]))
    files = ET.SubElement(root, "files")
    members = {}
    for o in outputs:
        x, y, w, h = o.area
        ET.SubElement(buf, "region", id=o.name, x=repr(float(x)), y=repr(float(y)), xSize=repr(float(w)),
                      ySize=repr(float(h)), xResolution=str(o.size[0]), yResolution=str(o.size[1]))
        fs = ET.SubElement(files, "fileset", region=o.name)
        warp = ET.SubElement(fs, "geometryWarpFile")
        ET.SubElement(warp, "path").text = f"{o.name}_warp.pfm"
        ET.SubElement(warp, "interpolation").text = "linear"
        grid = np.concatenate([o.warp, np.zeros(o.warp.shape[:2] + (1,))], axis=2)
        members[f"{o.name}_warp.pfm"] = pfm.write(grid)
        for which, values in (("alphaMap", o.alpha), ("betaMap", o.beta)):
            if values is None:
                continue
            grey = np.ndim(values) == 2  # 16 bits a value; colour maps in 8 (Pillow's RGB PNGs)
            top, kind = (65535, np.uint16) if grey else (255, np.uint8)
            elem = ET.SubElement(fs, which)
            ET.SubElement(elem, "path").text = f"{o.name}_{which[:-3]}.png"
            ET.SubElement(elem, "componentDepth").text = "1" if grey else "3"
            ET.SubElement(elem, "bitDepth").text = "16" if grey else "8"
            ET.SubElement(elem, "gammaEmbedded").text = repr(float(gamma_embedded))
            coded = np.round(np.clip(values, 0, 1) ** (1 / gamma_embedded) * top).astype(kind)
            png = io.BytesIO()
            Image.fromarray(coded).save(png, format="PNG")
            members[f"{o.name}_{which[:-3]}.png"] = png.getvalue()
    path = Path(path)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("mpcdi.xml", ET.tostring(root, encoding="unicode"))
        for name, data in members.items():
            z.writestr(name, data)
    return path
