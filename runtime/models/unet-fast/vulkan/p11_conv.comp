#version 450
#extension GL_EXT_samplerless_texture_functions : require
// conv products: fp32
#define hvec4 vec4
#define hmat4 mat4
// neuralao compute pass 11: Resize + Conv + LeakyRelu
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
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= 2) {
        return;
    }
    ivec2 src_size0 = textureSize(src0, 0).xy;
    ivec2 size0 = src_size0 * 2;
    vec4 acc = prm[288 + gid.z];
    {
        // input part 0: src0 upsampled x2, its 3x3 taps from 3x3 low texels
        ivec2 lo = src_size0 - 1;
        ivec2 m = gid.xy / 2;
        bool ox = (gid.x & 1) == 1;
        bool oy = (gid.y & 1) == 1;
        int x0 = clamp(m.x - 1, 0, lo.x);
        int x1 = clamp(m.x, 0, lo.x);
        int x2 = clamp(m.x + 1, 0, lo.x);
        int y0 = clamp(m.y - 1, 0, lo.y);
        int y1 = clamp(m.y, 0, lo.y);
        int y2 = clamp(m.y + 1, 0, lo.y);
        float wx = (ox ? 0.75 : 0.25);
        float wy = (oy ? 0.75 : 0.25);
        bool vx0 = gid.x >= 1;
        bool vx2 = gid.x + 1 < size0.x;
        bool vy0 = gid.y >= 1;
        bool vy2 = gid.y + 1 < size0.y;
        for (int l = 0; l < 4; ++l) {
            vec4 c00 = texelFetch(src0, ivec3(x0, y0, l), 0);
            vec4 c01 = texelFetch(src0, ivec3(x1, y0, l), 0);
            vec4 c02 = texelFetch(src0, ivec3(x2, y0, l), 0);
            vec4 c10 = texelFetch(src0, ivec3(x0, y1, l), 0);
            vec4 c11 = texelFetch(src0, ivec3(x1, y1, l), 0);
            vec4 c12 = texelFetch(src0, ivec3(x2, y1, l), 0);
            vec4 c20 = texelFetch(src0, ivec3(x0, y2, l), 0);
            vec4 c21 = texelFetch(src0, ivec3(x1, y2, l), 0);
            vec4 c22 = texelFetch(src0, ivec3(x2, y2, l), 0);
            vec4 h00 = mix(c00, c01, wx);
            vec4 h01 = mix((ox ? c01 : c00), (ox ? c02 : c01), (1.0 - wx));
            vec4 h02 = mix(c01, c02, wx);
            vec4 h10 = mix(c10, c11, wx);
            vec4 h11 = mix((ox ? c11 : c10), (ox ? c12 : c11), (1.0 - wx));
            vec4 h12 = mix(c11, c12, wx);
            vec4 h20 = mix(c20, c21, wx);
            vec4 h21 = mix((ox ? c21 : c20), (ox ? c22 : c21), (1.0 - wx));
            vec4 h22 = mix(c21, c22, wx);
            vec4 u00 = mix(h00, h10, wy);
            vec4 u01 = mix(h01, h11, wy);
            vec4 u02 = mix(h02, h12, wy);
            vec4 u10 = mix((oy ? h10 : h00), (oy ? h20 : h10), (1.0 - wy));
            vec4 u11 = mix((oy ? h11 : h01), (oy ? h21 : h11), (1.0 - wy));
            vec4 u12 = mix((oy ? h12 : h02), (oy ? h22 : h12), (1.0 - wy));
            vec4 u20 = mix(h10, h20, wy);
            vec4 u21 = mix(h11, h21, wy);
            vec4 u22 = mix(h12, h22, wy);
            int o = 0 + gid.z * 9 * 16 + (0 + l) * 4;
            if (vy0 && vx0) {
                int t0 = o + 0 * 16;
                mat4 w0 = mat4(prm[t0], prm[t0 + 1], prm[t0 + 2], prm[t0 + 3]);
                acc += vec4(hmat4(w0) * hvec4(u00));
            }
            if (vy0) {
                int t1 = o + 1 * 16;
                mat4 w1 = mat4(prm[t1], prm[t1 + 1], prm[t1 + 2], prm[t1 + 3]);
                acc += vec4(hmat4(w1) * hvec4(u01));
            }
            if (vy0 && vx2) {
                int t2 = o + 2 * 16;
                mat4 w2 = mat4(prm[t2], prm[t2 + 1], prm[t2 + 2], prm[t2 + 3]);
                acc += vec4(hmat4(w2) * hvec4(u02));
            }
            if (vx0) {
                int t3 = o + 3 * 16;
                mat4 w3 = mat4(prm[t3], prm[t3 + 1], prm[t3 + 2], prm[t3 + 3]);
                acc += vec4(hmat4(w3) * hvec4(u10));
            }
            if (true) {
                int t4 = o + 4 * 16;
                mat4 w4 = mat4(prm[t4], prm[t4 + 1], prm[t4 + 2], prm[t4 + 3]);
                acc += vec4(hmat4(w4) * hvec4(u11));
            }
            if (vx2) {
                int t5 = o + 5 * 16;
                mat4 w5 = mat4(prm[t5], prm[t5 + 1], prm[t5 + 2], prm[t5 + 3]);
                acc += vec4(hmat4(w5) * hvec4(u12));
            }
            if (vy2 && vx0) {
                int t6 = o + 6 * 16;
                mat4 w6 = mat4(prm[t6], prm[t6 + 1], prm[t6 + 2], prm[t6 + 3]);
                acc += vec4(hmat4(w6) * hvec4(u20));
            }
            if (vy2) {
                int t7 = o + 7 * 16;
                mat4 w7 = mat4(prm[t7], prm[t7 + 1], prm[t7 + 2], prm[t7 + 3]);
                acc += vec4(hmat4(w7) * hvec4(u21));
            }
            if (vy2 && vx2) {
                int t8 = o + 8 * 16;
                mat4 w8 = mat4(prm[t8], prm[t8 + 1], prm[t8 + 2], prm[t8 + 3]);
                acc += vec4(hmat4(w8) * hvec4(u22));
            }
        }
    }
    vec4 r = vec4(acc);
    r = nao_leaky_relu(r, 0.01);
    imageStore(dst, ivec3(gid.xy, gid.z), r);
}
