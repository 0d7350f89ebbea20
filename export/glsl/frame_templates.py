"""Shader text of the frame passes (every compute pass of a screen-space frame that is not the network),
as named templates, and the fill functions of each compute dialect.

The habit of :mod:`neuralao.export.glsl.templates`: ``_FT`` holds the templates every dialect shares,
written once in GLSL with its dialect words (``${vec4}``, ``${let_float}``, ``${var_int:i}``,
``${fetch}`` ... and the words added here: ``${vec2}``, ``${vec3}``, ``${let_vec2}``, ``${let_vec3}``,
``${var_vec3}`` and the frame uniforms ``${u_proj}``, ``${u_radius}``, ``${u_pixels_per_unit}``);
``_FG`` the GLSL 4.30 spelling of what differs in structure (entry point, resource declarations, helper
functions), ``_FV`` the Vulkan GLSL overrides of ``_FG`` and ``_FW`` the WGSL ones. The one writer is
:mod:`neuralao.export.glsl.frame`; :func:`fill` / :func:`fill_vulkan` / :func:`fill_wgsl` are strict
(:func:`neuralao.export.glsl.templates.fill_from`).

Conventions every body relies on:

* ``px`` is the invocation's pixel in **GL order** (row 0 at the bottom, so pixel y and camera-space y
  both point up), whatever the engine's textures are: ``nao_texel`` maps a GL-order pixel to the
  texture's own row (the frame uniform ``u_flip_y``: 1 = textures bottom-up as GL stores them, 0 = row 0
  at the top as D3D, Vulkan, Metal and WebGPU store them), so one frame stored either way gives the same
  AO image, stored the same way. ``nao_load(src, p, layer)`` and ``nao_store(p, layer, v)`` take GL-order
  pixels; ``nao_size(src)`` is a texture's width and height.
* every texture is a 2-D array texture (layers of 4 channels, fetched without a sampler); a pass writes
  one output ``dst``, ``rgba32f``, ``r32f``, ``r16f`` or ``r16`` (16-bit unsigned normalised: the store
  clamps to [0, 1]).
* no pass reads a full-resolution position texture: ``nao_position(p, size, z)`` reconstructs the
  camera-space position of pixel ``p`` of a ``size`` frame from the engine's linear depth ``z`` and
  ``u_proj`` (as XeGTAO does from its depth); a pixel is foreground where ``z > 0``.
* values substituted by the writer are integers, GLSL float literals (``glsl_float``: they parse back to
  the exact float32) and other templates of this table.
"""

from __future__ import annotations

from string import Template

from neuralao.export.glsl.templates import _WGSL_WORDS, _WORDS, _with_words, fill_from

# Words of the frame passes on top of the network's (templates._WORDS / _WGSL_WORDS): the vector types
# the network never needs, declarations of them, and the frame uniforms (loose names in GLSL, members of
# the uniform struct in WGSL).
_FRAME_WORDS = {
    "vec2": "vec2",
    "vec3": "vec3",
    "let_vec2": "vec2",
    "let_vec3": "vec3",
    "var_vec3": "vec3",
    "u_proj": "u_proj",
    "u_radius": "u_radius",
    "u_pixels_per_unit": "u_pixels_per_unit",
}
_FRAME_WGSL_WORDS = {
    "vec2": "vec2<f32>",
    "vec3": "vec3<f32>",
    "let_vec2": "let",
    "let_vec3": "let",
    "var_vec3": "var",
    "u_proj": "nao_frame.proj",
    "u_radius": "nao_frame.radius",
    "u_pixels_per_unit": "nao_frame.pixels_per_unit",
}

_FT: dict[str, str] = {}  # every dialect's, in GLSL with dialect words
_FG: dict[str, str] = {}  # GLSL 4.30
_FV: dict[str, str] = {}  # Vulkan GLSL overrides of _FG
_FW: dict[str, str] = {}  # WGSL

# --------------------------------------------------------------------------- pass skeleton, GLSL 4.30

_FG["frame_pass"] = """${header}
// neuralao frame pass ${name}: ${summary}
layout(local_size_x = ${local_x}, local_size_y = ${local_y}, local_size_z = 1) in;

${declarations}

${prelude}
${functions}
void main() {
    ivec2 gid = ivec2(gl_GlobalInvocationID.xy);
    ivec2 out_size = imageSize(dst).xy;${load}
    if (gid.x >= out_size.x || gid.y >= out_size.y) {
        return;
    }
    ivec2 px = nao_texel(gid, out_size);  // this invocation's pixel, GL order
${body}
}
"""

