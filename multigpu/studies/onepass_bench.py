"""``multigpu bench onepass``: both eyes of a stereo frame in one pass, against the pipeline's two.

The lever for a stereo frame that costs less than two mono frames is to process the geometry
once for both eyes. Two ways GL 4.5 offers, each drawing into a framebuffer of two eye canvases
stacked (``GL_ARB_viewport_array``: a viewport and a scissor per eye):

* ``instanced``: every draw command twice (instance count 2), the vertex shader choosing the
  eye's matrix and viewport by ``gl_InstanceID`` (``GL_ARB_shader_viewport_layer_array``): one
  draw call for both eyes, the vertices still shaded once per eye;
* ``geometry``: a geometry shader invoked twice per triangle (``invocations = 2``), the vertex
  shader run once for both eyes and the eye's matrix applied per invocation.

Along the plant's walkthrough (100,000 requested triangles), for each of the four regions of a
2x2 wall of 256x256 tiles at anaglyph's eye resolution (a 512x512 eye canvas, the balancer's
regions, each region's objects), one process renders: ``mono`` (one eye), ``two passes`` (the
pipeline's: the region once per eye), and the two single passes. Printed: render CPU per region
and frame (process CPU time, llvmpipe's rasterizer on the rank's own thread), its ratio to mono,
and the pixels that differ from the two passes' (the stacked viewport's transform rounds
otherwise). Medians over rounds, in rotating order. Figures only, no asserts. Needs the two GL
extensions (Mesa's llvmpipe has them); ``glViewportArrayv`` and ``glScissorArrayv`` are called
through EGL's ``eglGetProcAddress``, since moderngl exposes neither.
"""

from __future__ import annotations

import ctypes
import time
from pathlib import Path

import numpy as np

from multigpu.studies.tables import Columns, write_csv

GRID, TILE = (2, 2), (256, 256)
SEPARATION = 0.3  # scene units between the eyes: a visible disparity along the walk
ARMS = ("mono", "two passes", "instanced", "geometry")
#: where the results go (onepass.csv); docs/results/onepass/ holds the published ones
OUT = Path("out/onepass")

_DECODE = """
    vec2 f = vec2(float(in_nrm & 0xFFFFu), float(in_nrm >> 16)) / 65535.0 * 2.0 - 1.0;
    vec3 n = vec3(f, 1.0 - abs(f.x) - abs(f.y));
    float t = max(-n.z, 0.0);
    n.xy += vec2(n.x >= 0.0 ? -t : t, n.y >= 0.0 ? -t : t);
"""
INSTANCED = """#version 430
#extension GL_ARB_shader_viewport_layer_array : require
uniform mat4 mvps[2];
layout(std430, binding = 0) readonly buffer Colors { float colors[]; };
in vec3 in_pos; in uint in_nrm; in uint in_obj;
out vec3 v_nrm; out vec3 v_col; flat out int v_eye;
void main() {
    gl_Position = mvps[gl_InstanceID] * vec4(in_pos, 1.0);
    gl_ViewportIndex = gl_InstanceID; v_eye = gl_InstanceID;
""" + _DECODE + """
    v_nrm = n; uint c = 3u * in_obj; v_col = vec3(colors[c], colors[c + 1u], colors[c + 2u]);
}"""
PASS_THROUGH = """#version 430
layout(std430, binding = 0) readonly buffer Colors { float colors[]; };
in vec3 in_pos; in uint in_nrm; in uint in_obj;
out vec3 g_pos; out vec3 g_nrm; out vec3 g_col;
void main() {
    g_pos = in_pos;
""" + _DECODE + """
    g_nrm = n; uint c = 3u * in_obj; g_col = vec3(colors[c], colors[c + 1u], colors[c + 2u]);
}"""
GEOMETRY = """#version 430
layout(triangles, invocations = 2) in;
layout(triangle_strip, max_vertices = 3) out;
uniform mat4 mvps[2];
in vec3 g_pos[]; in vec3 g_nrm[]; in vec3 g_col[];
out vec3 v_nrm; out vec3 v_col; flat out int v_eye;
void main() {
    for (int i = 0; i < 3; i++) {
        gl_Position = mvps[gl_InvocationID] * vec4(g_pos[i], 1.0);
        gl_ViewportIndex = gl_InvocationID; v_eye = gl_InvocationID; v_nrm = g_nrm[i]; v_col = g_col[i];
        EmitVertex();
    }
    EndPrimitive();
}"""
FRAGMENT = """#version 430
uniform vec3 lights[2];
in vec3 v_nrm; in vec3 v_col; flat in int v_eye;
out vec4 f_color;
void main() {
    float d = abs(dot(normalize(v_nrm), lights[v_eye]));
    f_color = vec4(v_col * (0.25 + 0.75 * d), 1.0);
}"""


