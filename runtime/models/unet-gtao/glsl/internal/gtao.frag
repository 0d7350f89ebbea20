#version 430 core
// neuralao baseline: GTAO (Jimenez et al. 2016), 4 slices x 8 steps per side.
uniform vec2 u_proj;                 // (P00, P11) of the projection matrix
uniform float u_radius;              // world-space radius (scene units)
uniform float u_falloff;             // fraction of the radius over which occluder weight fades to 0
uniform float u_pixels_per_unit;     // pixels spanned by 1 scene unit at depth 1: 0.5 * H * P11
layout(binding = 0) uniform sampler2D u_position;  // xyz camera-space position, w mask
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
}

const float PI = 3.14159265358979;
const float HALF_PI = 1.57079632679490;

float acos_safe(float x) { return acos(clamp(x, -1.0, 1.0)); }

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    ivec2 size = textureSize(u_position, 0);
    vec4 pw = texelFetch(u_position, px, 0);
    if (pw.w < 0.5) { o_ao = 1.0; return; }
    vec3 p = pw.xyz;
    vec3 n = texelFetch(u_normal, px, 0).xyz;
    float ln = length(n);
    n = ln > 1e-20 ? n / ln : vec3(0.0, 0.0, 1.0);
    vec3 view_v = normalize(-p);
    float radius_px = u_radius * u_pixels_per_unit / max(-p.z, 1e-30);
    if (!(radius_px > 1.0)) { o_ao = 1.0; return; }   // the radius stays inside this pixel
    vec2 noise = texelFetch(u_noise, px % 4, 0).xy;
    float falloff_range = max(u_falloff, 1e-6) * u_radius;
    float falloff_mul = -1.0 / falloff_range;
    float falloff_add = (u_radius - falloff_range) / falloff_range + 1.0;
    float min_s = 1.3 / radius_px;                    // skip samples within ~1 pixel (self)
    vec2 centre = vec2(px) + 0.5;
    float visibility = 0.0;
    for (int slice = 0; slice < 4; ++slice) {
        float phi = (float(slice) + noise.x) * (PI / float(4));
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
        for (int k = 0; k < 8; ++k) {
            float s = (float(k) + noise.y) / float(8);
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
                        float w = clamp(dist * falloff_mul + falloff_add, 0.0, 1.0);
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
                        float w = clamp(dist * falloff_mul + falloff_add, 0.0, 1.0);
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
    o_ao = clamp(visibility / float(4), 0.0, 1.0);
}