# ${load} of a pass whose workgroup first loads what its pixels share into workgroup memory: every
# invocation runs ${tile_load} (none returns before the barrier), then those outside the frame stop.
# Other passes' ${load} and ${builtins} are empty.
_FG["frame_pass_load"] = """
    int lid = int(gl_LocalInvocationIndex);
    ivec2 group0 = ivec2(gl_WorkGroupID.xy) * ivec2(${local_x}, ${local_y});
${tile_load}
    memoryBarrierShared();
    barrier();"""

_FG["header"] = "#version 430 core"
_FG["input_decl"] = "layout(binding = ${binding}) uniform highp sampler2DArray ${name};"
_FG["output_decl"] = "layout(binding = ${binding}, ${format}) writeonly uniform highp image2DArray dst;"
_FG["format_rgba32f"] = "rgba32f"
_FG["format_r32f"] = "r32f"
_FG["format_r16f"] = "r16f"
_FG["format_r16"] = "r16"
# One per-frame uniform block, the same bytes for every frame pass (std140: offsets 0, 8, 12, 16).
_FG["uniforms_decl"] = """layout(std140, binding = ${binding}) uniform FrameUniforms {
    vec2 u_proj;               // (P00, P11) of the projection matrix
    float u_radius;            // R, the AO radius in scene units
    float u_pixels_per_unit;   // 0.5 * H * P11: pixels spanned by one scene unit at depth 1
    int u_flip_y;              // 1: textures bottom-up (GL), 0: row 0 at the top
};"""

_FG[
    "prelude"
] = """// GL-order pixel (row 0 at the bottom) <-> texel of a texture of this frame (its own row order).
ivec2 nao_texel(ivec2 p, ivec2 size) {
    return u_flip_y != 0 ? p : ivec2(p.x, size.y - 1 - p.y);
}

ivec2 nao_size(highp ${sampler} t) {
    return textureSize(t, 0).xy;
}

vec4 nao_load(highp ${sampler} t, ivec2 p, int layer) {
    return texelFetch(t, ivec3(nao_texel(p, nao_size(t)), layer), 0);
}

void nao_store(ivec2 p, int layer, vec4 v) {
    imageStore(dst, ivec3(nao_texel(p, imageSize(dst).xy), layer), v);
}

bool nao_inside(ivec2 q, ivec2 size) {
    return all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size));
}

float nao_acos(float x) {
    return acos(clamp(x, -1.0, 1.0));
}

// Camera-space position of GL-order pixel p of a size-pixel frame at linear depth z (OpenGL camera, -z
// forward): the pixel centre's ray at depth z.
vec3 nao_position(ivec2 p, ivec2 size, float z) {
    vec2 ndc = (vec2(p) + 0.5) / vec2(size) * 2.0 - 1.0;
    return vec3(ndc.x / u_proj.x * z, ndc.y / u_proj.y * z, -z);
}

// floor(a / b) for b > 0 (GLSL's int division truncates toward 0)
int nao_floor_div(int a, int b) {
    return a >= 0 ? a / b : -((-a + b - 1) / b);
}
"""
_FG["sampler"] = "sampler2DArray"

# GTAO's noise tile as constants, texel t = y * size + x of the tile at (x, y), GL rows: its slice
# directions (cos phi, sin phi), phi = (slice + noise.x) * pi / slices, baked so that no GPU's cos / sin
# moves a horizon sample to the next pixel (entry t * slices + slice), and its step jitter noise.y.
_FG["noise_table"] = """const vec2 NAO_DIRECTIONS[${entries}] = vec2[${entries}](
${directions});
const float NAO_JITTER[${count}] = float[${count}](
${jitter});

int nao_tile(ivec2 p) {
    return (p.y % ${size}) * ${size} + p.x % ${size};
}

vec2 nao_direction(int tile, int slice) {
    return NAO_DIRECTIONS[tile * ${slices} + slice];
}

float nao_jitter(int tile) {
    return NAO_JITTER[tile];
}
"""

# --------------------------------------------------------------------------- Vulkan GLSL

