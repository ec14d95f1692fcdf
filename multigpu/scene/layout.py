"""The GPU-ready scene layout every renderer and experiment consumes.

All objects' vertices (position + normal, float32) live in one buffer and all indices in one
uint32 buffer; object ``i`` is drawn by the indirect command ``(index_count[i], 1,
first_index[i], base_vertex[i], i)``. Per-object bounds (box and sphere, float64) feed the
balancer. Vertex positions are stored relative to the scene's float64 ``origin`` (the centre of
its bounds), so float32 keeps sub-millimetre precision for CAD or geographic data placed 1e6 or
1e8 units from the world origin; the renderer folds ``origin`` into the camera in float64. A
scene saves to and loads from one uncompressed ``.npz`` (the cache format).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multigpu.errors import InputError

#: 11: a simulation's point and cell of each vertex; 10: a glTF model's morph targets and skins;
#: 9: each object's body (the modelled object it was cut from)
#: 7: the model's own colours and normals (vertex colours, materials, crease-angle normals); 6: levels of
#: detail; 5: parts (objects cut inside themselves for culling); 4: objects/up decisions, routes
FORMAT_VERSION = 11


@dataclass
class Scene:
    """Objects in one concatenated layout.

    vertices : (V, 6) float32  position xyz, normal xyz
    indices : (I,) uint32  triangle list, relative to each object's base vertex
    first_index, index_count, base_vertex : (N,) int64  per-object draw ranges
    bmin, bmax : (N, 3) float64  axis-aligned bounding boxes (world space)
    centers : (N, 3) float64, radii : (N,) float64  bounding spheres
    colors : (N, 3) float32  per-object colour in [0, 1]: the model's (its material's, or one neutral
        grey where the file gives none); ``scene/looks.py``
    vertex_colors : (V, 4) uint8 RGBA per vertex where the model's colours vary inside an object
        (vertex colours, or materials mixed in one object); None: each object is ``colors``
    texcoords : (V, 3) float32  a textured model's UV (v down the image) and texture layer per
        vertex (-1: untextured); texels : (N,) uint32  its colour textures' mip chains, RGBA8;
        texture_levels : (T * 16, 4) int32  each layer's levels: first texel, width, height, count;
        texture_modes : (T, 4) float32  each layer's wrap s, wrap t, nearest, alpha cutoff
        (``scene/textures.py``); None: no textures
    origin : (3,) float64  world position of vertex coordinate (0, 0, 0)
    meta : free-form facts (generator options, landmarks for camera paths, warnings)
    part_start : (N+1,) int64  object i's parts are rows part_start[i]:part_start[i+1] of:
    part_count : (P,) int64  index count of each part (an object's parts follow each other in its
        index range, from its ``first_index``)
    part_bmin, part_bmax : (P, 3) float64  each part's bounding box (world space)
    (None: no parts, each object one part; ``scene/parts.py`` makes them)
    lod_first, lod_count : (N, L) int64  object i's level l is drawn by ``lod_count[i, l]`` indices of
        ``indices`` from ``lod_first[i, l]`` (level 0: its own range; coarser levels follow the
        scene's own indices, relative to its base vertex as those)
    lod_error : (N, L) float64  each level's geometric error (world units), non-decreasing
    (None: no levels; ``scene/lod.py`` makes them)
    body : (N,) int64  the modelled object each object was cut from (``scene/cluster.py``): a
        moving scene moves them as one (None: every object a body of its own)
    morph_rows : (V,) int32  a glTF model's morph targets (``scene/gltf_load.py``): each vertex's row
        of ``morph_deltas`` (M, T, 3) float32, its world-space position delta per target (-1: none);
    morph_lo, morph_hi : (N, T, 3) float64  each object's least and greatest delta per target (0
        held): its bounds grown by a frame's weights (None: no morph targets)
    skin_joints, skin_weights : (V, 4) uint16, float32  a glTF model's skins: each vertex's joints in
        the palette and their weights (0: not skinned); skin_pairs (P, 2) int64 (body, joint) and
        skin_boxes (P, 6) float64 world min and max of the body's vertices leaning on the joint
        (None: no skins; ``scene/gltf_load.py``)
    sources : (V, 2) int64  a simulation's point and cell (-1: none) of each vertex in its file
        (``scene/simulation.py``): a later step with the same cells fills this layout from its own
        points and field (``scene/same_cells.py``; None: not a simulation)
    movers : (N,) bool  the objects a run's motion moves where some stand still (``scene/moves.py``:
        set by the run, never cached): the order they are drawn in (``core.drawlist.drawn_order``)
    """

    vertices: np.ndarray
    indices: np.ndarray
    first_index: np.ndarray
    index_count: np.ndarray
    base_vertex: np.ndarray
    bmin: np.ndarray
    bmax: np.ndarray
    centers: np.ndarray
    radii: np.ndarray
    colors: np.ndarray
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    name: str = "scene"
    meta: dict = field(default_factory=dict)
    part_start: np.ndarray | None = None
    part_count: np.ndarray | None = None
    part_bmin: np.ndarray | None = None
    part_bmax: np.ndarray | None = None
    lod_first: np.ndarray | None = None
    lod_count: np.ndarray | None = None
    lod_error: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None
    texcoords: np.ndarray | None = None
    texels: np.ndarray | None = None
    texture_levels: np.ndarray | None = None
    texture_modes: np.ndarray | None = None
    body: np.ndarray | None = None
    morph_rows: np.ndarray | None = None
    morph_deltas: np.ndarray | None = None
    morph_lo: np.ndarray | None = None
    morph_hi: np.ndarray | None = None
    skin_joints: np.ndarray | None = None
    skin_weights: np.ndarray | None = None
    skin_pairs: np.ndarray | None = None
    skin_boxes: np.ndarray | None = None
    sources: np.ndarray | None = None
    movers: np.ndarray | None = None

    @property
    def n_objects(self) -> int:
        return int(self.first_index.shape[0])

    @property
    def tris(self) -> np.ndarray:
        return self.index_count // 3

    @property
    def n_triangles(self) -> int:
        return int(self.index_count.sum() // 3)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) scene bounding box."""
        if self.n_objects == 0:
            return np.zeros((2, 3))
        return np.stack([self.bmin.min(axis=0), self.bmax.max(axis=0)])

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in self._arrays().values())

    #: the arrays with one row per object (``objects`` picks rows of these)
    PER_OBJECT = ("first_index", "index_count", "base_vertex", "bmin", "bmax", "centers", "radii", "colors", "body",
                  "morph_lo", "morph_hi")

    #: a model's look beyond its objects' colours (None where it has none)
    PER_VERTEX = ("vertex_colors", "texcoords", "texels", "texture_levels", "texture_modes", "morph_rows",
                  "morph_deltas", "skin_joints", "skin_weights", "skin_pairs", "skin_boxes", "sources")

    #: the parts' arrays (``part_start`` indexes the others)
    PARTS = ("part_start", "part_count", "part_bmin", "part_bmax")
    #: the levels of detail's arrays (one row per object, a column per level)
    LODS = ("lod_first", "lod_count", "lod_error")

    @property
    def n_parts(self) -> int:
        """Parts in all (one per object where the scene has none)."""
        return self.n_objects if self.part_start is None else int(self.part_start[-1])

    @property
    def levels(self) -> int:
        """Levels of detail per object (1: only the object as modelled)."""
        return 1 if self.lod_count is None else int(self.lod_count.shape[1])

    def _arrays(self, parts: bool = True, lods: bool = True) -> dict[str, np.ndarray]:
        names = ("vertices", "indices", *self.PER_VERTEX, *self.PER_OBJECT, "origin", *(self.PARTS if parts else ()),
                 *(self.LODS if lods else ()))
        return {k: getattr(self, k) for k in names if getattr(self, k) is not None}

    def translated(self, offset) -> "Scene":
        """The same scene moved by ``offset`` world units (float64 bounds and origin; the
        float32 vertex buffer is shared, unchanged)."""
        off = np.asarray(offset, dtype=np.float64).reshape(3)
        if not np.isfinite(off).all():
            raise InputError(f"scene offset must be finite, got {off.tolist()}")
        moved = {k: getattr(self, k) + off for k in ("bmin", "bmax", "centers", "origin", "part_bmin", "part_bmax")
                 if getattr(self, k) is not None}
        return Scene(**{**self._arrays(), **moved}, name=self.name,
                     meta={**self.meta, "offset": (np.asarray(self.meta.get("offset", 0.0)) + off).tolist()})

    def objects(self, idx) -> "Scene":
        """The scene's objects ``idx`` (indices, in that order) alone: their draw ranges, bounds
        and colours; the vertex and index buffers are shared, unchanged (``bench frame`` plans a
        few of a scene's objects to measure what a frame costs whatever its objects)."""
        idx = np.asarray(idx, dtype=np.int64)
        if idx.ndim != 1:
            raise InputError(f"object indices must be a 1-D array, got shape {idx.shape}")
        if idx.size and (idx.min() < 0 or idx.max() >= self.n_objects):
            raise InputError(f"object indices must lie in [0, {self.n_objects}), got {idx.min()}..{idx.max()}")
        picked = {k: getattr(self, k)[idx] for k in (*self.PER_OBJECT, *self.LODS) if getattr(self, k) is not None}
        if self.part_start is not None:  # the picked objects' parts, in the same order
            n = self.part_start[idx + 1] - self.part_start[idx]
            rows = np.repeat(self.part_start[idx] - np.concatenate([[0], np.cumsum(n)[:-1]]), n) + np.arange(n.sum())
            picked |= {"part_start": np.concatenate([[0], np.cumsum(n)]).astype(np.int64),
                       "part_count": self.part_count[rows], "part_bmin": self.part_bmin[rows],
                       "part_bmax": self.part_bmax[rows]}
        return Scene(**{**self._arrays(), **picked}, name=self.name, meta=self.meta)

    def without_geometry(self) -> "Scene":
        """The same objects without their vertex and index buffers (empty arrays), for the
        frame loop once the GL buffers hold them: bounds, draw ranges, colours and meta stay.
        Dropping the last reference to a mapped buffer unmaps it, so its pages leave the rank."""
        empty = {"vertices": np.empty((0, 6), dtype=np.float32), "indices": np.empty(0, dtype=np.uint32)}
        for k in ("vertex_colors", "texcoords", "texels", "morph_rows", "morph_deltas", "skin_joints", "skin_weights",
                  "sources"):
            a = getattr(self, k)
            if a is not None:
                empty[k] = np.empty((0, *a.shape[1:]), dtype=a.dtype)
        return Scene(**{**self._arrays(), **empty}, name=self.name, meta=self.meta)

    def world_positions(self) -> np.ndarray:
        """(V, 3) float64 vertex positions in world space."""
        return self.vertices[:, :3].astype(np.float64) + self.origin

    def save(self, path: Path) -> None:
        """Write the scene as one .npz, atomically (temp file, then rename)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp.npz")
        meta = json.dumps({"name": self.name, "meta": self.meta, "version": FORMAT_VERSION})
        np.savez(tmp, meta=np.array(meta), **self._arrays())
        tmp.replace(path)

    @classmethod
    def load(cls, path: Path, mapped: bool = True) -> "Scene":
        """The scene saved at ``path``. ``mapped``: the vertex and index buffers are read-only
        maps of the file, not copies, so every rank of a host shares one copy of them (the
        page cache's) and a scene larger than memory still loads."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                head = json.loads(str(z["meta"]))
                if head.get("version") != FORMAT_VERSION:
                    raise InputError(f"{path}: scene cache version {head.get('version')} is not {FORMAT_VERSION}")
                maps = _map_members(path, MAPPED) if mapped else {}
                arrays = {k: maps[k] if k in maps else z[k] for k in z.files if k != "meta"}
        except InputError:
            raise
        except Exception as exc:  # a truncated or foreign file
            raise InputError(f"{path}: not a readable multigpu scene file ({exc.__class__.__name__}: {exc})") from None
        return cls(name=head["name"], meta=head["meta"], **arrays)


#: the buffers ``Scene.load`` maps from the file (the bulk of a scene; read only after loading, and a
#: simulation's vertex sources only where a later step is made from it: never a rank's own copy)
MAPPED = ("vertices", "indices", "vertex_colors", "texcoords", "texels", "sources")


def _map_members(path: Path, names) -> dict[str, np.ndarray]:
    """Read-only ``np.memmap`` views of the named arrays stored (uncompressed) in the .npz at
    ``path``: each member's local zip header and .npy header give where its data starts."""
    import struct
    import zipfile

    from numpy.lib import format as npy

    out = {}
    with zipfile.ZipFile(path) as zf, open(path, "rb") as fh:
        for info in zf.infolist():
            name = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
            if name not in names or info.compress_type != zipfile.ZIP_STORED:
                continue
            fh.seek(info.header_offset)
            local = fh.read(30)
            if local[:4] != b"PK\x03\x04":
                raise ValueError(f"member {info.filename}: bad local header")
            name_len, extra_len = struct.unpack("<HH", local[26:30])
            fh.seek(info.header_offset + 30 + name_len + extra_len)
            version = npy.read_magic(fh)
            shape, fortran, dtype = (npy.read_array_header_1_0(fh) if version == (1, 0)
                                     else npy.read_array_header_2_0(fh))
            if dtype.hasobject or 0 in shape:
                continue
            out[name] = np.memmap(path, dtype=dtype, mode="r", offset=fh.tell(), shape=shape,
                                  order="F" if fortran else "C")
    return out


def assemble(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]], name: str, meta: dict,
             colors: np.ndarray | None = None) -> Scene:
    """Build a Scene from groups of same-topology objects.

    Each part is ``(positions (n, v, 3), normals (n, v, 3), indices (t*3,), color (n, 3))``: ``n``
    objects sharing one index list of ``v`` local vertices. Vectorized per group.
    """
    positions = [np.asarray(p, dtype=np.float64) for p, *_ in parts if p.shape[0]]
    if not positions:
        raise InputError(f"{name}: the scene has no objects")
    bmin = np.concatenate([p.min(axis=1) for p in positions])
    bmax = np.concatenate([p.max(axis=1) for p in positions])
    origin = (bmin.min(axis=0) + bmax.max(axis=0)) / 2
    verts, idx, first, count, base, cols = [], [], [], [], [], []
    v_off = i_off = 0
    for pos, nrm, tri_idx, col in parts:
        n, v, _ = pos.shape
        if n == 0:
            continue
        verts.append(np.concatenate([np.asarray(pos, dtype=np.float64) - origin, nrm], axis=2)
                     .reshape(n * v, 6).astype(np.float32))
        idx.append(np.tile(tri_idx.astype(np.uint32), n))
        t = tri_idx.size
        first.append(i_off + np.arange(n, dtype=np.int64) * t)
        count.append(np.full(n, t, dtype=np.int64))
        base.append(v_off + np.arange(n, dtype=np.int64) * v)
        cols.append(np.asarray(col, dtype=np.float32))
        v_off += n * v
        i_off += n * t
    vertices = np.concatenate(verts)
    centers = (bmin + bmax) / 2
    radii = np.concatenate([np.linalg.norm(p - ((p.min(1) + p.max(1)) / 2)[:, None, :], axis=2).max(axis=1)
                            for p in positions]).astype(np.float64)
    return Scene(vertices=vertices, indices=np.concatenate(idx), first_index=np.concatenate(first),
                 index_count=np.concatenate(count), base_vertex=np.concatenate(base), bmin=bmin, bmax=bmax,
                 centers=centers, radii=radii, colors=np.concatenate(cols) if colors is None else colors,
                 origin=origin, name=name, meta=meta)
