"""GLSL text of the screen-space AO baselines (SSAO, GTAO, the shared blur), as named templates.

Same habit as :mod:`neuralao.export.glsl.templates`: every shader string lives here, :func:`fill` substitutes
``${name}`` fields strictly (a missing or unexpected field is an error), and
:mod:`neuralao.runtime.baselines` is the one writer. Values substituted are integers and float literals.

G-buffer textures every pass reads (RGBA32F, nearest, fetched with ``texelFetch``; GL row 0 at the
bottom, so ``gl_FragCoord`` y and camera-space y both point up):

* ``u_position``: xyz camera-space position (OpenGL camera: -z forward), w = 1 on foreground, 0 on
  background;
* ``u_normal``: xyz camera-space unit normal facing the viewer;
* ``u_noise``: the ``noise_size`` x ``noise_size`` tile of per-pixel random values, repeated over the
  screen (``pixel % noise_size``).

Every pass writes one float to ``o_ao`` (R32F target): accessibility, 1 on background.
"""

from __future__ import annotations

from string import Template

from neuralao.export.glsl.templates import fill_from

_T: dict[str, str] = {}

_T["fullscreen_vertex"] = """#version 430 core
// Full-screen triangle from gl_VertexID; draw 3 vertices with an empty VAO.
void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

_T[
    "gbuffer_inputs"
] = """layout(binding = 0) uniform sampler2D u_position;  // xyz camera-space position, w mask
layout(binding = 1) uniform sampler2D u_normal;    // xyz camera-space unit normal
layout(binding = 2) uniform sampler2D u_noise;     // per-pixel random values, tiled
layout(location = 0) out float o_ao;

// Camera-space point -> pixel (GL order, row 0 at the bottom); u_proj = (P00, P11).
ivec2 to_pixel(vec3 s, ivec2 size) {
    vec2 ndc = u_proj * s.xy / (-s.z);
    return ivec2(floor((ndc * 0.5 + 0.5) * vec2(size)));
}

bool inside(ivec2 q, ivec2 size) {
    return all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size));
}"""

# Crytek-style SSAO (Mittring 2007) in its normal-oriented hemisphere form (Chapman 2013): kernel
# points in the unit hemisphere around +z, rotated per pixel by a random tangent from the noise
# tile (Gram-Schmidt), scaled by the world radius; a kernel point counts as occluded when the
# G-buffer surface seen at its pixel lies in front of it by more than the bias, faded by a range
# check so far-away foreground does not darken silhouettes.
# Both screen-space methods start the same way: this pixel's camera-space position and unit normal
# (background -> ao 1; a zero-length or NaN normal falls back to +z, facing the camera).
_T["surface_at_pixel"] = """    ivec2 px = ivec2(gl_FragCoord.xy);
    ivec2 size = textureSize(u_position, 0);
    vec4 pw = texelFetch(u_position, px, 0);
    if (pw.w < 0.5) { o_ao = 1.0; return; }
    vec3 p = pw.xyz;
    vec3 n = texelFetch(u_normal, px, 0).xyz;
    float ln = length(n);
    n = ln > 1e-20 ? n / ln : vec3(0.0, 0.0, 1.0);"""

_T["ssao_fragment"] = """#version 430 core
// neuralao baseline: normal-oriented hemisphere SSAO (Crytek style), ${samples} kernel samples.
uniform vec2 u_proj;                 // (P00, P11) of the projection matrix
uniform float u_radius;              // world-space kernel radius (scene units)
uniform float u_bias;                // depth bias (scene units)
uniform vec3 u_kernel[${samples}];   // hemisphere kernel, |k| <= 1, k.z > 0
${inputs}