_FV["header"] = """#version 450
#extension GL_EXT_samplerless_texture_functions : require"""
_FV["input_decl"] = "layout(set = 0, binding = ${binding}) uniform highp texture2DArray ${name};"
_FV["output_decl"] = (
    "layout(set = 0, binding = ${binding}, ${format}) writeonly uniform highp image2DArray dst;"
)
_FV["uniforms_decl"] = _FG["uniforms_decl"].replace("std140, binding", "std140, set = 0, binding")
_FV["sampler"] = "texture2DArray"

# --------------------------------------------------------------------------- WGSL

_FW["frame_pass"] = """${header}
// neuralao frame pass ${name}: ${summary}

${declarations}

${prelude}
${functions}
@compute @workgroup_size(${local_x}, ${local_y}, 1)
fn main(@builtin(global_invocation_id) gid_u: vec3<u32>${builtins}) {
    let gid = vec2<i32>(gid_u.xy);
    let out_size = vec2<i32>(textureDimensions(dst));${load}
    if (gid.x >= out_size.x || gid.y >= out_size.y) {
        return;
    }
    let px = nao_texel(gid, out_size);  // this invocation's pixel, GL order
${body}
}
"""

_FW["frame_pass_builtins"] = (
    ", @builtin(local_invocation_index) lid_u: u32, @builtin(workgroup_id) group_u: vec3<u32>"
)
_FW["frame_pass_load"] = """
    let lid = i32(lid_u);
    let group0 = vec2<i32>(group_u.xy) * vec2<i32>(${local_x}, ${local_y});
${tile_load}
    workgroupBarrier();"""

_FW["header"] = "// WGSL (WebGPU compute), generated by neuralao from the same templates as the GLSL"
_FW["input_decl"] = "@group(0) @binding(${binding}) var ${name}: texture_2d_array<f32>;"
_FW["output_decl"] = "@group(0) @binding(${binding}) var dst: texture_storage_2d_array<${format}, write>;"
_FW["format_rgba32f"] = "rgba32float"
_FW["format_r32f"] = "r32float"
_FW["uniforms_decl"] = """struct FrameUniforms {
    proj: vec2<f32>,           // (P00, P11) of the projection matrix
    radius: f32,               // R, the AO radius in scene units
    pixels_per_unit: f32,      // 0.5 * H * P11: pixels spanned by one scene unit at depth 1
    flip_y: i32,               // 1: textures bottom-up (GL), 0: row 0 at the top
};
@group(0) @binding(${binding}) var<uniform> nao_frame: FrameUniforms;"""

_FW[
    "prelude"
] = """// GL-order pixel (row 0 at the bottom) <-> texel of a texture of this frame (its own row order).
fn nao_texel(p: vec2<i32>, size: vec2<i32>) -> vec2<i32> {
    if (nao_frame.flip_y != 0) {
        return p;
    }
    return vec2<i32>(p.x, size.y - 1 - p.y);
}

fn nao_size(t: texture_2d_array<f32>) -> vec2<i32> {
    return vec2<i32>(textureDimensions(t));
}

fn nao_load(t: texture_2d_array<f32>, p: vec2<i32>, layer: i32) -> vec4<f32> {
    return textureLoad(t, nao_texel(p, nao_size(t)), layer, 0);
}

fn nao_store(p: vec2<i32>, layer: i32, v: vec4<f32>) {
    textureStore(dst, nao_texel(p, vec2<i32>(textureDimensions(dst))), layer, v);
}

fn nao_inside(q: vec2<i32>, size: vec2<i32>) -> bool {
    return all(q >= vec2<i32>(0)) && all(q < size);
}

fn nao_acos(x: f32) -> f32 {
    return acos(clamp(x, -1.0, 1.0));
}

// Camera-space position of GL-order pixel p of a size-pixel frame at linear depth z (OpenGL camera, -z
// forward): the pixel centre's ray at depth z.
fn nao_position(p: vec2<i32>, size: vec2<i32>, z: f32) -> vec3<f32> {
    let ndc = (vec2<f32>(p) + 0.5) / vec2<f32>(size) * 2.0 - 1.0;
    return vec3<f32>(ndc.x / nao_frame.proj.x * z, ndc.y / nao_frame.proj.y * z, -z);
}

// floor(a / b) for b > 0 (WGSL's i32 division truncates toward 0)
fn nao_floor_div(a: i32, b: i32) -> i32 {
    if (a >= 0) {
        return a / b;
    }
    return -((-a + b - 1) / b);
}
"""

