#version 430 core

// conv products: fp32
#define hvec4 vec4
#define hmat4 mat4
// neuralao compute pass 1: Pad + Mul + Conv + Mul + Clip + Conv + Sub + Mul + Neg + Exp + Clip + Mul
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

layout(binding = 0) uniform highp sampler2DArray src0;
layout(binding = 1) uniform highp sampler2DArray src1;
layout(binding = 0, rgba32f) writeonly uniform highp image2DArray dst;
layout(std430, binding = 0) readonly buffer Params {
    vec4 prm[];
};
layout(location = 0) uniform int u_flip_y;

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 1) {
        return;
    }
    ivec2 src_size0 = textureSize(src0, 0).xy;
    ivec2 size0 = (src_size0 + 7) / 8 * 8;
    int ix = gid.x;
    int iy = gid.y;
    // input texel (ix, iy): src0 reflect-padded at the bottom/right to size0
    int rx = clamp(src_size0.x - 1 - abs(src_size0.x - 1 - ix), 0, src_size0.x - 1);
    int ry = clamp(src_size0.y - 1 - abs(src_size0.y - 1 - iy), 0, src_size0.y - 1);
    if (u_flip_y != 0) {
        ry = src_size0.y - 1 - ry;  // the input is stored bottom-up (a GL render target)
    }
    vec4 v0[2];
    {
    vec4 a = mix(vec4(0.0), texelFetch(src0, ivec3(rx, ry, 0), 0), lessThan(ivec4(4 * 0) + ivec4(0, 1, 2, 3), ivec4(6)));
    vec4 b = mix(vec4(0.0), texelFetch(src0, ivec3(rx, ry, 0), 0), lessThan(ivec4(4 * 0) + ivec4(0, 1, 2, 3), ivec4(6)));
    // no guard
    vec4 r = a * b;
    // no epilogue
        v0[0] = r;
    }
    {
    vec4 a = mix(vec4(0.0), texelFetch(src0, ivec3(rx, ry, 1), 0), lessThan(ivec4(4 * 1) + ivec4(0, 1, 2, 3), ivec4(6)));
    vec4 b = mix(vec4(0.0), texelFetch(src0, ivec3(rx, ry, 1), 0), lessThan(ivec4(4 * 1) + ivec4(0, 1, 2, 3), ivec4(6)));
    // no guard
    vec4 r = a * b;
    // no epilogue
        v0[1] = r;
    }
    vec4 v1[1];
    {
    vec4 r = prm[8];
    r += mat4(prm[0], prm[0 + 1], prm[0 + 2], prm[0 + 3]) * v0[0];
    r += mat4(prm[4], prm[4 + 1], prm[4 + 2], prm[4 + 3]) * v0[1];
    r = min(max(r, vec4(0.0)), vec4(1.0));
        v1[0] = r;
    }
    vec4 v2[1];
    {
    vec4 r = prm[17];
    r += mat4(prm[9], prm[9 + 1], prm[9 + 2], prm[9 + 3]) * mix(vec4(0.0), texelFetch(src0, ivec3(rx, ry, 0), 0), lessThan(ivec4(4 * 0) + ivec4(0, 1, 2, 3), ivec4(6)));
    r += mat4(prm[13], prm[13 + 1], prm[13 + 2], prm[13 + 3]) * mix(vec4(0.0), texelFetch(src0, ivec3(rx, ry, 1), 0), lessThan(ivec4(4 * 1) + ivec4(0, 1, 2, 3), ivec4(6)));
    // no epilogue
        v2[0] = r;
    }
    vec4 v3[1];
    {
    vec4 a = v2[0];
    vec4 b = texelFetch(src1, ivec3(0, 0, 0), 0);
    // no guard
    vec4 r = a - b;
    // no epilogue
        v3[0] = r;
    }
    vec4 v4[1];
    {
    vec4 a = v3[0];
    vec4 b = v1[0];
    // no guard
    vec4 r = a * b;
    // no epilogue
        v4[0] = r;
    }
    vec4 v5[1];
    {
    vec4 r = v4[0];
    r = (-r);
    r = exp(r);
    r = mix(vec4(0.0), r, lessThan(ivec4(4 * 0) + ivec4(0, 1, 2, 3), ivec4(1)));
    r = min(max(r, vec4(0.0)), vec4(8.0));
        v5[0] = r;
    }
    vec4 v6[1];
    {
    vec4 a = v5[0];
    vec4 b = v1[0];
    // no guard
    vec4 r = a * b;
    // no epilogue
        v6[0] = r;
    }
    vec4 r = v6[gid.z];
    // no epilogue
    imageStore(dst, ivec3(gid.xy, gid.z), r);
}
