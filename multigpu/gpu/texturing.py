"""A model's textures on the GL side: which path draws them, and what each path binds.

The texel pool (``scene/textures.py``) is read by the fragment shader from storage buffers: the
pool itself comes with the vertex buffers (``buffers.py``: the host's buffers file where the GL
draws from host memory); here its level table and the layers' modes. The array path builds a
hardware texture array per rank instead, for A/B measurements (``multigpu bench textures``).
"""

from __future__ import annotations

import os

import numpy as np

from multigpu.errors import InputError


def texture_path() -> str:
    """How textures are drawn (``MULTIGPU_TEXTURES``): ``pool`` (default: the texel pool, from the
    host's buffers file where the driver draws from host memory, so one copy per host) or
    ``array`` (a hardware texture array per rank, for A/B measurements: ``bench textures``)."""
    from multigpu.gpu.shaders import TEXTURE_PATHS

    how = os.environ.get("MULTIGPU_TEXTURES", "pool")
    if how not in TEXTURE_PATHS:
        raise InputError(f"MULTIGPU_TEXTURES must be one of {', '.join(TEXTURE_PATHS)}, got '{how}'")
    return how


def make(ctx, prog, scene, path: str) -> tuple:
    """``(texture, samplers, modes)``: what the shader samples besides the texel pool: the
    layers' modes (storage buffer 1) and, as ``texture``, their level table (2); or, on the
    array path, a texture array of every layer's top level resampled to the largest (mipmapped
    by the GL) and a sampler of it per filter (units 0: linear, 1: nearest)."""
    modes = ctx.buffer(np.ascontiguousarray(scene.texture_modes, dtype=np.float32))
    if path == "pool":
        return ctx.buffer(np.ascontiguousarray(scene.texture_levels, dtype=np.int32)), [], modes
    import moderngl

    from multigpu.scene.textures import LEVEL_ROWS, layer_image, resized

    top = np.asarray(scene.texture_levels)[::LEVEL_ROWS]
    w, h = int(top[:, 1].max()), int(top[:, 2].max())
    images = [layer_image(scene.texels, scene.texture_levels, t) for t in range(len(top))]
    data = np.stack([im if im.shape[:2] == (h, w) else resized(im, w, h) for im in images])
    tex = ctx.texture_array((w, h, len(images)), 4, data)
    tex.build_mipmaps()
    samplers = [ctx.sampler(repeat_x=True, repeat_y=True, filter=f, texture=tex)
                for f in ((moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR),
                          (moderngl.NEAREST_MIPMAP_NEAREST, moderngl.NEAREST))]
    prog["tex_linear"].value, prog["tex_nearest"].value = 0, 1
    return tex, samplers, modes