_FW[
    "noise_table"
] = """// GTAO's noise tile as constants, texel t = y * size + x of the tile at (x, y), GL rows: its slice
// directions (cos phi, sin phi), phi = (slice + noise.x) * pi / slices, baked so that no GPU's cos / sin
// moves a horizon sample to the next pixel (entry t * slices + slice), and its step jitter noise.y.
fn nao_tile(p: vec2<i32>) -> i32 {
    return (p.y % ${size}) * ${size} + p.x % ${size};
}

fn nao_direction(tile: i32, slice: i32) -> vec2<f32> {
    var table = array<vec2<f32>, ${entries}>(
${directions});
    return table[tile * ${slices} + slice];
}

fn nao_jitter(tile: i32) -> f32 {
    var table = array<f32, ${count}>(
${jitter});
    return table[tile];
}
"""

# --------------------------------------------------------------------------- shared bodies

_FT["direction_item"] = "    ${vec2}(${x}, ${y})"
_FT["jitter_item"] = "    ${y}"

# GTAO (Jimenez et al. 2016, structured as Intel's XeGTAO), the maths of neuralao.runtime.baselines'
# gtao fragment shader, which the shipped hybrid was trained on: ${slices} slice directions rotated by
# the noise tile, ${steps} horizon samples per side up to the projected radius (quadratic spacing,
# jittered), horizons faded over the last ${falloff} of the radius, the cosine-weighted visibility
# integrated analytically per slice. src0: the engine's linear depth, src1: its normal.
_FT["gtao_body"] = """    ${let_float} z = nao_load(src0, px, 0).x;
    if (!(z > 0.0)) {
        nao_store(px, 0, ${vec4}(1.0));
        return;
    }
    ${let_vec3} p = nao_position(px, out_size, z);
    ${var_vec3} n = nao_load(src1, px, 0).xyz;
    ${let_float} ln = length(n);
    if (ln > 1e-20) {
        n = n / ln;
    } else {
        n = ${vec3}(0.0, 0.0, 1.0);
    }
    ${let_vec3} view_v = normalize(-p);
    ${let_float} radius_px = ${u_radius} * ${u_pixels_per_unit} / max(-p.z, 1e-30);
    if (!(radius_px > 1.0)) {
        nao_store(px, 0, ${vec4}(1.0));  // the radius stays inside this pixel
        return;
    }
    ${let_int} tile = nao_tile(px);
    ${let_float} jitter = nao_jitter(tile);
    ${let_float} falloff_range = max(${falloff}, 1e-6) * ${u_radius};
    ${let_float} falloff_mul = -1.0 / falloff_range;
    ${let_float} falloff_add = (${u_radius} - falloff_range) / falloff_range + 1.0;
    ${let_float} min_s = 1.3 / radius_px;  // skip samples within ~1 pixel (self)
    ${let_vec2} centre = ${vec2}(px) + 0.5;
    ${var_float:visibility} = 0.0;
    for (${var_int:slice} = 0; slice < ${slices}; ${inc:slice}) {
        ${let_vec2} omega = nao_direction(tile, slice);  // screen direction = camera-space (x, y)
        ${let_vec3} dir_v = ${vec3}(omega, 0.0);
        ${let_vec3} ortho_v = dir_v - dot(dir_v, view_v) * view_v;
        ${let_vec3} axis_v = normalize(cross(dir_v, view_v));
        ${let_vec3} proj_n = n - axis_v * dot(n, axis_v);
        ${let_float} proj_len = length(proj_n);
        ${var_float:sign_n} = -1.0;
        if (dot(ortho_v, proj_n) >= 0.0) {
            sign_n = 1.0;
        }
        ${let_float} cos_n = clamp(dot(proj_n, view_v) / max(proj_len, 1e-20), 0.0, 1.0);
        ${let_float} ang_n = sign_n * nao_acos(cos_n);
        ${let_float} low0 = cos(ang_n + 1.57079632679490);
        ${let_float} low1 = cos(ang_n - 1.57079632679490);
        ${var_float:hc0} = low0;
        ${var_float:hc1} = low1;
        for (${var_int:k} = 0; k < ${steps}; ${inc:k}) {
            ${var_float:s} = (${float}(k) + jitter) / ${float}(${steps});
            s = min_s + (1.0 - min_s) * s * s;
            ${let_vec2} off = omega * (s * radius_px);
            ${let_ivec2} q0 = ${ivec2}(floor(centre + off));
            ${let_ivec2} q1 = ${ivec2}(floor(centre - off));
${sample0}
${sample1}
        }
        ${var_float:h0} = -nao_acos(hc1);
        ${var_float:h1} = nao_acos(hc0);
        h0 = ang_n + clamp(h0 - ang_n, -1.57079632679490, 1.57079632679490);
        h1 = ang_n + clamp(h1 - ang_n, -1.57079632679490, 1.57079632679490);
        ${let_float} sin_n = sin(ang_n);
        ${let_float} arc0 = (cos_n + 2.0 * h0 * sin_n - cos(2.0 * h0 - ang_n)) * 0.25;
        ${let_float} arc1 = (cos_n + 2.0 * h1 * sin_n - cos(2.0 * h1 - ang_n)) * 0.25;
        visibility += proj_len * (arc0 + arc1);
    }
    nao_store(px, 0, ${vec4}(clamp(visibility / ${float}(${slices}), 0.0, 1.0)));"""

