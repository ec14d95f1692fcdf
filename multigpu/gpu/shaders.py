"""The renderer's GLSL: a vertex shader that decodes the packed normal and takes each vertex's
colour (its object's, from a storage buffer indexed by the vertex's object id, or the model's
own per-vertex RGBA8 where ``VERTEX_COLORS`` is defined), and a headlight-lit fragment shader.
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


def vertex_shader(per_vertex_colors: bool) -> str:
    """The vertex shader, reading the model's per-vertex colours or its objects' colours."""
    return VERTEX.replace("#version 430", "#version 430\n#define VERTEX_COLORS") if per_vertex_colors else VERTEX
