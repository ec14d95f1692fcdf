"""Depth complexity and overdraw of one frame (``multigpu depth``), measured on the GL side.

Two additive passes into a float framebuffer count fragments per pixel: with the depth test
off, every fragment counts (depth complexity ``d``); with it on, in the scene's draw order,
only fragments that pass at the time they are drawn count (overdraw ``o``, the fragments a
renderer actually shades). For a random draw order the expected overdraw of a pixel of depth
complexity d is the harmonic number o(d) = 1 + 1/2 + ... + 1/d (Doggett's culling slides);
the report puts the measured mean o beside the model's.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

COUNT_VERTEX = """
#version 430
uniform mat4 mvp;
in vec3 in_pos;
void main() { gl_Position = mvp * vec4(in_pos, 1.0); }
"""
COUNT_FRAGMENT = """
#version 430
out vec4 f_count;
void main() { f_count = vec4(1.0, 0.0, 0.0, 1.0); }
"""


def harmonic(d: np.ndarray) -> np.ndarray:
    """o(d) = sum_{k=1..d} 1/k per element (0 for d = 0)."""
    d = np.asarray(d, dtype=np.int64)
    table = np.concatenate([[0.0], np.cumsum(1.0 / np.arange(1, max(int(d.max(initial=0)), 1) + 1))])
    return table[d]


def measure(ctx, scene, mvp: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(d, o) per pixel, (H, W) int arrays, row 0 at the bottom (GL order)."""
    import moderngl

    from multigpu.core.drawlist import DrawList

    W, H = size
    draws = DrawList(scene)
    prog = ctx.program(vertex_shader=COUNT_VERTEX, fragment_shader=COUNT_FRAGMENT)
    vbo = ctx.buffer(np.ascontiguousarray(scene.vertices[:, :3], dtype=np.float32))
    ibo = ctx.buffer(draws.indices)
    vao = ctx.vertex_array(prog, [(vbo, "3f", "in_pos")], index_buffer=ibo, index_element_size=4)
    color = ctx.renderbuffer((W, H), 4, dtype="f4")
    depth = ctx.depth_renderbuffer((W, H))
    fbo = ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
    prog["mvp"].write(np.ascontiguousarray(np.asarray(mvp).T, dtype=np.float32))
    out = []
    try:
        for depth_test in (False, True):
            fbo.use()
            fbo.viewport = (0, 0, W, H)
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.disable(moderngl.CULL_FACE)
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.ONE, moderngl.ONE
            if depth_test:
                ctx.enable(moderngl.DEPTH_TEST)
            else:
                ctx.disable(moderngl.DEPTH_TEST)
            vao.render(vertices=draws.indices.size)
            raw = np.frombuffer(fbo.read(components=4, dtype="f4"), dtype=np.float32).reshape(H, W, 4)
            out.append(np.rint(raw[:, :, 0]).astype(np.int64))
        ctx.disable(moderngl.BLEND)
    finally:
        for obj in (vao, fbo, color, depth, ibo, vbo, prog):
            obj.release()
    return out[0], out[1]


def summarize(d: np.ndarray, o: np.ndarray) -> dict:
    covered = d > 0
    n = int(covered.sum())
    if n == 0:
        return {"covered_pixels": 0, "mean_d": 0.0, "mean_o": 0.0, "model_o": 0.0, "max_d": 0}
    return {"covered_pixels": n, "coverage": n / d.size, "mean_d": float(d[covered].mean()),
            "max_d": int(d.max()), "mean_o": float(o[covered].mean()),
            "model_o": float(harmonic(d[covered]).mean()),
            "model_o_of_mean_d": float(harmonic(np.array([int(round(d[covered].mean()))]))[0])}


def run(scene, camera, size: tuple[int, int], out: Path) -> dict:
    """Measure one frame, write ``depth_complexity.png``, ``overdraw.png`` and ``depth.json``."""
    from multigpu.core.camera import frame_matrices, model_view
    from multigpu.gpu.render import create_context

    ctx, _ = create_context()
    view, proj, _ = frame_matrices(camera, size)
    d, o = measure(ctx, scene, proj @ model_view(view, scene.origin), size)
    stats = summarize(d, o)
    out.mkdir(parents=True, exist_ok=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    top = max(int(d.max()), 1)
    for name, img in (("depth_complexity", d), ("overdraw", o)):
        plt.imsave(out / f"{name}.png", img[::-1], cmap="magma", vmin=0, vmax=top)
    (out / "depth.json").write_text(json.dumps(stats, indent=1))
    return stats
