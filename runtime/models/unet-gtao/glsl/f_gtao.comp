#version 430 core
// neuralao frame pass f_gtao: GTAO, 4 slices x 8 steps per side
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(binding = 0) uniform highp sampler2DArray src0;
layout(binding = 1) uniform highp sampler2DArray src1;
layout(binding = 2, r32f) writeonly uniform highp image2DArray dst;
layout(std140, binding = 3) uniform FrameUniforms {
    vec2 u_proj;               // (P00, P11) of the projection matrix
    float u_radius;            // R, the AO radius in scene units
    float u_pixels_per_unit;   // 0.5 * H * P11: pixels spanned by one scene unit at depth 1
    int u_flip_y;              // 1: textures bottom-up (GL), 0: row 0 at the top
};

// GL-order pixel (row 0 at the bottom) <-> texel of a texture of this frame (its own row order).
ivec2 nao_texel(ivec2 p, ivec2 size) {
    return u_flip_y != 0 ? p : ivec2(p.x, size.y - 1 - p.y);
}

ivec2 nao_size(highp sampler2DArray t) {
    return textureSize(t, 0).xy;
}

vec4 nao_load(highp sampler2DArray t, ivec2 p, int layer) {
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

const vec2 NAO_DIRECTIONS[64] = vec2[64](
    vec2(0.95628655, 0.29243124),
    vec2(0.46941665, 0.8829768),
    vec2((-0.29243124), 0.95628655),
    vec2((-0.88297683), 0.46941662),
    vec2(0.7242497, 0.68953776),
    vec2(0.024545068, 0.9996987),
    vec2((-0.68953776), 0.7242498),
    vec2((-0.9996987), 0.024545025),
    vec2(0.99795014, 0.0639959),
    vec2(0.6604054, 0.75090927),
    vec2((-0.06399587), 0.99795014),
    vec2((-0.75090927), 0.66040534),
    vec2(0.9999867, 0.005155663),
    vec2(0.7034518, 0.71074295),
    vec2((-0.0051557035), 0.9999867),
    vec2((-0.71074307), 0.7034517),
    vec2(0.7800557, 0.62571007),
    vec2(0.10913888, 0.9940265),
    vec2((-0.6257101), 0.7800557),
    vec2((-0.9940265), 0.10913896),
    vec2(0.80715895, 0.5903342),
    vec2(0.15331827, 0.9881769),
    vec2((-0.5903341), 0.80715895),
    vec2((-0.9881769), 0.15331823),
    vec2(0.96166176, 0.27423826),
    vec2(0.4860818, 0.8739133),
    vec2((-0.27423838), 0.96166176),
    vec2((-0.8739134), 0.48608166),
    vec2(0.83909816, 0.54398),
    vec2(0.2086799, 0.977984),
    vec2((-0.54398024), 0.83909804),
    vec2((-0.977984), 0.20867997),
    vec2(0.8709345, 0.4913991),
    vec2(0.26837197, 0.96331537),
    vec2((-0.49139926), 0.8709344),
    vec2((-0.9633154), 0.26837182),
    vec2(0.9941793, 0.107738264),
    vec2(0.6268084, 0.77917343),
    vec2((-0.10773823), 0.9941793),
    vec2((-0.7791734), 0.6268084),
    vec2(0.9251711, 0.37955043),
    vec2(0.38581204, 0.9225774),
    vec2((-0.37955052), 0.925171),
    vec2((-0.92257744), 0.38581198),
    vec2(0.91631, 0.40046972),
    vec2(0.3647541, 0.9311039),
    vec2((-0.40046984), 0.91630995),
    vec2((-0.9311039), 0.36475405),
    vec2(0.7444354, 0.66769445),
    vec2(0.05426406, 0.99852663),
    vec2((-0.66769445), 0.7444354),
    vec2((-0.99852663), 0.054264016),
    vec2(0.9787356, 0.2051257),
    vec2(0.5470248, 0.8371164),
    vec2((-0.20512569), 0.9787356),
    vec2((-0.83711636), 0.54702485),
    vec2(0.9872106, 0.15942174),
    vec2(0.5853351, 0.8107915),
    vec2((-0.15942189), 0.9872106),
    vec2((-0.81079155), 0.585335),
    vec2(0.89627, 0.4435089),
    vec2(0.3201505, 0.9473667),
    vec2((-0.44350877), 0.89627004),
    vec2((-0.9473667), 0.32015046));
const float NAO_JITTER[16] = float[16](
    0.16784167,
    0.7069943,
    0.59926146,
    0.5217559,
    0.29334372,
    0.83652043,
    0.9306502,
    0.74723846,
    0.18946956,
    0.5179998,
    0.86254483,
    0.8962807,
    0.19567448,
    0.04882246,
    0.999012,
    0.2510019);

int nao_tile(ivec2 p) {
    return (p.y % 4) * 4 + p.x % 4;
}

vec2 nao_direction(int tile, int slice) {
    return NAO_DIRECTIONS[tile * 4 + slice];
}

float nao_jitter(int tile) {
    return NAO_JITTER[tile];
}

void main() {
    ivec2 gid = ivec2(gl_GlobalInvocationID.xy);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y) {
        return;
    }
    ivec2 px = nao_texel(gid, out_size);  // this invocation's pixel, GL order
    float z = nao_load(src0, px, 0).x;
    if (!(z > 0.0)) {
        nao_store(px, 0, vec4(1.0));
        return;
    }
    vec3 p = nao_position(px, out_size, z);
    vec3 n = nao_load(src1, px, 0).xyz;
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
    int tile = nao_tile(px);
    float jitter = nao_jitter(tile);
    float falloff_range = max(0.2, 1e-6) * u_radius;
    float falloff_mul = -1.0 / falloff_range;
    float falloff_add = (u_radius - falloff_range) / falloff_range + 1.0;
    float min_s = 1.3 / radius_px;  // skip samples within ~1 pixel (self)
    vec2 centre = vec2(px) + 0.5;
    float visibility = 0.0;
    for (int slice = 0; slice < 4; ++slice) {
        vec2 omega = nao_direction(tile, slice);  // screen direction = camera-space (x, y)
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
            float s = (float(k) + jitter) / float(8);
            s = min_s + (1.0 - min_s) * s * s;
            vec2 off = omega * (s * radius_px);
            ivec2 q0 = ivec2(floor(centre + off));
            ivec2 q1 = ivec2(floor(centre - off));
            if (nao_inside(q0, out_size)) {
                float zq = nao_load(src0, q0, 0).x;
                if (zq > 0.0) {
                    vec3 d = nao_position(q0, out_size, zq) - p;
                    float dist = length(d);
                    if (dist > 1e-30) {
                        float w = clamp(dist * falloff_mul + falloff_add, 0.0, 1.0);
                        hc0 = max(hc0, mix(low0, dot(d / dist, view_v), w));
                    }
                }
            }
            if (nao_inside(q1, out_size)) {
                float zq = nao_load(src0, q1, 0).x;
                if (zq > 0.0) {
                    vec3 d = nao_position(q1, out_size, zq) - p;
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