def _gl_arrays():
    """``glViewportArrayv`` and ``glScissorArrayv`` of the current context."""
    egl = ctypes.CDLL("libEGL.so.1")
    egl.eglGetProcAddress.restype, egl.eglGetProcAddress.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
    viewports = ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.c_int, ctypes.POINTER(ctypes.c_float))(
        egl.eglGetProcAddress(b"glViewportArrayv"))
    scissors = ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.c_int, ctypes.POINTER(ctypes.c_int))(
        egl.eglGetProcAddress(b"glScissorArrayv"))
    return viewports, scissors


class OnePass:
    """Both eyes of a region in one draw, into two stacked eye canvases (see the module)."""

    def __init__(self, renderer, geometry: bool):
        ctx, r = renderer.ctx, renderer
        self.r, self.ctx, self.geometry = r, ctx, geometry
        W, H = self.size = r.size
        self.prog = (ctx.program(vertex_shader=PASS_THROUGH, geometry_shader=GEOMETRY, fragment_shader=FRAGMENT)
                     if geometry else ctx.program(vertex_shader=INSTANCED, fragment_shader=FRAGMENT))
        self.vao = ctx.vertex_array(self.prog, [(r.vbo, "3f 1u", "in_pos", "in_nrm"), (r.obo, "1u", "in_obj")],
                                    index_buffer=r.ibo, index_element_size=4)
        self.fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((W, 2 * H), 4)],
                                   depth_attachment=ctx.depth_renderbuffer((W, 2 * H)))
        self.viewports, self.scissors = _gl_arrays()
        self.depth_test = ctx.DEPTH_TEST

    def render(self, eyes, region, mask) -> list[np.ndarray]:
        """Each eye's ``(view, proj, light)`` of ``region``'s ``mask`` objects, as two images."""
        from multigpu.core.camera import model_view
        from multigpu.gpu.render import BACKGROUND

        r, (W, H) = self.r, self.size
        x0, y0, x1, y1 = (int(v) for v in region)
        w, h = x1 - x0, y1 - y0
        cmds = r.draws.leveled(mask, None, None).copy()
        if not self.geometry:
            cmds[:, 1] = 2  # instances: an eye each
        r._upload(cmds, eyes[0][2])
        mvps = [np.ascontiguousarray((p @ model_view(v, r.origin)).T, dtype=np.float32) for v, p, _ in eyes]
        self.prog["mvps"].write(np.concatenate(mvps).tobytes())
        self.prog["lights"].write(np.array([li for _, _, li in eyes], dtype=np.float32).tobytes())
        self.fbo.use()
        self.fbo.viewport = (0, 0, W, 2 * H)
        self.ctx.enable(self.depth_test)
        for e in range(2):  # each eye's region cleared, as a pass of the pipeline clears its own
            self.fbo.scissor = (x0, y0 + e * H, w, h)
            self.fbo.clear(*BACKGROUND, 1.0, depth=1.0)
        self.viewports(0, 2, (ctypes.c_float * 8)(0, 0, W, H, 0, H, W, H))
        self.scissors(0, 2, (ctypes.c_int * 8)(x0, y0, w, h, x0, y0 + H, w, h))
        self.ctx.enable_direct(0x0C11)  # GL_SCISSOR_TEST, for every viewport
        if len(cmds):
            self.vao.render_indirect(r.indirect, count=len(cmds))
        return [np.frombuffer(self.fbo.read(viewport=(x0, y0 + e * H, w, h), components=3, alignment=1),
                              np.uint8).reshape(h, w, 3) for e in range(2)]


