"""Headless GL rendering of one rank's screen region (moderngl on EGL). The only GL module.

One context per rank, the whole scene uploaded once. A frame is ONE ``render_indirect`` call
over the draw commands of the objects in the rank's T' mask (one command per run of visible
objects in the spatially ordered index buffer, built with numpy: see ``drawlist.py``), into a
full-display-sized framebuffer with the full-display viewport and projection, scissored to the
rank's region. Because viewport and projection are those of a one-rank full render, the pixels
a rank produces are bit-identical to that render's pixels in its region (the scissor only
discards fragments outside it; llvmpipe bins triangles to the scissor, so work outside the
region is skipped).
"""

from __future__ import annotations

import ctypes
import os

import numpy as np

from .drawlist import DrawList
from .errors import InputError

EGL_HELP = ("EGL headless OpenGL is not available: install Mesa's EGL and GL drivers "
            "(Debian/Ubuntu: sudo apt install libegl1 libgl1-mesa-dri) or an NVIDIA driver with EGL")

VERTEX = """
#version 430
uniform mat4 mvp;
layout(std430, binding = 0) readonly buffer Colors { float colors[]; };  // 3 per object
in vec3 in_pos;
in vec3 in_nrm;
in uint in_obj;
out vec3 v_nrm;
out vec3 v_col;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_nrm = in_nrm;
    uint c = 3u * in_obj;
    v_col = vec3(colors[c], colors[c + 1u], colors[c + 2u]);
}
"""

FRAGMENT = """
#version 430
uniform vec3 light;
in vec3 v_nrm;
in vec3 v_col;
out vec4 f_color;
void main() {
    float d = abs(dot(normalize(v_nrm), light));
    f_color = vec4(v_col * (0.25 + 0.75 * d), 1.0);
}
"""

BACKGROUND = (0.08, 0.09, 0.12)


class EglUnavailable(RuntimeError):
    """No headless EGL context could be made on this machine."""


def egl_device_count() -> int:
    """Number of EGL devices (``eglQueryDevicesEXT``), 1 when the extension is missing."""
    try:
        egl = ctypes.CDLL("libEGL.so.1")
        egl.eglGetProcAddress.restype = ctypes.c_void_p
        egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
        addr = egl.eglGetProcAddress(b"eglQueryDevicesEXT")
        if not addr:
            return 1
        query = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_int))(addr)
        n = ctypes.c_int(0)
        if not query(0, None, ctypes.byref(n)):
            return 1
        return max(1, n.value)
    except OSError:
        raise EglUnavailable(EGL_HELP + " (libEGL.so.1 not found)") from None


def local_rank() -> int:
    for var in ("MPI_LOCALRANKID", "OMPI_COMM_WORLD_LOCAL_RANK", "SLURM_LOCALID", "PMI_LOCAL_RANK"):
        if var in os.environ:
            return int(os.environ[var])
    return 0


def create_context(device: int | None = None):
    """A standalone EGL context on ``device`` (default: local rank modulo the device count)."""
    os.environ.setdefault("LP_NUM_THREADS", "1")  # llvmpipe: a rank's raster work is its own CPU time
    import moderngl

    count = egl_device_count()
    index = local_rank() % count if device is None else device
    if device is not None and not (0 <= device < count):
        raise InputError(f"--device {device}: this machine has {count} EGL device(s) (0..{count - 1})")
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=430, device_index=index)
    except Exception as exc:
        raise EglUnavailable(f"{EGL_HELP} ({exc.__class__.__name__}: {str(exc).strip().splitlines()[0] if str(exc) else ''})") from None
    return ctx, index


class RegionRenderer:
    """Draws any subset of a scene's objects into any region of a ``size`` display."""

    def __init__(self, ctx, scene, size: tuple[int, int]):
        import moderngl

        self.ctx = ctx
        self.size = W, H = size
        self.prog = ctx.program(vertex_shader=VERTEX, fragment_shader=FRAGMENT)
        self.draws = DrawList(scene)
        self.vbo = ctx.buffer(np.ascontiguousarray(scene.vertices, dtype=np.float32))
        self.obo = ctx.buffer(self.draws.vertex_object)
        self.ibo = ctx.buffer(self.draws.indices)
        self.cbo = ctx.buffer(np.ascontiguousarray(scene.colors, dtype=np.float32).ravel())
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "3f 3f", "in_pos", "in_nrm"),
                                                (self.obo, "1u", "in_obj")],
                                    index_buffer=self.ibo, index_element_size=4)
        self.indirect = ctx.buffer(reserve=20 * 1024)  # grows when a frame needs more commands
        self.last_commands = 0  # draw commands of the last frame (runs of visible objects)
        self.fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((W, H), 4)],
                                   depth_attachment=ctx.depth_renderbuffer((W, H)))
        self.depth_test = moderngl.DEPTH_TEST

    def render(self, mvp: np.ndarray, light: np.ndarray, region, mask: np.ndarray | None) -> np.ndarray:
        """Render the objects in ``mask`` (all when None) into ``region``; return its pixels.

        Returns ``(h, w, 3)`` uint8, row 0 at the BOTTOM of the region (GL order).
        """
        x0, y0, x1, y1 = (int(v) for v in region)
        w, h = x1 - x0, y1 - y0
        cmds = self.draws.commands(mask)
        self.last_commands = len(cmds)
        ctx = self.ctx
        self.fbo.use()
        self.fbo.viewport = (0, 0, *self.size)
        self.fbo.scissor = (x0, y0, w, h)
        ctx.enable(self.depth_test)
        self.fbo.clear(*BACKGROUND, 1.0, depth=1.0)
        if len(cmds):
            if cmds.nbytes > self.indirect.size:
                self.indirect.orphan(cmds.nbytes)
            self.indirect.write(cmds)
            self.prog["mvp"].write(np.ascontiguousarray(mvp.T, dtype=np.float32))
            self.prog["light"].value = tuple(float(v) for v in light)
            self.cbo.bind_to_storage_buffer(0)
            self.vao.render_indirect(self.indirect, count=len(cmds))
        data = self.fbo.read(viewport=(x0, y0, w, h), components=3, alignment=1)
        return np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)

    def release(self) -> None:
        for obj in (self.vao, self.fbo, self.indirect, self.cbo, self.ibo, self.obo, self.vbo, self.prog):
            obj.release()


def frame_matrices(camera, size) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """view, projection (float64) and the light direction (towards the viewer, slightly above)."""
    W, H = size
    view = camera.view()
    proj = camera.projection(W / H)
    light = view[:3, :3].T @ np.array([0.3, 0.5, 0.8])
    return view, proj, light / np.linalg.norm(light)