void main() {
${surface}
    vec3 r = texelFetch(u_noise, px % ${noise_size}, 0).xyz;
    vec3 t = r - n * dot(r, n);
    // A noise vector (nearly) parallel to the normal leaves no tangent: pick any perpendicular.
    if (dot(t, t) < 1e-8) t = abs(n.x) < 0.9 ? cross(n, vec3(1.0, 0.0, 0.0)) : cross(n, vec3(0.0, 1.0, 0.0));
    t = normalize(t);
    mat3 tbn = mat3(t, cross(n, t), n);
    float occlusion = 0.0;
    for (int i = 0; i < ${samples}; ++i) {
        vec3 s = p + tbn * (u_kernel[i] * u_radius);
        if (s.z >= -1e-20) continue;         // behind the camera: nothing can cover it
        ivec2 q = to_pixel(s, size);
        if (!inside(q, size)) continue;      // off screen: unknown, counted open
        vec4 sw = texelFetch(u_position, q, 0);
        if (sw.w < 0.5) continue;            // background: open
        float range = smoothstep(0.0, 1.0, u_radius / max(abs(p.z - sw.z), 1e-30));
        occlusion += (sw.z >= s.z + u_bias ? 1.0 : 0.0) * range;
    }
    o_ao = 1.0 - occlusion / float(${samples});
}
"""

# Ground-truth-based AO (Jimenez et al. 2016), structured as Intel's XeGTAO: per pixel ${slices}
# slice directions (rotated by the noise tile), ${steps} horizon samples per side along each slice
# up to the projected radius (quadratic spacing, jittered), horizons faded over the last
# ``falloff`` fraction of the radius, and the cosine-weighted visibility integrated analytically
# between the two horizons and the normal's hemisphere within the slice (projected normal).
_T["gtao_fragment"] = """#version 430 core
// neuralao baseline: GTAO (Jimenez et al. 2016), ${slices} slices x ${steps} steps per side.
uniform vec2 u_proj;                 // (P00, P11) of the projection matrix
uniform float u_radius;              // world-space radius (scene units)
uniform float u_falloff;             // fraction of the radius over which occluder weight fades to 0
uniform float u_pixels_per_unit;     // pixels spanned by 1 scene unit at depth 1: 0.5 * H * P11
${inputs}

const float PI = 3.14159265358979;
const float HALF_PI = 1.57079632679490;

float acos_safe(float x) { return acos(clamp(x, -1.0, 1.0)); }