# One horizon sample of one side: the point at pixel ${q} (from its depth) raises that side's horizon
# cosine ${hc} (from its low bound ${low}), faded by distance.
_FT["gtao_sample"] = """            if (nao_inside(${q}, out_size)) {
                ${let_float} zq = nao_load(src0, ${q}, 0).x;
                if (zq > 0.0) {
                    ${let_vec3} d = nao_position(${q}, out_size, zq) - p;
                    ${let_float} dist = length(d);
                    if (dist > 1e-30) {
                        ${let_float} w = clamp(dist * falloff_mul + falloff_add, 0.0, 1.0);
                        ${hc} = max(${hc}, mix(${low}, dot(d / dist, view_v), w));
                    }
                }
            }"""

# Mask-aware box blur over the noise tile (window = tile size, offsets -n/2 .. n/2-1): averages
# foreground pixels only, so the background's 1 never bleeds in. src0: the depth, src1: raw GTAO.
_FT["gtao_blur_body"] = """    if (!(nao_load(src0, px, 0).x > 0.0)) {
        nao_store(px, 0, ${vec4}(1.0));
        return;
    }
    ${var_float:sum} = 0.0;
    ${var_float:count} = 0.0;
    for (${var_int:y} = -${half}; y < ${size} - ${half}; ${inc:y}) {
        for (${var_int:x} = -${half}; x < ${size} - ${half}; ${inc:x}) {
            ${let_ivec2} q = px + ${ivec2}(x, y);
            if (!nao_inside(q, out_size)) {
                continue;
            }
            if (!(nao_load(src0, q, 0).x > 0.0)) {
                continue;
            }
            sum += nao_load(src1, q, 0).x;
            count += 1.0;
        }
    }
    nao_store(px, 0, ${vec4}(sum / max(count, 1.0)));"""

# Point sampling to the network's size: low texel t of an axis of n texels copies pixel
# floor((t + 0.5) * N / n) (GL order) of N, exactly, never a blend across an edge. src0: the depth, src1:
# the normal, into layer 0 = (camera-space position, mask) and layer 1 = (normal, 0), zeros on
# background; a hybrid's src2: GTAO, into layer 2 (x), and where it reads it GTAO before its blur (src3,
# into y); with the back layer (input version 4) its depth goes into layer 1's last lane.
_FT["downsample_body"] = """    ${let_ivec2} hi = nao_size(src0);
    ${let_ivec2} q = min(((2 * px + 1) * hi) / (2 * out_size), hi - 1);
    ${let_float} z = nao_load(src0, q, 0).x;
    if (z > 0.0) {
        nao_store(px, 0, ${vec4}(nao_position(q, hi, z), 1.0));
        nao_store(px, 1, ${vec4}(nao_load(src1, q, 0).xyz, ${back}));
    } else {
        nao_store(px, 0, ${vec4}(0.0));
        nao_store(px, 1, ${vec4}(0.0));
    }${gtao}"""
_FT["downsample_back"] = "nao_load(${src}, q, 0).x"
_FT["downsample_gtao"] = """
    nao_store(px, 2, ${vec4}(nao_load(src2, q, 0).x, ${raw}, 0.0, 0.0));"""

