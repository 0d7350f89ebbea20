#version 450
#extension GL_EXT_samplerless_texture_functions : require
// conv accumulation: fp32
#define hvec4 vec4
#define hmat4 mat4
// neuralao compute pass 6: Resize + Conv + LeakyRelu
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

// Overflow-safe activations (exp() only sees arguments <= 0).
vec4 nao_tanh(vec4 x) {
    vec4 e = exp(-2.0 * abs(x));
    return sign(x) * ((1.0 - e) / (1.0 + e));
}

vec4 nao_sigmoid(vec4 x) {
    vec4 e = exp(-abs(x));
    vec4 r = 1.0 / (1.0 + e);
    return mix(e * r, r, greaterThanEqual(x, vec4(0.0)));
}

vec4 nao_leaky_relu(vec4 x, float alpha) {
    return mix(alpha * x, x, greaterThanEqual(x, vec4(0.0)));
}

layout(set = 0, binding = 0) uniform highp texture2DArray src0;
layout(set = 0, binding = 1, rgba32f) writeonly uniform highp image2DArray dst;
layout(std430, set = 0, binding = 2) readonly buffer Params {
    vec4 prm[];
};

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 8) {
        return;
    }
    ivec2 src_size0 = textureSize(src0, 0).xy;
    ivec2 size0 = src_size0 * 2;
    hvec4 acc = hvec4(prm[4608 + gid.z]);
    for (int ky = 0; ky < 3; ++ky) {
        int iy = gid.y * 1 - 1 + ky * 1;
        for (int kx = 0; kx < 3; ++kx) {
            int ix = gid.x * 1 - 1 + kx * 1;
            int tap = 0 + ((gid.z * 3 + ky) * 3 + kx) * 64;
            if (iy >= 0 && iy < size0.y && ix >= 0 && ix < size0.x) {
                // input texel (ix, iy): src0 upsampled x2 (bilinear, half_pixel)
                float fy = clamp(float(iy) * 0.5 - 0.25, 0.0, float(src_size0.y - 1));
                float fx = clamp(float(ix) * 0.5 - 0.25, 0.0, float(src_size0.x - 1));
                int y0 = int(fy);
                int x0 = int(fx);
                int y1 = min(y0 + 1, src_size0.y - 1);
                int x1 = min(x0 + 1, src_size0.x - 1);
                float wy = fy - float(y0);
                float wx = fx - float(x0);
                for (int l = 0; l < 16; ++l) {
                    vec4 v = (texelFetch(src0, ivec3(x0, y0, l), 0) * (1.0 - wx)
                        + texelFetch(src0, ivec3(x1, y0, l), 0) * wx) * (1.0 - wy)
                        + (texelFetch(src0, ivec3(x0, y1, l), 0) * (1.0 - wx)
                        + texelFetch(src0, ivec3(x1, y1, l), 0) * wx) * wy;
                    int o = tap + (0 + l) * 4;
                    acc += hmat4(mat4(prm[o], prm[o + 1], prm[o + 2], prm[o + 3])) * hvec4(v);
                }
            }
        }
    }
    vec4 r = vec4(acc);
    r = nao_leaky_relu(r, 0.01);
    imageStore(dst, ivec3(gid.xy, gid.z), r);
}
