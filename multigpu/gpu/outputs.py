"""A projector output's final pass on the GPU: the composed tile warped, blended and coloured
into the picture the projector shows (``core/warpblend.py`` is the same arithmetic in numpy, the
reference the tests hold this pass to).

One draw per frame over the output's pixels: each fragment reads its content coordinates (a
float texture, the warp upsampled once at setup; NaN where the pixel shows nothing), samples the
tile there (bilinear between pixel centres, clamped at the tile's edges), and computes MPCDI's
``P * alpha * (1 - beta) + beta`` in linear light (the output's gamma taken off before and put
back after), the colour matrix before the blend and the ``.cube`` LUT on the signal last. The
tile's texture, the maps and the framebuffer are made once; a frame writes the tile and reads the
picture back (what goes to the projector's window, and to the records).
"""

from __future__ import annotations

import numpy as np

VERTEX = """
#version 330
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""

FRAGMENT = """
uniform sampler2D content;   // the composed tile, row 0 at the bottom
uniform sampler2D maps;      // every output pixel's tile coordinates (x right, y down), alpha, beta; row 0 on top
uniform sampler2D alpha3;    // colour alpha and beta maps (rgb), where the file's are not grey
uniform sampler2D beta3;
uniform sampler3D lut3;      // a 3D .cube table, [blue][green][red]
uniform sampler2D lut1;      // a 1D .cube table, n x 1
uniform float gamma;
uniform mat3 matrix;
uniform vec3 lut_lo;
uniform vec3 lut_hi;
uniform float lut_n;
uniform int height;
uniform vec2 rect_lo;        // the output's region in the tile: its first and last pixel centres
uniform vec2 rect_hi;
out vec4 f_color;

vec3 signal_of(vec3 coded) {
    vec3 x = clamp((coded - lut_lo) / (lut_hi - lut_lo), 0.0, 1.0);
    vec3 at = (x * (lut_n - 1.0) + 0.5) / lut_n;  // sample centres: linear between entries
#if LUT_DIMS == 1
    return vec3(texture(lut1, vec2(at.r, 0.5)).r, texture(lut1, vec2(at.g, 0.5)).g, texture(lut1, vec2(at.b, 0.5)).b);
#else
    return texture(lut3, at).rgb;
#endif
}