# The mean foreground depth, in two passes: the sum and count of each column (GL row order, so a frame
# stored either way sums in the same order), then of the columns; 1 with no foreground.
_FT["depth_columns_body"] = """    ${let_int} rows = nao_size(src0).y;
    ${var_float:sum} = 0.0;
    ${var_float:count} = 0.0;
    for (${var_int:y} = 0; y < rows; ${inc:y}) {
        ${let_vec4} pw = nao_load(src0, ${ivec2}(px.x, y), 0);
        if (pw.w >= 0.5) {
            sum += -pw.z;
            count += 1.0;
        }
    }
    nao_store(px, 0, ${vec4}(sum, count, 0.0, 0.0));"""
_FT["depth_mean_body"] = """    ${let_int} cols = nao_size(src0).x;
    ${var_float:sum} = 0.0;
    ${var_float:count} = 0.0;
    for (${var_int:x} = 0; x < cols; ${inc:x}) {
        ${let_vec4} c = nao_load(src0, ${ivec2}(x, 0), 0);
        sum += c.x;
        count += c.y;
    }
    ${var_float:mean} = 1.0;
    if (count > 0.0) {
        mean = sum / count;
    }
    nao_store(px, 0, ${vec4}(mean, count, sum, 0.0));"""

# The network's input texture: layer 0 = (depth, normal) on foreground, 0 on background; a hybrid's
# layer 1 = (GTAO, 0, 0, 0), 1 on background. Unused lanes are written 0.
_FT["network_input_body"] = """    ${let_vec4} pw = nao_load(src0, px, 0);
    ${var_vec4} x = ${vec4}(0.0);
    if (${foreground}) {
        x = ${vec4}(${depth}, nao_load(src0, px, 1).xyz);
    }
    nao_store(px, 0, x);${gtao}"""
# version 2: depth over the mean foreground depth (src1: the depth_mean pass's 1 x 1 texture)
_FT["foreground_mask"] = "pw.w >= 0.5"
_FT["depth_over_mean"] = "-pw.z / nao_load(src1, ${ivec2}(0, 0), 0).x"
# version 3: log depth, frame-local; a foreground pixel at depth 0 has no logarithm: background
_FT["foreground_positive"] = "pw.w >= 0.5 && -pw.z > 0.0"
_FT["log_depth"] = "log(-pw.z)"
_FT["network_input_gtao"] = """
    ${var_float:g} = 1.0;
    if (pw.w >= 0.5) {
        g = nao_load(src0, px, 2).x;
    }
    nao_store(px, 1, ${vec4}(g, 0.0, 0.0, 0.0));"""
# version 4: layer 1 = (thickness, GTAO or 0, 0, 0): the thickness clamp(log(back / depth), 0, cap) where
# the back layer lies behind a foreground pixel, else 0
_FT["network_input_back"] = """
    ${var_float:t} = 0.0;
    ${var_float:g} = ${gtao_empty};
    if (pw.w >= 0.5) {
        ${let_float} back = nao_load(src0, px, 1).w;
        if (-pw.z > 0.0 && back > -pw.z) {
            t = clamp(log(back / -pw.z), 0.0, ${cap});
        }${gtao_load}
    }
    nao_store(px, 1, ${vec4}(t, g, 0.0, 0.0));"""
_FT["network_input_back_gtao"] = """
        g = nao_load(src0, px, 2).x;"""
# A hybrid that also reads GTAO before its blur (layer 2's y): layer 1 = (GTAO before its blur, GTAO, 0, 0),
# and with the back layer (thickness, GTAO before its blur, GTAO, 0); 1 on background for both.
_FT["network_input_gtao_raw"] = """
    ${var_float:g} = 1.0;
    ${var_float:r} = 1.0;
    if (pw.w >= 0.5) {
        g = nao_load(src0, px, 2).x;
        r = nao_load(src0, px, 2).y;
    }
    nao_store(px, 1, ${vec4}(r, g, 0.0, 0.0));"""
_FT["network_input_back_raw"] = """
    ${var_float:t} = 0.0;
    ${var_float:g} = 1.0;
    ${var_float:r} = 1.0;
    if (pw.w >= 0.5) {
        ${let_float} back = nao_load(src0, px, 1).w;
        if (-pw.z > 0.0 && back > -pw.z) {
            t = clamp(log(back / -pw.z), 0.0, ${cap});
        }
        g = nao_load(src0, px, 2).x;
        r = nao_load(src0, px, 2).y;
    }
    nao_store(px, 1, ${vec4}(t, r, g, 0.0));"""

