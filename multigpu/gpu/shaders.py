"""The renderer's GLSL: a vertex shader that decodes the packed normal, moves the vertex by its
object's map where the scene moves (``MOVING``, ``core/motion.py``), and takes each vertex's
colour (its object's, from a storage buffer indexed by the vertex's object id, or the model's
own per-vertex RGBA8 where ``VERTEX_COLORS`` is defined), and a headlight-lit fragment shader.

``TEXTURED``: the colour is multiplied by the vertex's texture layer (``scene/textures.py``), with
that layer's wrap and filter; a texel under a MASK layer's cutoff is left out. From the texel
pool (``TEXEL_POOL``, the default): the layer's mip chain read from a storage buffer, wrapped per
texel (repeat, clamp to edge, mirrored repeat, exactly as GL does) and filtered here (nearest, or
bilinear within a level and linear between levels, the level chosen from the UV's screen
derivatives as GL's isotropic rule does). From a texture array (``MULTIGPU_TEXTURES=array``):
the hardware's filter, one sampler per filter, repeat the sampler's and clamp and mirror folded
into the UV. The derivatives come from the whole canvas's 2x2 pixel quads, so a region's pixels
are those a one-rank render draws.
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
#endif
#if !defined(VERTEX_COLORS) || defined(MOVING)
in uint in_obj;
#endif
#ifdef MOVING
layout(std430, binding = 4) readonly buffer Motions { vec4 motions[]; };  // 3 rows of [A | b] per object
#endif
#ifdef MORPH
in int in_morph;  // this vertex's row of deltas (-1: it does not morph)
uniform int morph_targets;
layout(std430, binding = 5) readonly buffer MorphDeltas { vec4 deltas[]; };  // morph_targets a row
layout(std430, binding = 6) readonly buffer MorphWeights { float weights[]; };
layout(std430, binding = 7) readonly buffer MorphOf { ivec2 morph_of[]; };  // per object: first weight, count
#endif
#ifdef SKIN
in uvec4 in_joints;  // the joints this vertex leans on (the palette's), and how much
in vec4 in_weights;
layout(std430, binding = 8) readonly buffer Palette { vec4 palette[]; };  // 3 rows of [A | b] per joint
#endif
#ifdef TEXTURED
in vec3 in_uvl;  // UV and texture layer (-1: none)
out vec2 v_uv;
flat out int v_layer;
#endif
out vec3 v_nrm;
out vec3 v_col;
void main() {
    vec2 f = vec2(float(in_nrm & 0xFFFFu), float(in_nrm >> 16)) / 65535.0 * 2.0 - 1.0;
    vec3 n = vec3(f, 1.0 - abs(f.x) - abs(f.y));
    float t = max(-n.z, 0.0);
    n.xy += vec2(n.x >= 0.0 ? -t : t, n.y >= 0.0 ? -t : t);
#ifdef MOVING
    vec4 r0 = motions[3u * in_obj], r1 = motions[3u * in_obj + 1u], r2 = motions[3u * in_obj + 2u];
    vec4 p = vec4(in_pos, 1.0);
#ifdef MORPH
    if (in_morph >= 0) {  // the morph targets' deltas at this frame's weights, then the map
        ivec2 w = morph_of[in_obj];
        for (int k = 0; k < w.y; ++k) p.xyz += weights[w.x + k] * deltas[in_morph * morph_targets + k].xyz;
    }
#endif
#ifdef SKIN
    if (in_weights != vec4(0.0)) {  // a weighted mean of its joints' maps (the mesh's own is the identity)
        vec3 q = vec3(0.0), m = vec3(0.0);
        for (int i = 0; i < 4; ++i) {
            uint j = 3u * in_joints[i];
            vec4 a = palette[j], b = palette[j + 1u], c = palette[j + 2u];
            vec3 s0 = vec3(a.x, b.x, c.x), s1 = vec3(a.y, b.y, c.y), s2 = vec3(a.z, b.z, c.z);
            q += in_weights[i] * vec3(dot(a, p), dot(b, p), dot(c, p));
            m += in_weights[i] * (mat3(cross(s1, s2), cross(s2, s0), cross(s0, s1)) * n);
        }
        p = vec4(q, 1.0);
        n = m;
    }
#endif
    gl_Position = mvp * vec4(dot(r0, p), dot(r1, p), dot(r2, p), 1.0);
    vec3 a0 = vec3(r0.x, r1.x, r2.x), a1 = vec3(r0.y, r1.y, r2.y), a2 = vec3(r0.z, r1.z, r2.z);
    n = mat3(cross(a1, a2), cross(a2, a0), cross(a0, a1)) * n;  // the cofactor: normals stay normal
#else
    gl_Position = mvp * vec4(in_pos, 1.0);
#endif
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
layout(std430, binding = 1) readonly buffer Layers { vec4 layers[]; };  // wrap s, wrap t, nearest, cutoff
in vec2 v_uv;
flat in int v_layer;
#ifdef TEXEL_POOL
layout(std430, binding = 2) readonly buffer Levels { ivec4 levels[]; };  // 16 a layer: first, w, h, count
layout(std430, binding = 3) readonly buffer Texels { uint texels[]; };  // RGBA8
float reduce(float u, float wrap) {  // into one period: [0, 1], [0, 1) or [0, 2)
    if (wrap == 1.0) return clamp(u, 0.0, 1.0);
    if (wrap == 2.0) return u - 2.0 * floor(0.5 * u);
    return fract(u);
}
int wrap_index(int i, int n, float wrap) {  // i in [-1, 2n] (a reduced UV's): no integer division
    if (wrap == 1.0) return clamp(i, 0, n - 1);
    if (wrap == 2.0) { int j = i < 0 ? i + 2 * n : (i >= 2 * n ? i - 2 * n : i); return j < n ? j : 2 * n - 1 - j; }
    return i < 0 ? i + n : (i >= n ? i - n : i);
}
vec4 texel(ivec4 lv, ivec2 i, vec4 mode) {
    return unpackUnorm4x8(texels[lv.x + wrap_index(i.y, lv.z, mode.y) * lv.y + wrap_index(i.x, lv.y, mode.x)]);
}
vec4 bilinear(ivec4 lv, vec2 uv, vec4 mode) {
    vec2 p = uv * vec2(lv.yz) - 0.5;
    vec2 f = fract(p);
    ivec2 i = ivec2(floor(p));
    return mix(mix(texel(lv, i, mode), texel(lv, i + ivec2(1, 0), mode), f.x),
               mix(texel(lv, i + ivec2(0, 1), mode), texel(lv, i + ivec2(1, 1), mode), f.x), f.y);
}
vec4 sample_layer(int layer, vec2 uv, vec2 dx, vec2 dy) {
    vec4 mode = layers[layer];
    ivec4 top = levels[16 * layer];
    vec2 size = vec2(top.yz);
    float rho = max(length(dx * size), length(dy * size));
    float lod = clamp(log2(max(rho, 1e-30)), 0.0, float(top.w - 1));
    uv = vec2(reduce(uv.x, mode.x), reduce(uv.y, mode.y));
    if (mode.z > 0.5) {  // nearest, nearest mipmap nearest
        ivec4 lv = levels[16 * layer + (rho > 1.0 ? int(floor(lod + 0.5)) : 0)];
        return texel(lv, ivec2(floor(uv * vec2(lv.yz))), mode);
    }
    if (rho <= 1.0) return bilinear(top, uv, mode);  // magnified
    int l0 = int(floor(lod));
    int l1 = min(l0 + 1, top.w - 1);
    return mix(bilinear(levels[16 * layer + l0], uv, mode), bilinear(levels[16 * layer + l1], uv, mode),
               lod - float(l0));
}
#else
uniform sampler2DArray tex_linear;
uniform sampler2DArray tex_nearest;
float fold(float u, float wrap, float texel) {
    if (wrap == 1.0) return clamp(u, 0.5 * texel, 1.0 - 0.5 * texel);
    if (wrap == 2.0) return 1.0 - abs(mod(u, 2.0) - 1.0);
    return u;
}
vec4 sample_layer(int layer, vec2 uv, vec2 dx, vec2 dy) {
    vec4 mode = layers[layer];
    vec2 texel = 1.0 / vec2(textureSize(tex_linear, 0).xy);
    vec3 at = vec3(fold(uv.x, mode.x, texel.x), fold(uv.y, mode.y, texel.y), float(layer));
    return mode.z > 0.5 ? textureGrad(tex_nearest, at, dx, dy) : textureGrad(tex_linear, at, dx, dy);
}
#endif
#endif
out vec4 f_color;
void main() {
    vec3 col = v_col;
#ifdef TEXTURED
    vec2 dx = dFdx(v_uv), dy = dFdy(v_uv);  // in uniform control flow: every pixel of a quad
    if (v_layer >= 0) {
        vec4 t = sample_layer(v_layer, v_uv, dx, dy);
        if (t.a < layers[v_layer].w) discard;
        col *= t.rgb;
    }
#endif
    float d = abs(dot(normalize(v_nrm), light));
    f_color = vec4(col * (0.25 + 0.75 * d), 1.0);
}
"""


