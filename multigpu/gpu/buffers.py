"""A scene's GL buffers: their layout, the upload, and one copy per host.

The renderer draws from three buffers: the vertices (position float32 x3 + octahedral normal,
16 bytes), the index buffer in the draw list's spatial order (absolute uint32 indices), and each
vertex's object id (for its colour). Uploaded the ordinary way, every rank's driver holds its own
copy of all three (llvmpipe: in the rank's heap), ~36 bytes a triangle per rank.

Where the scene comes from the cache, the three are also written once beside it, in their GL
layout, to a *buffers file* (``<cache>.gl<VERSION>``; atomically, like the cache). Every rank maps
it read-only, and where the driver can draw straight from host memory (``GL_AMD_pinned_memory``:
Mesa's llvmpipe and radeonsi) the GL buffers *are* the map: the ranks of a host share the page
cache's one copy, and a rank's own memory no longer grows with the scene. Elsewhere (NVIDIA)
the buffers are uploaded from the map, a block at a time. The pixels are the same either way
(tests/test_buffers.py).
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import mmap
import os
import socket
from pathlib import Path

import numpy as np

from multigpu.core.octahedral import encode, pack
from multigpu.errors import InputError

#: the file's layout and the packing it holds (2: levels of detail in the index buffer; 3: wide objects
#: drawn last; 4: the model's vertex colours, where it has them; 5: its texture coordinates, where it has
#: textures; 6: a normal with a coordinate that is not finite coded as +z); a change makes a new name
VERSION = 6
MAGIC = b"MULTIGPU-GL-BUFFERS\n"
PAGE = mmap.PAGESIZE
#: bytes per block when a buffer is uploaded or written
UPLOAD_BLOCK = 16 << 20
_MADV_DONTNEED = 4
_MADV_POPULATE_READ = 22  # Linux 5.14: the pages mapped now, in the calling thread
_GL_EXTERNAL_VIRTUAL_MEMORY_BUFFER_AMD = 0x9160
_GL_STATIC_DRAW = 0x88E4
_GL_BUFFER_SIZE = 0x8764


def pack_normals(normals: np.ndarray) -> np.ndarray:
    """(V,) uint32 octahedral encodings of (V, 3) normals (``core/octahedral.py``: 16 bits per
    coordinate, the vertex shader decodes them; a zero normal reads as +z)."""
    return encode(normals)


def pack_vertices(vertices: np.ndarray) -> np.ndarray:
    """(V, 4) uint32 GL vertices of the scene's (V, 6) float32 ones: the position's three
    float32 as they are, the normal packed (``pack_normals``): 16 bytes a vertex, not 24
    (``core/octahedral.pack``: compiled, one pass)."""
    return pack(vertices)


def _blocks(array: np.ndarray, row_bytes: int):
    """``(first row, rows)`` of ``array`` a block of about ``UPLOAD_BLOCK`` bytes at a time; the
    pages of a read-only file map are unmapped from this process once the caller is done with
    each block (the page cache keeps them for other processes)."""
    rows = max(1, UPLOAD_BLOCK // max(1, row_bytes))
    mapped = isinstance(array, np.memmap) and array.mode == "r"
    for s in range(0, array.shape[0], rows):
        part = array[s:s + rows]
        yield s, part
        if mapped:
            _unmap_pages(part)


def upload(ctx, array: np.ndarray, row_bytes: int, convert=lambda a: a):
    """A GL buffer holding ``convert(block)`` (``row_bytes`` per row of ``array``) for the
    blocks of ``array``, written one block at a time: a rank never holds a read-only file map's
    pages and the driver's copy whole at once."""
    buf = ctx.buffer(reserve=max(4, array.shape[0] * row_bytes))
    for s, part in _blocks(array, row_bytes):
        buf.write(np.ascontiguousarray(convert(part)), offset=s * row_bytes)
    return buf


