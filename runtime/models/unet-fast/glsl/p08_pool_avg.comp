#version 430 core

// conv accumulation: fp32
#define hvec4 vec4
#define hmat4 mat4
// neuralao compute pass 8: AveragePool
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
layout(binding = 0, rgba32f) writeonly uniform highp image2DArray dst;

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 8) {
        return;
    }
    ivec2 in_size = textureSize(src0, 0).xy;
    vec4 r = vec4(0.0);
    int count = 0;
    int count_padded = 0;
    for (int ky = 0; ky < 2; ++ky) {
        int iy = gid.y * 2 - 0 + ky * 1;
        if (iy < -0 || iy >= in_size.y + 0) {
            continue;
        }
        for (int kx = 0; kx < 2; ++kx) {
            int ix = gid.x * 2 - 0 + kx * 1;
            if (ix < -0 || ix >= in_size.x + 0) {
                continue;
            }
            count_padded += 1;
            if (iy < 0 || iy >= in_size.y || ix < 0 || ix >= in_size.x) {
                continue;
            }
            vec4 v = texelFetch(src0, ivec3(ix, iy, gid.z), 0);
            r = r + v;
            count += 1;
        }
    }
    r /= float(max(count_padded, 1));
    // no epilogue
    imageStore(dst, ivec3(gid.xy, gid.z), r);
}