def _defined(source: str, names: list[str]) -> str:
    return source.replace("#version 430", "\n".join(["#version 430", *(f"#define {n}" for n in names)]))


#: how textures are drawn: from the texel pool (a storage buffer) or a hardware texture array
TEXTURE_PATHS = ("pool", "array")


def vertex_shader(per_vertex_colors: bool, textured: bool = False, moving: bool = False, morph: bool = False,
                  skin: bool = False) -> str:
    """The vertex shader, reading the model's per-vertex colours or its objects' colours, and
    its texture coordinates where it is ``textured``; ``moving``: each vertex moved by its
    object's map (``core/motion.py``) before the camera's, its morph targets' deltas added first
    where it has any (``morph``), and its joints' maps before that where it is skinned (``skin``)."""
    return _defined(VERTEX, ["VERTEX_COLORS"] * per_vertex_colors + ["TEXTURED"] * textured + ["MOVING"] * moving
                    + ["MORPH"] * (moving and morph) + ["SKIN"] * (moving and skin))


def fragment_shader(textured: bool = False, path: str = "pool") -> str:
    """The fragment shader, with the model's textures where it is ``textured``, drawn from
    ``path`` (``TEXTURE_PATHS``)."""
    return _defined(FRAGMENT, ["TEXTURED"] * textured + ["TEXEL_POOL"] * (textured and path == "pool"))