def _unmap_pages(part: np.ndarray) -> None:
    """Drop this process's mapping of the whole pages under ``part`` (a read-only file map:
    touching them again reads them back from the file)."""
    start = -(-part.ctypes.data // PAGE) * PAGE
    end = (part.ctypes.data + part.nbytes) // PAGE * PAGE
    if end > start:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.madvise(ctypes.c_void_p(start), ctypes.c_size_t(end - start), _MADV_DONTNEED)


def populate(maps: dict[str, np.ndarray]) -> None:
    """Fault in the pages of a buffers file's maps now (``madvise(MADV_POPULATE_READ)``; nothing
    where the kernel has it not): a series' next step, readied in a thread, so the frame that
    first draws it does not stop on each page."""
    libc = ctypes.CDLL(None, use_errno=True)
    for a in maps.values():
        if isinstance(a, np.memmap) and a.nbytes:
            start = a.ctypes.data // PAGE * PAGE
            libc.madvise(ctypes.c_void_p(start), ctypes.c_size_t(a.ctypes.data + a.nbytes - start),
                         _MADV_POPULATE_READ)


# -- the buffers file ------------------------------------------------------------------------

def buffers_path(cache: str | os.PathLike) -> Path:
    """Where the buffers file of the scene cached at ``cache`` lives."""
    cache = Path(cache)
    return cache.with_name(f"{cache.name}.gl{VERSION}")


def _order_digest(draws) -> str:
    """What the index buffer's layout depends on besides the scene: the draw order."""
    return hashlib.sha1(np.ascontiguousarray(draws.order, dtype=np.int64).tobytes()).hexdigest()


def _layout(n_vertices: int, n_indices: int, colors: bool = False, texcoords: bool = False, texels: int = 0
            ) -> dict[str, tuple[int, int]]:
    """Byte offset and length of each array in the file, every one starting on a page (``colors``:
    each vertex's RGBA8 as one uint32, only where the scene has vertex colours; ``texcoords``:
    each vertex's UV and texture layer, 3 float32, and ``texels`` its textures' pool, RGBA8
    words, only where it has textures)."""
    out, at = {}, PAGE  # the first page: magic and header
    for name, nbytes in (("vertices", 16 * n_vertices), ("indices", 4 * n_indices), ("objects", 4 * n_vertices),
                         ("colors", 4 * n_vertices if colors else 0),
                         ("texcoords", 12 * n_vertices if texcoords else 0), ("texels", 4 * texels)):
        out[name] = (at, nbytes)
        at += -(-nbytes // PAGE) * PAGE
    out["end"] = (at, 0)
    return out


def write_buffers(path: Path, scene, draws) -> None:
    """Write ``scene``'s GL buffers (``draws``' order) to ``path``, atomically: a temporary
    file beside it, then a rename, so a reader never sees it half-written and two writers
    (ranks of two hosts sharing the directory) leave one whole file."""
    nv, ni, colors, uv = scene.vertices.shape[0], draws.total, scene.vertex_colors is not None, _textured(scene)
    lay = _layout(nv, ni, colors, uv, _n_texels(scene))
    head = json.dumps(_head(scene, draws)).encode()
    if len(MAGIC) + len(head) + 1 > PAGE:
        raise ValueError("buffers file header too long")
    tmp = path.with_name(f"{path.name}.tmp-{socket.gethostname()}-{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            fh.write(MAGIC + head + b"\n")
            fh.truncate(lay["end"][0])
            at = lay["vertices"][0]
            for s, part in _blocks(scene.vertices, 24):
                fh.seek(at + 16 * s)
                fh.write(pack_vertices(part).tobytes())
            for s, block in draws.index_blocks():
                fh.seek(lay["indices"][0] + 4 * s)
                fh.write(block.tobytes())
            fh.seek(lay["objects"][0])
            fh.write(draws.vertex_object.tobytes())
            if colors:
                fh.seek(lay["colors"][0])
                fh.write(np.ascontiguousarray(scene.vertex_colors, dtype=np.uint8).tobytes())
            if uv:
                fh.seek(lay["texcoords"][0])
                for s, part in _blocks(scene.texcoords, 12):
                    fh.write(np.ascontiguousarray(part, dtype=np.float32).tobytes())
                fh.seek(lay["texels"][0])
                for s, part in _blocks(scene.texels, 4):
                    fh.write(np.ascontiguousarray(part, dtype=np.uint32).tobytes())
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def _head(scene, draws) -> dict:
    """The header a buffers file of ``scene`` in ``draws``' order holds."""
    return {"version": VERSION, "vertices": scene.vertices.shape[0], "indices": draws.total,
            "objects": scene.n_objects, "colors": scene.vertex_colors is not None, "texcoords": _textured(scene),
            "texels": _n_texels(scene), "order": _order_digest(draws)}


def _textured(scene) -> bool:
    return getattr(scene, "texcoords", None) is not None


def _n_texels(scene) -> int:
    return int(scene.texels.shape[0]) if _textured(scene) else 0


def map_buffers(path: Path, scene, draws) -> dict[str, np.ndarray] | None:
    """Read-only maps of the buffers file at ``path`` for ``scene`` drawn in ``draws``' order:
    ``vertices`` (V, 4) uint32, ``indices`` (I,) uint32, ``objects`` (V,) uint32 and, where the
    scene has vertex colours, ``colors`` (V,) uint32 (RGBA8), and where it has textures,
    ``texcoords`` (V, 3) float32 and ``texels`` (N,) uint32; None when the file is missing or was
    written for another scene, order or version."""
    nv, ni, colors, uv = scene.vertices.shape[0], draws.total, scene.vertex_colors is not None, _textured(scene)
    lay = _layout(nv, ni, colors, uv, _n_texels(scene))
    try:
        with open(path, "rb") as fh:
            first = fh.read(PAGE)
            size = os.fstat(fh.fileno()).st_size
    except OSError:
        return None
    if not first.startswith(MAGIC) or size != lay["end"][0]:
        return None
    try:
        head = json.loads(first[len(MAGIC):].split(b"\n", 1)[0])
    except ValueError:
        return None
    if head != _head(scene, draws):
        return None
    shapes = {"vertices": (nv, 4), "indices": (ni,), "objects": (nv,), **({"colors": (nv,)} if colors else {}),
              **({"texcoords": (nv, 3), "texels": (_n_texels(scene),)} if uv else {})}
    dtype = lambda k: np.float32 if k == "texcoords" else np.uint32
    return {k: np.memmap(path, dtype=dtype(k), mode="r", offset=lay[k][0], shape=shapes[k])
            if lay[k][1] else np.zeros(shapes[k], dtype=dtype(k)) for k in shapes}


def ensure_buffers(cache: str | os.PathLike | None, scene) -> Path | None:
    """The buffers file of the scene cached at ``cache``, written now if missing or stale;
    None where there is no cache or it cannot be written (a read-only cache: the renderer
    then uploads from the scene as before), or where ``MULTIGPU_GL_BUFFERS=upload`` asks every
    rank to upload its own copy (a driver that misbehaves on host memory; A/B measurements)."""
    how = os.environ.get("MULTIGPU_GL_BUFFERS", "shared")
    if how not in ("shared", "upload"):
        raise InputError(f"MULTIGPU_GL_BUFFERS must be 'shared' or 'upload', got '{how}'")
    if not cache or scene.vertices.shape[0] == 0 or how == "upload":
        return None
    from multigpu.core.drawlist import DrawList

    path = buffers_path(cache)
    draws = DrawList(scene)
    if map_buffers(path, scene, draws) is None:
        try:
            write_buffers(path, scene, draws)
        except OSError:
            return None
    return path


# -- GL buffers that are the map itself --------------------------------------------------------

class _GL:
    """The three GL entry points the pinned buffers need, from the process's GL library (with
    libglvnd they dispatch to the current context, EGL's or a window's GLX one)."""

    def __init__(self):
        for name in ("libOpenGL.so.0", "libGL.so.1"):
            try:
                lib = ctypes.CDLL(name)
                break
            except OSError:
                continue
        else:
            raise OSError("no libOpenGL.so.0 or libGL.so.1")
        self.bind, self.data, self.param = lib.glBindBuffer, lib.glBufferData, lib.glGetBufferParameteri64v
        self.bind.argtypes = [ctypes.c_uint, ctypes.c_uint]
        self.data.argtypes = [ctypes.c_uint, ctypes.c_ssize_t, ctypes.c_void_p, ctypes.c_uint]
        self.param.argtypes = [ctypes.c_uint, ctypes.c_uint, ctypes.POINTER(ctypes.c_int64)]


def can_pin(ctx) -> str | None:
    """None where ``ctx`` can draw from host memory (``GL_AMD_pinned_memory``), else why not."""
    if "GL_AMD_pinned_memory" not in ctx.extensions:
        return "this GL has no GL_AMD_pinned_memory"
    try:
        _GL()
    except (OSError, AttributeError) as exc:
        return f"GL entry points not found ({exc})"
    return None


def pinned(ctx, array: np.ndarray):
    """A GL buffer whose storage is ``array``'s memory (page-aligned, kept alive by the caller
    for as long as the buffer lives), or None where the driver refused it."""
    if array.nbytes == 0:
        return ctx.buffer(reserve=4)
    gl = _GL()
    buf = ctx.buffer(reserve=4)
    target = _GL_EXTERNAL_VIRTUAL_MEMORY_BUFFER_AMD
    gl.bind(target, buf.glo)
    gl.data(target, array.nbytes, array.ctypes.data, _GL_STATIC_DRAW)
    got = ctypes.c_int64(0)
    gl.param(target, _GL_BUFFER_SIZE, ctypes.byref(got))
    gl.bind(target, 0)
    if got.value != array.nbytes:
        ctx.error  # consume the refusal's GL error
        buf.release()
        return None
    return buf
