#version 450
#extension GL_EXT_samplerless_texture_functions : require
// neuralao frame pass f_upsample: joint bilateral upsampling of the correction to GTAO, added to GTAO and clamped
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(set = 0, binding = 0) uniform highp texture2DArray src0;
layout(set = 0, binding = 1) uniform highp texture2DArray src1;
layout(set = 0, binding = 2) uniform highp texture2DArray src2;
layout(set = 0, binding = 3) uniform highp texture2DArray src3;
layout(set = 0, binding = 4) uniform highp texture2DArray src4;
layout(set = 0, binding = 5, r32f) writeonly uniform highp image2DArray dst;
layout(std140, set = 0, binding = 6) uniform FrameUniforms {
    vec2 u_proj;               // (P00, P11) of the projection matrix
    float u_radius;            // R, the AO radius in scene units
    float u_pixels_per_unit;   // 0.5 * H * P11: pixels spanned by one scene unit at depth 1
    int u_flip_y;              // 1: textures bottom-up (GL), 0: row 0 at the top
};
shared vec4 nao_tile_a[144];  // the low texels' position, foreground flag
shared vec4 nao_tile_b[144];  // their normal and the value upsampled

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

ivec2 nao_up_base(ivec2 p, ivec2 lo, ivec2 hi) {
    ivec2 num = (2 * p + 1) * lo - hi;
    return ivec2(nao_floor_div(num.x, 2 * hi.x), nao_floor_div(num.y, 2 * hi.y)) - 1;
}

void main() {
    ivec2 gid = ivec2(gl_GlobalInvocationID.xy);
    ivec2 out_size = imageSize(dst).xy;
    int lid = int(gl_LocalInvocationIndex);
    ivec2 group0 = ivec2(gl_WorkGroupID.xy) * ivec2(8, 8);
    ivec2 hi = out_size;
    ivec2 lo = nao_size(src2);
    // the workgroup's first and last pixels in GL order (nao_texel flips rows where row 0 is the top)
    ivec2 c0 = nao_texel(min(group0, out_size - 1), out_size);
    ivec2 c1 = nao_texel(min(group0 + ivec2(7, 7), out_size - 1), out_size);
    ivec2 t0 = nao_up_base(min(c0, c1), lo, hi);
    ivec2 t_size = nao_up_base(max(c0, c1), lo, hi) + 4 - t0;
    bool tiled = t_size.x <= 12 && t_size.y <= 12;
    if (tiled) {
        for (int k = lid; k < t_size.x * t_size.y; k = k + 64) {
            ivec2 q = clamp(t0 + ivec2(k % t_size.x, k / t_size.x), ivec2(0), lo - 1);
            nao_tile_a[k] = nao_load(src3, q, 0);
            nao_tile_b[k] = vec4(nao_load(src3, q, 1).xyz, (nao_load(src2, q, 0).x - nao_load(src3, q, 2).x));
        }
    }
    memoryBarrierShared();
    barrier();
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
    float depth = max(z, 1e-30);
    vec2 uv = (vec2(px) + 0.5) * vec2(lo) / vec2(hi) - 0.5;
    ivec2 base = nao_up_base(px, lo, hi);
    float sum = 0.0;
    float total = 0.0;
    for (int y = 0; y < 4; ++y) {
        for (int x = 0; x < 4; ++x) {
            ivec2 o = base + ivec2(x, y);
            vec4 qw = vec4(0.0);
            vec4 qv = vec4(0.0);
            if (tiled) {
                int k = (o.y - t0.y) * t_size.x + (o.x - t0.x);
                qw = nao_tile_a[k];
                qv = nao_tile_b[k];
            } else {
                ivec2 q = clamp(o, ivec2(0), lo - 1);
                qw = nao_load(src3, q, 0);
                qv = vec4(nao_load(src3, q, 1).xyz, (nao_load(src2, q, 0).x - nao_load(src3, q, 2).x));
            }
            if (qw.w < 0.5) {
                continue;
            }
            vec2 d = vec2(o) - uv;
            float spatial = exp(-dot(d, d) / (2.0 * 0.6 * 0.6));
            vec3 qn = qv.xyz;
            float plane = abs(dot(qn, p - qw.xyz)) / (0.03 * depth);
            float agree = pow(max(dot(qn, n), 0.0), 8.0);
            float w = spatial * (0.001 + exp(-plane * plane) * agree);
            sum += w * qv.w;
            total += w;
        }
    }
    float up = 0.0;
    if (total > 0.0) {
        up = sum / total;
    }
    nao_store(px, 0, vec4(clamp(nao_load(src4, px, 0).x + up, 0.0, 1.0)));
}
