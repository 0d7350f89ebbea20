#version 450
#extension GL_EXT_samplerless_texture_functions : require
// conv products: fp32
#define hvec4 vec4
#define hmat4 mat4
// neuralao compute pass 0: Uniform
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

layout(set = 0, binding = 0, rgba32f) writeonly uniform highp image2DArray dst;
layout(std140, set = 0, binding = 2) uniform PassUniforms {
    float u_radius;
};

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 1) {
        return;
    }
    vec4 r = vec4(u_radius, 0.0, 0.0, 0.0);
    // no epilogue
    imageStore(dst, ivec3(gid.xy, gid.z), r);
}
