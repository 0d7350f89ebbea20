#version 450
#extension GL_EXT_samplerless_texture_functions : require
// conv accumulation: fp32
#define hvec4 vec4
#define hmat4 mat4
// neuralao compute pass 0: Pad
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
layout(std140, set = 0, binding = 3) uniform PassUniforms {
    int u_flip_y;
};

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 2) {
        return;
    }
    ivec2 in_size = textureSize(src0, 0).xy;
    int x = gid.x < in_size.x ? gid.x : 2 * (in_size.x - 1) - gid.x;
    int y = gid.y < in_size.y ? gid.y : 2 * (in_size.y - 1) - gid.y;
    x = clamp(x, 0, in_size.x - 1);
    y = clamp(y, 0, in_size.y - 1);
    if (u_flip_y != 0) {
        y = in_size.y - 1 - y;  // source texture stored bottom-up (a GL render target)
    }
    vec4 r = texelFetch(src0, ivec3(x, y, gid.z), 0);
    r = mix(vec4(0.0), r, lessThan(ivec4(4 * gid.z) + ivec4(0, 1, 2, 3), ivec4(5)));
    imageStore(dst, ivec3(gid.xy, gid.z), r);
}