void main() {
${surface}
    vec3 view_v = normalize(-p);
    float radius_px = u_radius * u_pixels_per_unit / max(-p.z, 1e-30);
    if (!(radius_px > 1.0)) { o_ao = 1.0; return; }   // the radius stays inside this pixel
    vec2 noise = texelFetch(u_noise, px % ${noise_size}, 0).xy;
    float falloff_range = max(u_falloff, 1e-6) * u_radius;
    float falloff_mul = -1.0 / falloff_range;
    float falloff_add = (u_radius - falloff_range) / falloff_range + 1.0;
    float min_s = 1.3 / radius_px;                    // skip samples within ~1 pixel (self)
    vec2 centre = vec2(px) + 0.5;
    float visibility = 0.0;
    for (int slice = 0; slice < ${slices}; ++slice) {
        float phi = (float(slice) + noise.x) * (PI / float(${slices}));
        vec2 omega = vec2(cos(phi), sin(phi));          // screen direction = camera-space (x, y)
        vec3 dir_v = vec3(omega, 0.0);
        vec3 ortho_v = dir_v - dot(dir_v, view_v) * view_v;
        vec3 axis_v = normalize(cross(dir_v, view_v));
        vec3 proj_n = n - axis_v * dot(n, axis_v);
        float proj_len = length(proj_n);
        float sign_n = dot(ortho_v, proj_n) >= 0.0 ? 1.0 : -1.0;
        float cos_n = clamp(dot(proj_n, view_v) / max(proj_len, 1e-20), 0.0, 1.0);
        float ang_n = sign_n * acos_safe(cos_n);
        float low0 = cos(ang_n + HALF_PI);
        float low1 = cos(ang_n - HALF_PI);
        float hc0 = low0;
        float hc1 = low1;
        for (int k = 0; k < ${steps}; ++k) {
            float s = (float(k) + noise.y) / float(${steps});
            s = min_s + (1.0 - min_s) * s * s;
            vec2 off = omega * (s * radius_px);
            ivec2 q0 = ivec2(floor(centre + off));
            ivec2 q1 = ivec2(floor(centre - off));
            if (inside(q0, size)) {
                vec4 sw = texelFetch(u_position, q0, 0);
                if (sw.w >= 0.5) {
                    vec3 d = sw.xyz - p;
                    float dist = length(d);
                    if (dist > 1e-30) {
                        float w = clamp(dist * falloff_mul + falloff_add, 0.0, 1.0);${thin0}
                        hc0 = max(hc0, mix(low0, dot(d / dist, view_v), w));
                    }
                }
            }
            if (inside(q1, size)) {
                vec4 sw = texelFetch(u_position, q1, 0);
                if (sw.w >= 0.5) {
                    vec3 d = sw.xyz - p;
                    float dist = length(d);
                    if (dist > 1e-30) {
                        float w = clamp(dist * falloff_mul + falloff_add, 0.0, 1.0);${thin1}
                        hc1 = max(hc1, mix(low1, dot(d / dist, view_v), w));
                    }
                }
            }
        }
        float h0 = -acos_safe(hc1);
        float h1 = acos_safe(hc0);
        h0 = ang_n + clamp(h0 - ang_n, -HALF_PI, HALF_PI);
        h1 = ang_n + clamp(h1 - ang_n, -HALF_PI, HALF_PI);
        float sin_n = sin(ang_n);
        float arc0 = (cos_n + 2.0 * h0 * sin_n - cos(2.0 * h0 - ang_n)) * 0.25;
        float arc1 = (cos_n + 2.0 * h1 * sin_n - cos(2.0 * h1 - ang_n)) * 0.25;
        visibility += proj_len * (arc0 + arc1);
    }
    o_ao = clamp(visibility / float(${slices}), 0.0, 1.0);
}
"""

# Mask-aware box blur over the noise tile (window = tile size, offsets -n/2 .. n/2-1 as in
# Chapman's SSAO blur): averages foreground pixels only, so the background's 1 never bleeds in.
_T["blur_fragment"] = """#version 430 core
// neuralao baseline: ${size}x${size} foreground-only box blur of a raw AO image.
layout(binding = 0) uniform sampler2D u_position;  // w = foreground mask
layout(binding = 3) uniform sampler2D u_raw;       // raw AO
layout(location = 0) out float o_ao;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    ivec2 size = textureSize(u_raw, 0);
    if (texelFetch(u_position, px, 0).w < 0.5) { o_ao = 1.0; return; }
    float sum = 0.0;
    float count = 0.0;
    for (int y = -${half}; y < ${size} - ${half}; ++y) {
        for (int x = -${half}; x < ${size} - ${half}; ++x) {
            ivec2 q = px + ivec2(x, y);
            if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
            if (texelFetch(u_position, q, 0).w < 0.5) continue;
            sum += texelFetch(u_raw, q, 0).r;
            count += 1.0;
        }
    }
    o_ao = sum / max(count, 1.0);
}
"""

# Depth- and normal-aware (joint bilateral) upsampling of AO computed at a reduced internal
# resolution: the high-resolution pixel blends the 4 x 4 nearest low-resolution texels, each weighted
# by a Gaussian of its distance in low-resolution texels, by how close the pixel's point lies to the
# texel's tangent plane (relative to depth) and by how well the normals agree; background texels get
# no weight. A small floor keeps the spatially nearest foreground texels in charge where no texel
# matches (thin parts the low resolution missed). No foreground texel in reach -> ${empty} (1.0, open,
# for AO; 0.0 for a hybrid's correction to GTAO, which then keeps GTAO).
# Low-resolution texels are point samples of the high-resolution G-buffer: texel t of a low axis of
# n texels is high pixel floor((t + 0.5) * N / n), so its position is that pixel's exact position.
_T["upsample_fragment"] = """#version 430 core
// neuralao: joint bilateral upsampling of low-resolution AO to the G-buffer's resolution.
layout(binding = 0) uniform sampler2D u_position;      // high res: xyz camera-space position, w mask
layout(binding = 1) uniform sampler2D u_normal;        // high res: xyz camera-space unit normal
layout(binding = 4) uniform sampler2D u_low_ao;        // low res: AO
layout(binding = 5) uniform sampler2D u_low_position;  // low res: point-sampled u_position
layout(binding = 6) uniform sampler2D u_low_normal;    // low res: point-sampled u_normal
layout(location = 0) out float o_ao;

