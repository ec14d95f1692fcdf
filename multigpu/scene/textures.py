"""A model's colour textures: each textured mesh's UVs, its image and sampler, packed as one array.

glTF ``baseColorTexture`` (TEXCOORD_0; the texture's sampler: ``wrapS``/``wrapT`` REPEAT,
CLAMP_TO_EDGE or MIRRORED_REPEAT, and ``magFilter`` NEAREST or LINEAR) and OBJ ``map_Kd``. trimesh
reads the images and UVs but drops the samplers, so they are read here from the file's own JSON
and matched to a mesh by its material's name (a file whose textures share one sampler needs no
match). The texture multiplies the material's colour (glTF's base colour factor, MTL's ``Kd``, as
both specifications say).

The images become one *texel pool* (``pack``): every layer's mip chain (each level a box filter
of the one before, down to 1x1) as RGBA8 words in one flat array, with a table of where each
level starts and its size (``LEVEL_ROWS`` rows a layer). Layers keep their own sizes (a side above
``MAX_SIDE`` is downscaled, with a warning). The renderer reads the pool from a storage buffer
and filters in the fragment shader (``gpu/shaders.py``), wrap and filter per layer, so the frame
stays one multi-draw call, and the pool lies in the host's buffers file like the vertices: one
copy per host where the driver draws from host memory. ``MULTIGPU_TEXTURES=array`` draws through
a hardware texture array instead (every layer resampled to the largest; wrap folded in the
shader): ``multigpu bench textures`` measures both. Identical images under one sampler are one
layer. A missing or unreadable image gets one warning naming the file, and its material's colour
stands in. Pure numpy and Pillow: no GL, no MPI.
"""

from __future__ import annotations

import hashlib
import json
import re
import struct
from pathlib import Path

import numpy as np

#: a texture side above this is downscaled (with a warning)
MAX_SIDE = 8192
#: at most this many distinct textures are drawn (GL 4.3 guarantees 256 array layers)
MAX_LAYERS = 256
#: glTF sampler wrap modes -> the shader's (0 repeat, 1 clamp to edge, 2 mirrored repeat)
WRAP = {10497: 0, 33071: 1, 33648: 2}
#: glTF magFilter NEAREST
NEAREST = 9728
#: a layer's sampler where the file gives none: repeat, linear (glTF's defaults)
DEFAULT = (0, 0, 0)
#: rows of the level table per layer (enough for 2**15 pixels a side)
LEVEL_ROWS = 16


