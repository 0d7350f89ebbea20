#version 430 core

// neuralao compute pass 3: Div + Clip
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

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 1) {
        return;
    }
    vec4 a = texelFetch(src0, ivec3(0, 0, gid.z), 0);
    vec4 b = texelFetch(src1, gid, 0);
    b = mix(vec4(1.0), b, lessThan(ivec4(4 * gid.z) + ivec4(0, 1, 2, 3), ivec4(1)));
    vec4 r = a / b;
    r = min(max(r, vec4(0.0)), vec4(8.0));
    imageStore(dst, gid, r);
}
