#version 450
#extension GL_EXT_samplerless_texture_functions : require
// conv products: fp32
#define hvec4 vec4
#define hmat4 mat4
// neuralao compute pass 13: Concat + Conv + Conv + Add + Clip + Crop
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
layout(set = 0, binding = 1) uniform highp texture2DArray src1;
layout(set = 0, binding = 2) uniform highp texture2DArray src2;
layout(set = 0, binding = 3, rgba32f) writeonly uniform highp image2DArray dst;
layout(std430, set = 0, binding = 4) readonly buffer Params {
    vec4 prm[];
};
layout(std140, set = 0, binding = 5) uniform PassUniforms {
    int u_flip_y;
};

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 1) {
        return;
    }
    vec4 v0[1];
    {
    vec4 r = prm[12];
    r += mat4(prm[0], prm[0 + 1], prm[0 + 2], prm[0 + 3]) * texelFetch(src0, ivec3(gid.xy, 0), 0);
    r += mat4(prm[4], prm[4 + 1], prm[4 + 2], prm[4 + 3]) * texelFetch(src0, ivec3(gid.xy, 1), 0);
    r += mat4(prm[8], prm[8 + 1], prm[8 + 2], prm[8 + 3]) * texelFetch(src1, ivec3(gid.xy, 0), 0);
    // no epilogue
        v0[0] = r;
    }
    vec4 v1[1];
    {
    vec4 r = prm[17];
    r += mat4(prm[13], prm[13 + 1], prm[13 + 2], prm[13 + 3]) * texelFetch(src2, ivec3(gid.xy, 0), 0);
    {
        vec4 a = v0[0];
        vec4 b = r;
    // no guard
        r = a + b;
    }
    r = min(max(r, vec4(0.0)), vec4(1.0));
        v1[0] = r;
    }
    vec4 r = v1[gid.z];
    // no epilogue
    imageStore(dst, ivec3(ivec2(gid.xy.x, u_flip_y != 0 ? out_size.y - 1 - gid.xy.y : gid.xy.y), gid.z), r);
}
