"""The renderer's GLSL: a vertex shader that decodes the packed normal and takes each vertex's
colour (its object's, from a storage buffer indexed by the vertex's object id, or the model's
own per-vertex RGBA8 where ``VERTEX_COLORS`` is defined), and a headlight-lit fragment shader.

``TEXTURED``: the colour is multiplied by the vertex's texture layer (``scene/textures.py``),
sampled with that layer's wrap (repeat is the sampler's; clamp and mirror are folded here, with
the unfolded UV's derivatives so the mip level does not jump at a fold) and filter (one sampler
of the array per filter); a texel under a MASK layer's cutoff is left out. The derivatives come
from the whole canvas's 2x2 pixel quads, so a region's pixels are those a one-rank render draws.
"""

from __future__ import annotations

VERTEX = """
#version 430
uniform mat4 mvp;
layout(std430, binding = 0) readonly buffer Colors { float colors[]; };  // 3 per object
in vec3 in_pos;
in uint in_nrm;  // octahedral, 16 + 16 bits (pack_normals)
#ifdef VERTEX_COLORS
in uint in_rgba;  // the model's colour at this vertex, RGBA8
#else
in uint in_obj;
#endif
#ifdef TEXTURED
in vec3 in_uvl;  // UV and texture layer (-1: none)
out vec2 v_uv;
flat out int v_layer;
#endif
out vec3 v_nrm;
out vec3 v_col;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    vec2 f = vec2(float(in_nrm & 0xFFFFu), float(in_nrm >> 16)) / 65535.0 * 2.0 - 1.0;
    vec3 n = vec3(f, 1.0 - abs(f.x) - abs(f.y));
    float t = max(-n.z, 0.0);
    n.xy += vec2(n.x >= 0.0 ? -t : t, n.y >= 0.0 ? -t : t);
    v_nrm = n;
#ifdef VERTEX_COLORS
    v_col = unpackUnorm4x8(in_rgba).rgb;
#else
    uint c = 3u * in_obj;
    v_col = vec3(colors[c], colors[c + 1u], colors[c + 2u]);
#endif
#ifdef TEXTURED
    v_uv = in_uvl.xy;
    v_layer = int(in_uvl.z);
#endif
}
"""

FRAGMENT = """
#version 430
uniform vec3 light;
in vec3 v_nrm;
in vec3 v_col;
#ifdef TEXTURED
uniform sampler2DArray tex_linear;
uniform sampler2DArray tex_nearest;
layout(std430, binding = 1) readonly buffer Layers { vec4 layers[]; };  // wrap s, wrap t, nearest, cutoff
in vec2 v_uv;
flat in int v_layer;
float fold(float u, float wrap, float texel) {
    if (wrap == 1.0) return clamp(u, 0.5 * texel, 1.0 - 0.5 * texel);
    if (wrap == 2.0) return 1.0 - abs(mod(u, 2.0) - 1.0);
    return u;
}
#endif
out vec4 f_color;
void main() {
    vec3 col = v_col;
#ifdef TEXTURED
    vec2 dx = dFdx(v_uv), dy = dFdy(v_uv);  // in uniform control flow: every pixel of a quad
    if (v_layer >= 0) {
        vec4 mode = layers[v_layer];
        vec2 texel = 1.0 / vec2(textureSize(tex_linear, 0).xy);
        vec3 at = vec3(fold(v_uv.x, mode.x, texel.x), fold(v_uv.y, mode.y, texel.y), float(v_layer));
        vec4 t = mode.z > 0.5 ? textureGrad(tex_nearest, at, dx, dy) : textureGrad(tex_linear, at, dx, dy);
        if (t.a < mode.w) discard;
        col *= t.rgb;
    }
#endif
    float d = abs(dot(normalize(v_nrm), light));
    f_color = vec4(col * (0.25 + 0.75 * d), 1.0);
}
"""


def _defined(source: str, names: list[str]) -> str:
    return source.replace("#version 430", "\n".join(["#version 430", *(f"#define {n}" for n in names)]))


def vertex_shader(per_vertex_colors: bool, textured: bool = False) -> str:
    """The vertex shader, reading the model's per-vertex colours or its objects' colours, and
    its texture coordinates where it is ``textured``."""
    return _defined(VERTEX, ["VERTEX_COLORS"] * per_vertex_colors + ["TEXTURED"] * textured)


def fragment_shader(textured: bool = False) -> str:
    """The fragment shader, with the model's textures where it is ``textured``."""
    return _defined(FRAGMENT, ["TEXTURED"] * textured)