void main() {
    ivec2 row = ivec2(int(gl_FragCoord.x), height - 1 - int(gl_FragCoord.y));
    vec4 m = texelFetch(maps, row, 0);
    vec3 a = vec3(m.z);
    vec3 b = vec3(m.w);
#if COLOUR_MAPS
    a = texelFetch(alpha3, row, 0).rgb;
    b = texelFetch(beta3, row, 0).rgb;
#endif
    bool inside = !(isnan(m.x) || isnan(m.y)) && all(greaterThanEqual(m.xy, vec2(0.0))) && all(lessThanEqual(m.xy, vec2(1.0)));
    vec2 at = clamp(m.xy, rect_lo, rect_hi);  // bilinear within the region, clamped at its edges
    vec3 p = inside ? texture(content, vec2(at.x, 1.0 - at.y)).rgb : vec3(0.0);
    vec3 light = pow(p, vec3(gamma));
#if MATRIX
    light = clamp(matrix * light, 0.0, 1.0);
#endif
    light = light * a * (1.0 - b) + b;
    vec3 coded = pow(clamp(light, 0.0, 1.0), vec3(1.0 / gamma));
#if LUT_DIMS != 0
    coded = signal_of(coded);
#endif
    f_color = vec4(clamp(coded, 0.0, 1.0), 1.0);
}
"""


def _rgb(values, size: tuple[int, int], default: float) -> np.ndarray:
    """(h, w, 3) float32 of a map (h, w) or (h, w, 3), or ``default`` everywhere (None)."""
    w, h = size
    if values is None:
        return np.full((h, w, 3), default, dtype=np.float32)
    v = np.asarray(values, dtype=np.float32)
    return np.ascontiguousarray(np.repeat(v[..., None], 3, axis=2) if v.ndim == 2 else v)


class OutputPass:
    """The pass of one output of ``size`` (w, h) on ``ctx`` from a tile of ``tile`` (w, h):
    ``coords`` (h, w, 2) its pixels' content coordinates (rows top first), ``alpha`` and ``beta``
    its linear maps (None: 1 and 0), ``gamma``, ``matrix`` (3x3 or None), ``lut``
    (``warp.colour.Lut`` or None); ``rect`` (x, y, w, h): its content, the region of the tile it
    shows (top-left origin; None: the whole tile)."""

    def __init__(self, ctx, size: tuple[int, int], tile: tuple[int, int], coords: np.ndarray, alpha=None,
                 beta=None, gamma: float = 2.2, matrix=None, lut=None, rect=None):
        import moderngl

        self.ctx, self.size = ctx, size
        w, h = size
        tw, th = tile
        x0, y0, rw, rh = (0, 0, tw, th) if rect is None else rect
        if (x0, y0, rw, rh) != (0, 0, tw, th):  # the region's coordinates as the tile's (outside it: nothing)
            coords = np.asarray(coords, dtype=np.float64)
            outside = (coords < 0).any(axis=2) | (coords > 1).any(axis=2)
            coords = np.stack([(x0 + coords[..., 0] * rw) / tw, (y0 + coords[..., 1] * rh) / th], axis=2)
            coords[outside] = np.nan
        grey = all(v is None or np.ndim(v) == 2 for v in (alpha, beta))
        # one program made for this output's colour: llvmpipe runs a branch not taken at the full cost of
        # its texture reads (an unused LUT's lookup doubled the pass), so what is not used is not compiled
        head = (f"#version 330\n#define LUT_DIMS {0 if lut is None else lut.dims}\n#define COLOUR_MAPS {int(not grey)}\n"
                f"#define MATRIX {int(matrix is not None)}\n")
        self.prog = ctx.program(vertex_shader=VERTEX, fragment_shader=head + FRAGMENT)
        self.content = ctx.texture(tile, 3, dtype="f1")
        self.content.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.content.repeat_x = self.content.repeat_y = False  # clamped to the edge pixels
        packed = np.empty((h, w, 4), dtype=np.float32)  # coordinates, grey alpha and beta: one fetch a pixel
        packed[..., :2] = coords
        packed[..., 2] = 1.0 if alpha is None or not grey else alpha
        packed[..., 3] = 0.0 if beta is None or not grey else beta
        self.maps = [ctx.texture(size, 4, packed, dtype="f4")]
        for v, d in ((alpha, 1.0), (beta, 0.0)):  # colour maps (where grey, a pixel's stand-in: never read)
            self.maps.append(ctx.texture(size, 3, _rgb(v, size, d), dtype="f4") if not grey else
                             ctx.texture((1, 1), 3, np.full(3, d, dtype=np.float32), dtype="f4"))
        for m in self.maps:
            m.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.luts = self._luts(ctx, lut)
        for i, name in enumerate(("content", "maps", "alpha3", "beta3", "lut3", "lut1")):
            if name in self.prog:
                self.prog[name] = i
        values = {"gamma": float(gamma), "height": h, "rect_lo": ((x0 + 0.5) / tw, (y0 + 0.5) / th),
                  "rect_hi": ((x0 + rw - 0.5) / tw, (y0 + rh - 0.5) / th),
                  "lut_n": 2.0 if lut is None else float(lut.table.shape[0]),
                  "lut_lo": (0.0, 0.0, 0.0) if lut is None else tuple(float(v) for v in lut.lo),
                  "lut_hi": (1.0, 1.0, 1.0) if lut is None else tuple(float(v) for v in lut.hi)}
        for name, value in values.items():
            if name in self.prog:  # the compiler drops what the shader does not use
                self.prog[name] = value
        m = np.eye(3) if matrix is None else np.asarray(matrix, dtype=np.float64).reshape(3, 3)
        if "matrix" in self.prog:
            self.prog["matrix"].write(np.ascontiguousarray(m.T, dtype=np.float32))  # GLSL's mat3 is column-major
        quad = np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype=np.float32)
        self.vbo = ctx.buffer(quad)
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "2f", "in_pos")])
        self.color = ctx.renderbuffer(size, 4)
        self.fbo = ctx.framebuffer(color_attachments=[self.color])
        self.out = np.empty((h, w, 4), dtype=np.uint8)

    @staticmethod
    def _luts(ctx, lut) -> list:
        """The 3D and 1D table textures (a 2x2x2 and 2x1 stand-in for the one not used)."""
        import moderngl

        t3 = np.zeros((2, 2, 2, 3), dtype=np.float32) if lut is None or lut.dims != 3 else lut.table
        t1 = np.zeros((2, 3), dtype=np.float32) if lut is None or lut.dims != 1 else lut.table
        lut3 = ctx.texture3d(t3.shape[2::-1], 3, np.ascontiguousarray(t3, dtype=np.float32), dtype="f4")
        lut1 = ctx.texture((t1.shape[0], 1), 3, np.ascontiguousarray(t1, dtype=np.float32), dtype="f4")
        for t in (lut3, lut1):
            t.filter = (moderngl.LINEAR, moderngl.LINEAR)
            t.repeat_x = t.repeat_y = False
        lut3.repeat_z = False
        return [lut3, lut1]

    def run(self, tile: np.ndarray) -> np.ndarray:
        """(h, w, 3) uint8, row 0 at the bottom (as the tile): the output's picture of ``tile``
        ((th, tw, 3) uint8, row 0 at the bottom)."""
        import moderngl

        self.content.write(np.ascontiguousarray(tile))
        self.content.use(0)
        for i, t in enumerate(self.maps + self.luts, 1):
            t.use(i)
        self.fbo.use()
        self.fbo.viewport = (0, 0, *self.size)
        self.fbo.scissor = None
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
        self.vao.render(moderngl.TRIANGLE_STRIP)
        self.fbo.read_into(self.out, components=4)
        return self.out[..., :3]

    def release(self) -> None:
        for r in (self.vao, self.vbo, self.fbo, self.color, self.content, *self.maps, *self.luts, self.prog):
            r.release()