const float SPATIAL_SIGMA = ${spatial_sigma};  // low-resolution texels
const float PLANE_SIGMA = ${plane_sigma};      // tangent-plane distance / depth
const float NORMAL_POWER = ${normal_power};
const float FLOOR = ${floor};

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 pw = texelFetch(u_position, px, 0);
    if (pw.w < 0.5) { o_ao = 1.0; return; }
    vec3 n = texelFetch(u_normal, px, 0).xyz;
    float depth = max(-pw.z, 1e-30);
    ivec2 hi = textureSize(u_position, 0);
    ivec2 lo = textureSize(u_low_ao, 0);
    vec2 uv = (vec2(px) + 0.5) * vec2(lo) / vec2(hi) - 0.5;
    // floor(uv) in integers (exact where uv is a whole number; int division truncates toward 0)
    ivec2 num = (2 * px + 1) * lo - hi;
    ivec2 fl = ivec2(num.x >= 0 ? num.x / (2 * hi.x) : -((-num.x + 2 * hi.x - 1) / (2 * hi.x)),
                     num.y >= 0 ? num.y / (2 * hi.y) : -((-num.y + 2 * hi.y - 1) / (2 * hi.y)));
    ivec2 base = fl - 1;
    float sum = 0.0;
    float total = 0.0;
    for (int y = 0; y < 4; ++y) {
        for (int x = 0; x < 4; ++x) {
            ivec2 q = clamp(base + ivec2(x, y), ivec2(0), lo - 1);
            vec4 qw = texelFetch(u_low_position, q, 0);
            if (qw.w < 0.5) continue;
            vec2 d = vec2(base + ivec2(x, y)) - uv;
            float spatial = exp(-dot(d, d) / (2.0 * SPATIAL_SIGMA * SPATIAL_SIGMA));
            vec3 qn = texelFetch(u_low_normal, q, 0).xyz;
            float plane = abs(dot(qn, pw.xyz - qw.xyz)) / (PLANE_SIGMA * depth);
            float agree = pow(max(dot(qn, n), 0.0), NORMAL_POWER);
            float w = spatial * (FLOOR + exp(-plane * plane) * agree);
            sum += w * texelFetch(u_low_ao, q, 0).r;
            total += w;
        }
    }
    o_ao = total > 0.0 ? sum / total : ${empty};
}
"""

# The G-buffer at the internal resolution: each low texel copies one high pixel (point sampling,
# never a blend across an edge), the pixel floor((t + 0.5) * N / n) per axis, as the upsampling
# pass and neuralao.runtime.internal_resolution.downsample_frame assume.
_T["downsample_fragment"] = """#version 430 core
// neuralao: point-sampled G-buffer at the internal resolution (two targets: position, normal).
layout(binding = 0) uniform sampler2D u_position;  // high res: xyz camera-space position, w mask
layout(binding = 1) uniform sampler2D u_normal;    // high res: xyz camera-space unit normal
uniform ivec2 u_low_size;                          // the internal resolution (this pass's target)
layout(location = 0) out vec4 o_position;
layout(location = 1) out vec4 o_normal;

void main() {
    ivec2 t = ivec2(gl_FragCoord.xy);
    ivec2 hi = textureSize(u_position, 0);
    ivec2 lo = u_low_size;
    ivec2 q = min(((2 * t + 1) * hi) / (2 * lo), hi - 1);  // floor((t + 0.5) * hi / lo), exactly
    o_position = texelFetch(u_position, q, 0);
    o_normal = texelFetch(u_normal, q, 0);
}
"""

TEMPLATES: dict[str, Template] = {name: Template(text) for name, text in _T.items()}


def fill(template: str, /, **fields: object) -> str:
    """Fill the baseline template named ``template``; every placeholder must be given and nothing else."""
    return fill_from(TEMPLATES, template, "baseline GLSL", **fields)