def bench_onepass(quick: bool) -> list[dict]:
    from multigpu.core.balance import partition
    from multigpu.core.bounds import BoxProjector
    from multigpu.core.camera import frame_matrices
    from multigpu.gpu.render import RegionRenderer, create_context, raster_threads
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import walkthrough

    frames, rounds, triangles = (40, 1, 20_000) if quick else (300, 3, 100_000)
    raster_threads(2)  # the rasterizer on this thread: its work is this process's CPU time
    scene, _ = load_scene(SceneSpec(triangles=triangles))
    path = walkthrough(scene, frames=frames)
    size = (GRID[1] * TILE[0], GRID[0] * TILE[1])
    ctx = create_context()[0]
    missing = [e for e in ("GL_ARB_viewport_array", "GL_ARB_shader_viewport_layer_array") if e not in ctx.extensions]
    if missing:
        print(f"bench onepass: this GL lacks {', '.join(missing)}: nothing to measure")
        return []
    r = RegionRenderer(ctx, scene, size, "scissor")
    one = {"instanced": OnePass(r, False), "geometry": OnePass(r, True)}
    project = BoxProjector(scene.bmin, scene.bmax)
    plans = []
    for f in range(0, frames, 10):  # every tenth frame of the walk
        view, proj, light = frame_matrices(path.camera(f), size)
        eyes = []
        for s in (-SEPARATION / 2, SEPARATION / 2):
            v = view.copy()
            v[0, 3] -= s
            eyes.append((v, proj, light))
        a, b = (project(v, p) for v, p, _ in eyes)
        both = np.column_stack([np.fmin(a[:, :2], b[:, :2]), np.fmax(a[:, 2:], b[:, 2:])])  # as the planner's union
        plans.append((eyes, partition(both, scene.tris, GRID, size)))

    def arm(name: str, eyes, region, mask):
        if name == "mono":
            return [r.render(*eyes[0], region, mask)]
        if name == "two passes":
            return [r.render(*e, region, mask) for e in eyes]
        return one[name].render(eyes, region, mask)

    differ = {name: 0 for name in ARMS[2:]}
    for eyes, part in plans:  # the single passes' pixels against the pipeline's
        for k in range(len(part.regions)):
            want = arm("two passes", eyes, tuple(part.regions[k]), part.visible[k])
            for name in differ:
                got = arm(name, eyes, tuple(part.regions[k]), part.visible[k])
                differ[name] += sum(int((g != w).any(axis=2).sum()) for g, w in zip(got, want))
    times: dict[str, list[float]] = {a: [] for a in ARMS}
    for rnd in range(rounds):
        for name in ARMS[rnd % len(ARMS):] + ARMS[:rnd % len(ARMS)]:  # rotating order
            t = time.process_time()
            for eyes, part in plans:
                for k in range(len(part.regions)):
                    arm(name, eyes, tuple(part.regions[k]), part.visible[k])
            times[name].append((time.process_time() - t) * 1e3 / (len(plans) * len(part.regions)))
    mono = float(np.median(times["mono"]))
    rows = [{"arm": a, "render_cpu_ms": float(np.median(times[a])), "ratio": float(np.median(times[a])) / mono,
             "differing_px": differ.get(a, 0)} for a in ARMS]
    print(f"bench onepass: the plant ({triangles} requested triangles), a 2x2 wall of 256x256 at anaglyph's eye "
          f"resolution, {len(plans)} frames x 4 regions, {rounds} rotating round(s); render CPU ms per region and "
          "frame (process CPU time), x mono, pixels differing from two passes over every region and frame")
    table = Columns(("arm", "arm", "<11"), ("render_cpu_ms", "render", "8.2f"), ("ratio", "x mono", "7.2f"),
                    ("differing_px", "differ px", "10d"))
    print(table.header())
    for row in rows:
        print(table.row(row))
    OUT.mkdir(parents=True, exist_ok=True)
    write_csv(OUT / "onepass.csv", [{"frames": len(plans), "rounds": rounds, "triangles": triangles, **r}
                                    for r in rows])
    print(f"results in {OUT}/onepass.csv")
    return rows