def gltf_json(path: Path) -> dict | None:
    """The JSON document of a .gltf or .glb file, or None where it cannot be read."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    try:
        if data[:4] == b"glTF":
            n = struct.unpack("<I", data[12:16])[0]
            return json.loads(data[20:20 + n])
        return json.loads(data)
    except (ValueError, struct.error):
        return None


def gltf_samplers(doc: dict | None) -> dict[str | None, tuple[int, int, int]]:
    """Material name -> (wrap s, wrap t, nearest) of its base colour texture's sampler; the key
    None holds the one sampler all textures share, where they share one."""
    if not doc:
        return {}
    textures, samplers = doc.get("textures", []), doc.get("samplers", [])

    def mode(tex_index) -> tuple[int, int, int]:
        try:
            s = samplers[textures[tex_index]["sampler"]]
        except (IndexError, KeyError, TypeError):
            return DEFAULT
        return (WRAP.get(s.get("wrapS", 10497), 0), WRAP.get(s.get("wrapT", 10497), 0),
                int(s.get("magFilter") == NEAREST))

    out: dict = {}
    for m in doc.get("materials", []):
        tex = (m.get("pbrMetallicRoughness") or {}).get("baseColorTexture")
        if isinstance(tex, dict) and "index" in tex:
            out[m.get("name")] = mode(tex["index"])
    shared = {mode(i) for i in range(len(textures))}
    if len(shared) == 1:
        out[None] = shared.pop()
    return out


def image_files(path: Path, doc: dict | None = None) -> list[Path]:
    """The image files a model names outside itself: glTF image URIs (not embedded), OBJ
    ``map_Kd`` in its MTL libraries (part of the scene cache's key: an edited texture is reloaded)."""
    from urllib.parse import unquote

    base, names = path.parent, []
    if path.suffix.lower() in (".gltf", ".glb"):
        doc = gltf_json(path) if doc is None else doc
        names = [unquote(im["uri"]) for im in (doc or {}).get("images", [])
                 if isinstance(im.get("uri"), str) and not im["uri"].startswith("data:")]
    elif path.suffix.lower() == ".obj":
        for lib in _obj_mtllibs(path):
            try:
                text = (base / lib).read_text(errors="replace")
            except OSError:
                continue
            names += [m.group(1).strip() for m in re.finditer(r"^\s*map_Kd\s+(?:-\S+\s+\S+\s+)*(.+)$", text, re.M)]
    return [base / n for n in dict.fromkeys(names)]


def missing_images(path: Path, doc: dict | None = None) -> list[Path]:
    """The image files a model names that cannot be read."""
    return [p for p in image_files(path, doc) if not _readable_image(p)]


def _obj_mtllibs(path: Path) -> list[str]:
    """The MTL files an OBJ names (read a line at a time: only ``mtllib`` lines are kept)."""
    libs = []
    try:
        with open(path, "r", errors="replace") as fh:
            for line in fh:
                if line.startswith("mtllib"):
                    libs += line.split()[1:]
    except OSError:
        pass
    return libs


def _readable_image(p: Path) -> bool:
    from PIL import Image

    try:
        with Image.open(p) as im:
            im.verify()
        return True
    except Exception:
        return False


def mesh_texture(mesh) -> tuple[np.ndarray | None, object | None]:
    """A trimesh mesh's UVs (V, 2) float32, ``v`` running down the image (row 0 at 0, as glTF)
    and its colour image (PIL), or (None, None) where it has no texture to draw."""
    visual = getattr(mesh, "visual", None)
    material = getattr(visual, "material", None)
    image = getattr(material, "baseColorTexture", None)
    if image is None:
        image = getattr(material, "image", None)
    uv = getattr(visual, "uv", None)
    if image is None or uv is None or len(uv) != len(mesh.vertices):
        return None, None
    uv = np.asarray(uv, dtype=np.float32)[:, :2].copy()
    uv[:, 1] = 1.0 - uv[:, 1]  # trimesh flips glTF's v to GL's: back to image rows
    return uv, image


class Layers:
    """The distinct (image, sampler) pairs of a model, in the order first met."""

    def __init__(self, samplers: dict | None = None):
        self.samplers = samplers or {}
        self.keys: dict[tuple, int] = {}
        self.images: list = []
        self.modes: list[tuple[int, int, int, float]] = []
        self.dropped = 0  # meshes whose texture came past MAX_LAYERS

    def layer(self, image, material_name: str | None, cutoff: float = 0.0) -> int:
        """The layer of ``image`` under ``material_name``'s sampler (``cutoff``: a MASK
        material's alpha cutoff, 0: opaque), added where new; -1 past ``MAX_LAYERS``."""
        mode = self.samplers.get(material_name, self.samplers.get(None, DEFAULT))
        rgba = np.asarray(image.convert("RGBA"))
        key = (hashlib.sha1(rgba.tobytes()).hexdigest(), rgba.shape, mode, cutoff)
        if key not in self.keys:
            if len(self.images) >= MAX_LAYERS:
                self.dropped += 1
                return -1
            self.keys[key] = len(self.images)
            self.images.append(rgba)
            self.modes.append((*mode, cutoff))
        return self.keys[key]

    def pack(self, warnings: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(texels (N,) uint32, levels (T * LEVEL_ROWS, 4) int32, modes (T, 4) float32)``: every
        layer's mip chain as RGBA8 words; each (layer, level) row's first texel, width, height and
        (in every row) the layer's level count; wrap s, wrap t, nearest, alpha cutoff per layer.
        None without textures."""
        if not self.images:
            return None
        chains = []
        for im in self.images:  # textures, a handful
            h, w = im.shape[:2]
            if max(h, w) > MAX_SIDE:
                k = MAX_SIDE / max(h, w)
                nw, nh = max(1, round(w * k)), max(1, round(h * k))
                warnings.append(f"a {w}x{h} texture is over {MAX_SIDE} pixels a side: downscaled to {nw}x{nh}")
                im = resized(im, nw, nh)
            chains.append(mip_chain(im))
        total = sum(lv.shape[0] * lv.shape[1] for chain in chains for lv in chain)
        texels = np.empty(total, dtype=np.uint32)
        levels = np.zeros((len(chains) * LEVEL_ROWS, 4), dtype=np.int32)
        at = 0
        for t, chain in enumerate(chains):
            for lv, im in enumerate(chain):  # levels, a dozen
                h, w = im.shape[:2]
                texels[at:at + h * w] = np.ascontiguousarray(im).view(np.uint32).ravel()
                levels[t * LEVEL_ROWS + lv] = (at, w, h, len(chain))
                at += h * w
        return texels, levels, np.asarray(self.modes, dtype=np.float32).reshape(-1, 4)


def mip_chain(rgba: np.ndarray) -> list[np.ndarray]:
    """``rgba`` (H, W, 4) and each half-size level below it (a box filter, sides rounded down,
    at least 1) down to 1x1."""
    from PIL import Image

    chain = [rgba]
    while chain[-1].shape[0] > 1 or chain[-1].shape[1] > 1:
        h, w = chain[-1].shape[:2]
        img = Image.fromarray(chain[-1], "RGBA").resize((max(1, w // 2), max(1, h // 2)), Image.Resampling.BOX)
        chain.append(np.asarray(img))
    return chain


def layer_image(texels: np.ndarray, levels: np.ndarray, layer: int, level: int = 0) -> np.ndarray:
    """One level of one layer of a texel pool as (H, W, 4) uint8 (a view)."""
    at, w, h, _ = (int(v) for v in levels[layer * LEVEL_ROWS + level])
    return np.asarray(texels[at:at + w * h]).view(np.uint8).reshape(h, w, 4)


def resized(rgba: np.ndarray, w: int, h: int) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.fromarray(rgba, "RGBA").resize((w, h), Image.Resampling.BILINEAR))


def texture_info(packed: tuple | None) -> dict:
    """What ``scene info`` says of a scene's textures (``Layers.pack``'s result)."""
    if packed is None:
        return {"count": 0}
    texels, levels, _ = packed
    top = levels[::LEVEL_ROWS]
    return {"count": int(len(top)), "pixels": int((top[:, 1].astype(np.int64) * top[:, 2]).sum()),
            "largest": [int(top[:, 1].max()), int(top[:, 2].max())], "mib": float(texels.nbytes / 2**20)}