# The network's radius input rho, into the texture its uniform pass would write (1 x 1, lane 0).
_FT["network_radius_body"] = """    nao_store(px, 0, ${vec4}(${rho}, 0.0, 0.0, 0.0));"""
# version 2: R / (m tan(yfov / 2)) = R P11 / m, m the mean foreground depth (src0: depth_mean's texture)
_FT["rho_over_mean"] = "${u_radius} * ${u_proj}.y / nao_load(src0, ${ivec2}(0, 0), 0).x"
# version 3: log(R / tan(yfov / 2)) = log(R P11)
_FT["rho_log"] = "log(${u_radius} * ${u_proj}.y)"

# Joint bilateral upsampling of the network's AO (a hybrid: its correction to GTAO, the network's AO minus
# the point-sampled GTAO) to the frame: the 4 x 4 nearest low texels, each weighted by a Gaussian of its
# distance in low texels, by how close this pixel lies to the texel's tangent plane (relative to depth)
# and by how well the normals agree; background texels get no weight, a small floor keeps the nearest
# foreground texels in charge where no texel matches. src0: the depth, src1: the normal, src2: the
# network's output, src3: the point-sampled G-buffer (a hybrid's layer 2: GTAO point-sampled), a hybrid's
# src4: GTAO.
#
# The workgroup's pixels share their low texels: while the network is smaller than the frame, the 4 x 4
# taps of an 8 x 8 tile of pixels span at most 12 x 12 low texels, loaded once into workgroup memory
# (position and foreground flag; normal and the value upsampled) instead of 16 x 3-4 fetches a pixel.
# A frame smaller than the network (a wider span) reads its taps directly; the arithmetic is the same.
_FT["upsample_load"] = """    ${let_ivec2} hi = out_size;
    ${let_ivec2} lo = nao_size(src2);
    // the workgroup's first and last pixels in GL order (nao_texel flips rows where row 0 is the top)
    ${let_ivec2} c0 = nao_texel(min(group0, out_size - 1), out_size);
    ${let_ivec2} c1 = nao_texel(min(group0 + ${ivec2}(${last_x}, ${last_y}), out_size - 1), out_size);
    ${let_ivec2} t0 = nao_up_base(min(c0, c1), lo, hi);
    ${let_ivec2} t_size = nao_up_base(max(c0, c1), lo, hi) + 4 - t0;
    ${let_bool} tiled = t_size.x <= ${tile} && t_size.y <= ${tile};
    if (tiled) {
        for (${var_int:k} = lid; k < t_size.x * t_size.y; k = k + ${threads}) {
            ${let_ivec2} q = clamp(t0 + ${ivec2}(k % t_size.x, k / t_size.x), ${ivec2}(0), lo - 1);
            nao_tile_a[k] = nao_load(src3, q, 0);
            nao_tile_b[k] = ${vec4}(nao_load(src3, q, 1).xyz, ${low_value});
        }
    }"""
