#version 450
#extension GL_EXT_samplerless_texture_functions : require
// neuralao frame pass f_gtao: GTAO, 4 slices x 8 steps per side
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(set = 0, binding = 0) uniform highp texture2DArray src0;
layout(set = 0, binding = 1, r32f) writeonly uniform highp image2DArray dst;
layout(std140, set = 0, binding = 2) uniform FrameUniforms {
    vec2 u_proj;               // (P00, P11) of the projection matrix
    float u_radius;            // R, the AO radius in scene units
    float u_pixels_per_unit;   // 0.5 * H * P11: pixels spanned by one scene unit at depth 1
    int u_flip_y;              // 1: textures bottom-up (GL), 0: row 0 at the top
};

// GL-order pixel (row 0 at the bottom) <-> texel of a texture of this frame (its own row order).
ivec2 nao_texel(ivec2 p, ivec2 size) {
    return u_flip_y != 0 ? p : ivec2(p.x, size.y - 1 - p.y);
}

ivec2 nao_size(highp texture2DArray t) {
    return textureSize(t, 0).xy;
}

vec4 nao_load(highp texture2DArray t, ivec2 p, int layer) {
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

// floor(a / b) for b > 0 (GLSL's int division truncates toward 0)
int nao_floor_div(int a, int b) {
    return a >= 0 ? a / b : -((-a + b - 1) / b);
}

const vec2 NAO_NOISE[16] = vec2[16](
    vec2(0.37785703, 0.16784167),
    vec2(0.96874505, 0.7069943),
    vec2(0.08153783, 0.59926146),
    vec2(0.006564423, 0.5217559),
    vec2(0.8607627, 0.29334372),
    vec2(0.8040162, 0.83652043),
    vec2(0.35370275, 0.9306502),
    vec2(0.7323331, 0.74723846),
    vec2(0.6540574, 0.18946956),
    vec2(0.1374434, 0.5179998),
    vec2(0.49568525, 0.86254483),
    vec2(0.5246121, 0.8962807),
    vec2(0.9308748, 0.19567448),
    vec2(0.2630413, 0.04882246),
    vec2(0.20385185, 0.999012),
    vec2(0.58506614, 0.2510019));

vec2 nao_noise(ivec2 p) {
    return NAO_NOISE[(p.y % 4) * 4 + p.x % 4];
}

void main() {
    ivec2 gid = ivec2(gl_GlobalInvocationID.xy);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y) {
        return;
    }
    ivec2 px = nao_texel(gid, out_size);  // this invocation's pixel, GL order
    vec4 pw = nao_load(src0, px, 0);
    if (pw.w < 0.5) {
        nao_store(px, 0, vec4(1.0));
        return;
    }
    vec3 p = pw.xyz;
    vec3 n = nao_load(src0, px, 1).xyz;
    float ln = length(n);
    if (ln > 1e-20) {
        n = n / ln;
    } else {
        n = vec3(0.0, 0.0, 1.0);
    }
    vec3 view_v = normalize(-p);
    float radius_px = u_radius * u_pixels_per_unit / max(-p.z, 1e-30);
    if (!(radius_px > 1.0)) {
        nao_store(px, 0, vec4(1.0));  // the radius stays inside this pixel
        return;
    }
    vec2 noise = nao_noise(px);
    float falloff_range = max(0.2, 1e-6) * u_radius;
    float falloff_mul = -1.0 / falloff_range;
    float falloff_add = (u_radius - falloff_range) / falloff_range + 1.0;
    float min_s = 1.3 / radius_px;  // skip samples within ~1 pixel (self)
    vec2 centre = vec2(px) + 0.5;
    float visibility = 0.0;
    for (int slice = 0; slice < 4; ++slice) {
        float phi = (float(slice) + noise.x) * (3.14159265358979 / float(4));
        vec2 omega = vec2(cos(phi), sin(phi));  // screen direction = camera-space (x, y)
        vec3 dir_v = vec3(omega, 0.0);
        vec3 ortho_v = dir_v - dot(dir_v, view_v) * view_v;
        vec3 axis_v = normalize(cross(dir_v, view_v));
        vec3 proj_n = n - axis_v * dot(n, axis_v);
        float proj_len = length(proj_n);
        float sign_n = -1.0;
        if (dot(ortho_v, proj_n) >= 0.0) {
            sign_n = 1.0;
        }
        float cos_n = clamp(dot(proj_n, view_v) / max(proj_len, 1e-20), 0.0, 1.0);
        float ang_n = sign_n * nao_acos(cos_n);
        float low0 = cos(ang_n + 1.57079632679490);
        float low1 = cos(ang_n - 1.57079632679490);
        float hc0 = low0;
        float hc1 = low1;
        for (int k = 0; k < 8; ++k) {
            float s = (float(k) + noise.y) / float(8);
            s = min_s + (1.0 - min_s) * s * s;
            vec2 off = omega * (s * radius_px);
            ivec2 q0 = ivec2(floor(centre + off));
            ivec2 q1 = ivec2(floor(centre - off));
            if (nao_inside(q0, out_size)) {
                vec4 sw = nao_load(src0, q0, 0);
                if (sw.w >= 0.5) {
                    vec3 d = sw.xyz - p;
                    float dist = length(d);
                    if (dist > 1e-30) {
                        float w = clamp(dist * falloff_mul + falloff_add, 0.0, 1.0);
                        hc0 = max(hc0, mix(low0, dot(d / dist, view_v), w));
                    }
                }
            }
            if (nao_inside(q1, out_size)) {
                vec4 sw = nao_load(src0, q1, 0);
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
        float h0 = -nao_acos(hc1);
        float h1 = nao_acos(hc0);
        h0 = ang_n + clamp(h0 - ang_n, -1.57079632679490, 1.57079632679490);
        h1 = ang_n + clamp(h1 - ang_n, -1.57079632679490, 1.57079632679490);
        float sin_n = sin(ang_n);
        float arc0 = (cos_n + 2.0 * h0 * sin_n - cos(2.0 * h0 - ang_n)) * 0.25;
        float arc1 = (cos_n + 2.0 * h1 * sin_n - cos(2.0 * h1 - ang_n)) * 0.25;
        visibility += proj_len * (arc0 + arc1);
    }
    nao_store(px, 0, vec4(clamp(visibility / float(4), 0.0, 1.0)));
}
