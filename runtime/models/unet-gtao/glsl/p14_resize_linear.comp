#version 430 core

// conv accumulation: fp32
#define hvec4 vec4
#define hmat4 mat4
// neuralao compute pass 14: Resize
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

float nao_div(float a, float b) {
    precise float q = a / b;
    precise float r = fma(-q, b, a);
    precise float d = q + r / b;
    return d;
}

layout(binding = 0) uniform highp sampler2DArray src0;
layout(binding = 0, rgba32f) writeonly uniform highp image2DArray dst;

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 4) {
        return;
    }
    ivec2 in_size = textureSize(src0, 0).xy;
    precise float fy = (nao_div(float(gid.y) + 0.5, 2.0) - 0.5);
    precise float fx = (nao_div(float(gid.x) + 0.5, 2.0) - 0.5);
    const bool outside = false;
    fy = clamp(fy, 0.0, float(in_size.y - 1));
    fx = clamp(fx, 0.0, float(in_size.x - 1));
    int y0 = int(fy);
    int x0 = int(fx);
    int y1 = min(y0 + 1, in_size.y - 1);
    int x1 = min(x0 + 1, in_size.x - 1);
    float wy = fy - float(y0);
    float wx = fx - float(x0);
    vec4 a = texelFetch(src0, ivec3(x0, y0, gid.z), 0);
    vec4 b = texelFetch(src0, ivec3(x1, y0, gid.z), 0);
    vec4 c = texelFetch(src0, ivec3(x0, y1, gid.z), 0);
    vec4 d = texelFetch(src0, ivec3(x1, y1, gid.z), 0);
    vec4 r = (a * (1.0 - wx) + b * wx) * (1.0 - wy) + (c * (1.0 - wx) + d * wx) * wy;
    if (outside) {
        r = vec4(0.0);
    }
    // no epilogue
    imageStore(dst, ivec3(gid.xy, gid.z), r);
}
