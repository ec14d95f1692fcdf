"""A model's colour textures: each textured mesh's UVs, its image and sampler, packed as one array.

glTF ``baseColorTexture`` (TEXCOORD_0; the texture's sampler: ``wrapS``/``wrapT`` REPEAT,
CLAMP_TO_EDGE or MIRRORED_REPEAT, and ``magFilter`` NEAREST or LINEAR) and OBJ ``map_Kd``. trimesh
reads the images and UVs but drops the samplers, so they are read here from the file's own JSON
and matched to a mesh by its material's name (a file whose textures share one sampler needs no
match). The texture multiplies the material's colour (glTF's base colour factor, MTL's ``Kd``, as
both specifications say).

The images become the layers of one texture array (``pack``): every layer the size of the
largest (smaller ones resampled up; a side above ``MAX_SIDE`` is downscaled, with a warning),
so the frame stays one multi-draw call and each layer keeps its own wrap and filter (done in the
fragment shader: ``gpu/shaders.py``), which an atlas could not (a wrapped UV would reach its
neighbour's tiles). Identical images under one sampler are one layer. A missing or unreadable
image gets one warning naming the file, and its material's colour stands in. Pure numpy and
Pillow: no GL, no MPI.
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

    def pack(self, warnings: list[str]) -> tuple[np.ndarray, np.ndarray] | None:
        """``(textures (T, H, W, 4) uint8, modes (T, 4) float32)``: wrap s, wrap t, nearest,
        alpha cutoff per layer; None without textures."""
        if not self.images:
            return None
        h = max(im.shape[0] for im in self.images)
        w = max(im.shape[1] for im in self.images)
        if max(h, w) > MAX_SIDE:
            k = MAX_SIDE / max(h, w)
            warnings.append(f"a {w}x{h} texture is over {MAX_SIDE} pixels a side: downscaled to "
                            f"{max(1, round(w * k))}x{max(1, round(h * k))}")
            h, w = max(1, round(h * k)), max(1, round(w * k))
        out = np.empty((len(self.images), h, w, 4), dtype=np.uint8)
        for i, im in enumerate(self.images):  # textures, a handful
            out[i] = im if im.shape[:2] == (h, w) else _resized(im, w, h)
        return out, np.asarray(self.modes, dtype=np.float32).reshape(-1, 4)


def _resized(rgba: np.ndarray, w: int, h: int) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.fromarray(rgba, "RGBA").resize((w, h), Image.Resampling.BILINEAR))


def texture_info(textures: np.ndarray | None) -> dict:
    """What ``scene info`` says of a scene's textures."""
    if textures is None or len(textures) == 0:
        return {"count": 0}
    t, h, w, _ = textures.shape
    return {"count": int(t), "width": int(w), "height": int(h), "mib": float(textures.nbytes / 2**20)}
