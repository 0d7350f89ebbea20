"""GLSL vertex shader of the instanced-decorator AO model (Sloan et al. 2013, section 2.2).

Per vertex of a tree model: ``a_local_ao`` (the model's local AO, baked in isolation). Per instance
(EXT_mesh_gpu_instancing attributes, divisor 1): ``i_translation``, ``i_rotation`` (unit quaternion
x, y, z, w), ``i_scale`` and ``i_ao_global`` = y, the 4 coefficients of the linear global function

    G(p) = y.x + y.yzw . (p - i_translation)        (p: world position of the vertex)

The shader outputs ``v_ao = clamp(a_local_ao * G(p), 0, 1)``: the product is formed per vertex and
interpolated by the rasteriser (what the bake's error table measures). Same habit as
:mod:`neuralao.export.glsl.templates`: the text lives in named templates here, filled strictly by
:func:`fill`.
"""

from __future__ import annotations

from string import Template

from neuralao.export.glsl.templates import fill_from

_T: dict[str, str] = {}

_T["decorator_vertex"] = """#version ${version}
// neuralao: instanced decorator AO = local AO (per model vertex) x linear global AO (per instance).
layout(location = 0) in vec3 a_position;     // object space
layout(location = 1) in float a_local_ao;    // per-model local AO in [0, 1]
layout(location = 2) in vec3 i_translation;  // per instance
layout(location = 3) in vec4 i_rotation;     // per instance, unit quaternion (x, y, z, w)
layout(location = 4) in vec3 i_scale;        // per instance
layout(location = 5) in vec4 i_ao_global;    // per instance: G(p) = x + dot(yzw, p - i_translation)
uniform mat4 u_view_projection;
out float v_ao;
out vec3 v_world;

vec3 nao_rotate(vec4 q, vec3 v) {
    vec3 t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

void main() {
    vec3 offset = nao_rotate(i_rotation, a_position * i_scale);
    vec3 world = offset + i_translation;
    float global_ao = i_ao_global.x + dot(i_ao_global.yzw, offset);
    v_ao = clamp(a_local_ao * global_ao, 0.0, 1.0);
    v_world = world;
    gl_Position = u_view_projection * vec4(world, 1.0);
}
"""

_T["decorator_fragment"] = """#version ${version}
in float v_ao;
in vec3 v_world;
layout(location = 0) out vec4 o_colour;
void main() {
    o_colour = vec4(vec3(v_ao), 1.0);
}
"""

TEMPLATES: dict[str, Template] = {name: Template(text) for name, text in _T.items()}
# Names of the attributes, in location order (the manifest states them for an engine).
ATTRIBUTES = ["a_position", "a_local_ao", "i_translation", "i_rotation", "i_scale", "i_ao_global"]


def fill(template: str, /, **fields: object) -> str:
    return fill_from(TEMPLATES, template, "decorator GLSL", **fields)


def decorator_shaders(version: str = "330 core") -> dict[str, str]:
    """{"vertex": ..., "fragment": ...} GLSL source of the decorator AO draw."""
    return {
        "vertex": fill("decorator_vertex", version=version),
        "fragment": fill("decorator_fragment", version=version),
    }


def manifest() -> dict:
    return {
        "shader": "decorator.vert",
        "fragment": "decorator.frag",
        "attributes": {name: loc for loc, name in enumerate(ATTRIBUTES)},
        "per_instance": ["i_translation", "i_rotation", "i_scale", "i_ao_global"],
        "gltf": {
            "a_position": "POSITION",
            "a_local_ao": "_AO_LOCAL",
            "i_translation": "TRANSLATION",
            "i_rotation": "ROTATION",
            "i_scale": "SCALE",
            "i_ao_global": "_AO_GLOBAL",
        },
        "model": (
            "v_ao = clamp(a_local_ao * (g.x + dot(g.yzw, p_world - i_translation)), 0, 1), g = i_ao_global"
        ),
        "outputs": ["v_ao", "v_world"],
    }
