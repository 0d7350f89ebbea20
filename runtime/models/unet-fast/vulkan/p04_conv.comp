#version 450
#extension GL_EXT_samplerless_texture_functions : require
// conv products: fp32
#define hvec4 vec4
#define hmat4 mat4
// neuralao compute pass 4: AveragePool + Conv + LeakyRelu
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
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 4) {
        return;
    }
    ivec2 src_size0 = textureSize(src0, 0).xy;
    ivec2 size0 = src_size0 / 2;
    vec4 acc = prm[288 + gid.z];
    for (int ky = 0; ky < 3; ++ky) {
        int iy = gid.y * 1 - 1 + ky * 1;
        for (int kx = 0; kx < 3; ++kx) {
            int ix = gid.x * 1 - 1 + kx * 1;
            int tap = 0 + ((gid.z * 3 + ky) * 3 + kx) * 8;
            if (iy >= 0 && iy < size0.y && ix >= 0 && ix < size0.x) {
                // input texel (ix, iy): the mean of src0's 2x2 texels from (2 ix, 2 iy)
                for (int l = 0; l < 2; ++l) {
                    vec4 v = (texelFetch(src0, ivec3(2 * ix, 2 * iy, l), 0)
                        + texelFetch(src0, ivec3(2 * ix + 1, 2 * iy, l), 0)
                        + texelFetch(src0, ivec3(2 * ix, 2 * iy + 1, l), 0)
                        + texelFetch(src0, ivec3(2 * ix + 1, 2 * iy + 1, l), 0)) / 4.0;
                    int o = tap + (0 + l) * 4;
                    mat4 w = mat4(prm[o], prm[o + 1], prm[o + 2], prm[o + 3]);
                    acc += vec4(hmat4(w) * hvec4(v));
                }
            }
        }
    }
    vec4 r = vec4(acc);
    r = nao_leaky_relu(r, 0.01);
    imageStore(dst, ivec3(gid.xy, gid.z), r);
}