_FG["upsample_shared"] = """shared vec4 nao_tile_a[${entries}];  // the low texels' position, foreground flag
shared vec4 nao_tile_b[${entries}];  // their normal and the value upsampled"""
_FW["upsample_shared"] = """// the low texels' position and foreground flag; their normal and value upsampled
var<workgroup> nao_tile_a: array<vec4<f32>, ${entries}>;
var<workgroup> nao_tile_b: array<vec4<f32>, ${entries}>;"""
# the 4 x 4 taps' first low texel of GL-order pixel p (lo: the network's size, hi: the frame's)
_FG["upsample_functions"] = """ivec2 nao_up_base(ivec2 p, ivec2 lo, ivec2 hi) {
    ivec2 num = (2 * p + 1) * lo - hi;
    return ivec2(nao_floor_div(num.x, 2 * hi.x), nao_floor_div(num.y, 2 * hi.y)) - 1;
}
"""
_FW["upsample_functions"] = """fn nao_up_base(p: vec2<i32>, lo: vec2<i32>, hi: vec2<i32>) -> vec2<i32> {
    let num = (2 * p + 1) * lo - hi;
    return vec2<i32>(nao_floor_div(num.x, 2 * hi.x), nao_floor_div(num.y, 2 * hi.y)) - 1;
}
"""
_FT["upsample_body"] = """    ${let_float} z = nao_load(src0, px, 0).x;
    if (!(z > 0.0)) {
        nao_store(px, 0, ${vec4}(1.0));
        return;
    }
    ${let_vec3} p = nao_position(px, out_size, z);
    ${let_vec3} n = nao_load(src1, px, 0).xyz;
    ${let_float} depth = max(z, 1e-30);
    ${let_vec2} uv = (${vec2}(px) + 0.5) * ${vec2}(lo) / ${vec2}(hi) - 0.5;
    ${let_ivec2} base = nao_up_base(px, lo, hi);
    ${var_float:sum} = 0.0;
    ${var_float:total} = 0.0;
    for (${var_int:y} = 0; y < 4; ${inc:y}) {
        for (${var_int:x} = 0; x < 4; ${inc:x}) {
            ${let_ivec2} o = base + ${ivec2}(x, y);
            ${var_vec4:qw} = ${vec4}(0.0);
            ${var_vec4:qv} = ${vec4}(0.0);
            if (tiled) {
                ${let_int} k = (o.y - t0.y) * t_size.x + (o.x - t0.x);
                qw = nao_tile_a[k];
                qv = nao_tile_b[k];
            } else {
                ${let_ivec2} q = clamp(o, ${ivec2}(0), lo - 1);
                qw = nao_load(src3, q, 0);
                qv = ${vec4}(nao_load(src3, q, 1).xyz, ${low_value});
            }
            if (qw.w < 0.5) {
                continue;
            }
            ${let_vec2} d = ${vec2}(o) - uv;
            ${let_float} spatial = exp(-dot(d, d) / (2.0 * ${spatial_sigma} * ${spatial_sigma}));
            ${let_vec3} qn = qv.xyz;
            ${let_float} plane = abs(dot(qn, p - qw.xyz)) / (${plane_sigma} * depth);
            ${let_float} agree = pow(max(dot(qn, n), 0.0), ${normal_power});
            ${let_float} w = spatial * (${floor} + exp(-plane * plane) * agree);
            sum += w * qv.w;
            total += w;
        }
    }
    ${var_float:up} = ${empty};
    if (total > 0.0) {
        up = sum / total;
    }
    nao_store(px, 0, ${vec4}(${result}));"""
_FT["low_ao"] = "nao_load(src2, q, 0).x"
_FT["low_correction"] = "(nao_load(src2, q, 0).x - nao_load(src3, q, 2).x)"
_FT["result_ao"] = "up"
_FT["result_combined"] = "clamp(nao_load(src4, px, 0).x + up, 0.0, 1.0)"

# The network at the frame's own size: its output where foreground, 1 on background. src0: the depth,
# src1: the network's output.
_FT["composite_body"] = """    if (!(nao_load(src0, px, 0).x > 0.0)) {
        nao_store(px, 0, ${vec4}(1.0));
        return;
    }
    nao_store(px, 0, ${vec4}(nao_load(src1, px, 0).x));"""


# --------------------------------------------------------------------------- filling

TEMPLATES: dict[str, Template] = _with_words({**_FT, **_FG}, {**_WORDS, **_FRAME_WORDS})
VULKAN_TEMPLATES: dict[str, Template] = _with_words({**_FT, **_FG, **_FV}, {**_WORDS, **_FRAME_WORDS})
WGSL_TEMPLATES: dict[str, Template] = _with_words(
    {**_FT, **_FW}, {**_WORDS, **_WGSL_WORDS, **_FRAME_WGSL_WORDS}
)


def fill(template: str, /, **fields: object) -> str:
    """Fill the GLSL 4.30 frame template named ``template`` (strict: every field, nothing else)."""
    return fill_from(TEMPLATES, template, "frame GLSL", **fields)


def fill_vulkan(template: str, /, **fields: object) -> str:
    """Fill the Vulkan GLSL frame template named ``template`` (strict)."""
    return fill_from(VULKAN_TEMPLATES, template, "frame Vulkan GLSL", **fields)


def fill_wgsl(template: str, /, **fields: object) -> str:
    """Fill the WGSL frame template named ``template`` (strict)."""
    return fill_from(WGSL_TEMPLATES, template, "frame WGSL", **fields)


FILLS = {"glsl430": fill, "vulkan": fill_vulkan, "wgsl": fill_wgsl}
