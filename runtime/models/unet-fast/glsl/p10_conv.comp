#version 430 core

// neuralao compute pass 10: Conv + LeakyRelu
// One invocation: 8x4 output texels x 2 output layer(s) from layer 2 * gid.z.
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
layout(std430, binding = 0) readonly buffer Params {
    vec4 prm[];
};

// Zero padding without a branch: q is clamped into the input; returns 1 inside, 0 outside (texels
// are finite, so 0 * texel is 0).
float nao_clip(inout ivec2 q, ivec2 size) {
    float k = all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size)) ? 1.0 : 0.0;
    q = clamp(q, ivec2(0), size - 1);
    return k;
}

mat4 nao_tap(int o) {
    return mat4(prm[o], prm[o + 1], prm[o + 2], prm[o + 3]);
}

// Epilogue and store of output texel xy, layer z (skipped outside the output: partial blocks).
void nao_store(ivec2 xy, int z, vec4 r) {
    if (all(lessThan(xy, imageSize(dst).xy))) {
        r = nao_leaky_relu(r, 0.01);
        imageStore(dst, ivec3(xy, z), r);
    }
}

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 base = gid.xy * ivec2(8, 4);
    int z0 = gid.z * 2;
    if (any(greaterThanEqual(base, imageSize(dst).xy))) {
        return;
    }
    ivec2 in_size = textureSize(src0, 0).xy;
    vec4 b0 = prm[4608 + z0 + 0];
    vec4 b1 = prm[4608 + z0 + 1];
    vec4 a0_0 = b0, a0_1 = b0, a0_2 = b0, a0_3 = b0, a0_4 = b0, a0_5 = b0, a0_6 = b0, a0_7 = b0, a0_8 = b0, a0_9 = b0, a0_10 = b0, a0_11 = b0, a0_12 = b0, a0_13 = b0, a0_14 = b0, a0_15 = b0, a0_16 = b0, a0_17 = b0, a0_18 = b0, a0_19 = b0, a0_20 = b0, a0_21 = b0, a0_22 = b0, a0_23 = b0, a0_24 = b0, a0_25 = b0, a0_26 = b0, a0_27 = b0, a0_28 = b0, a0_29 = b0, a0_30 = b0, a0_31 = b0;
    vec4 a1_0 = b1, a1_1 = b1, a1_2 = b1, a1_3 = b1, a1_4 = b1, a1_5 = b1, a1_6 = b1, a1_7 = b1, a1_8 = b1, a1_9 = b1, a1_10 = b1, a1_11 = b1, a1_12 = b1, a1_13 = b1, a1_14 = b1, a1_15 = b1, a1_16 = b1, a1_17 = b1, a1_18 = b1, a1_19 = b1, a1_20 = b1, a1_21 = b1, a1_22 = b1, a1_23 = b1, a1_24 = b1, a1_25 = b1, a1_26 = b1, a1_27 = b1, a1_28 = b1, a1_29 = b1, a1_30 = b1, a1_31 = b1;
    for (int ky = 0; ky < 3; ++ky) {
        for (int kx = 0; kx < 3; ++kx) {
            int tap = 0 + ((z0 * 3 + ky) * 3 + kx) * 32;
            ivec2 qb = base * ivec2(1, 1) + ivec2(kx * 1 - 1, ky * 1 - 1);
            ivec2 q0 = qb + ivec2(0, 0); float k0 = nao_clip(q0, in_size);
            ivec2 q1 = qb + ivec2(1, 0); float k1 = nao_clip(q1, in_size);
            ivec2 q2 = qb + ivec2(2, 0); float k2 = nao_clip(q2, in_size);
            ivec2 q3 = qb + ivec2(3, 0); float k3 = nao_clip(q3, in_size);
            ivec2 q4 = qb + ivec2(4, 0); float k4 = nao_clip(q4, in_size);
            ivec2 q5 = qb + ivec2(5, 0); float k5 = nao_clip(q5, in_size);
            ivec2 q6 = qb + ivec2(6, 0); float k6 = nao_clip(q6, in_size);
            ivec2 q7 = qb + ivec2(7, 0); float k7 = nao_clip(q7, in_size);
            ivec2 q8 = qb + ivec2(0, 1); float k8 = nao_clip(q8, in_size);
            ivec2 q9 = qb + ivec2(1, 1); float k9 = nao_clip(q9, in_size);
            ivec2 q10 = qb + ivec2(2, 1); float k10 = nao_clip(q10, in_size);
            ivec2 q11 = qb + ivec2(3, 1); float k11 = nao_clip(q11, in_size);
            ivec2 q12 = qb + ivec2(4, 1); float k12 = nao_clip(q12, in_size);
            ivec2 q13 = qb + ivec2(5, 1); float k13 = nao_clip(q13, in_size);
            ivec2 q14 = qb + ivec2(6, 1); float k14 = nao_clip(q14, in_size);
            ivec2 q15 = qb + ivec2(7, 1); float k15 = nao_clip(q15, in_size);
            ivec2 q16 = qb + ivec2(0, 2); float k16 = nao_clip(q16, in_size);
            ivec2 q17 = qb + ivec2(1, 2); float k17 = nao_clip(q17, in_size);
            ivec2 q18 = qb + ivec2(2, 2); float k18 = nao_clip(q18, in_size);
            ivec2 q19 = qb + ivec2(3, 2); float k19 = nao_clip(q19, in_size);
            ivec2 q20 = qb + ivec2(4, 2); float k20 = nao_clip(q20, in_size);
            ivec2 q21 = qb + ivec2(5, 2); float k21 = nao_clip(q21, in_size);
            ivec2 q22 = qb + ivec2(6, 2); float k22 = nao_clip(q22, in_size);
            ivec2 q23 = qb + ivec2(7, 2); float k23 = nao_clip(q23, in_size);
            ivec2 q24 = qb + ivec2(0, 3); float k24 = nao_clip(q24, in_size);
            ivec2 q25 = qb + ivec2(1, 3); float k25 = nao_clip(q25, in_size);
            ivec2 q26 = qb + ivec2(2, 3); float k26 = nao_clip(q26, in_size);
            ivec2 q27 = qb + ivec2(3, 3); float k27 = nao_clip(q27, in_size);
            ivec2 q28 = qb + ivec2(4, 3); float k28 = nao_clip(q28, in_size);
            ivec2 q29 = qb + ivec2(5, 3); float k29 = nao_clip(q29, in_size);
            ivec2 q30 = qb + ivec2(6, 3); float k30 = nao_clip(q30, in_size);
            ivec2 q31 = qb + ivec2(7, 3); float k31 = nao_clip(q31, in_size);
            for (int l = 0; l < 8; ++l) {
                int o = tap + (0 + l) * 4;
                vec4 v0 = texelFetch(src0, ivec3(q0, l), 0) * k0;
                vec4 v1 = texelFetch(src0, ivec3(q1, l), 0) * k1;
                vec4 v2 = texelFetch(src0, ivec3(q2, l), 0) * k2;
                vec4 v3 = texelFetch(src0, ivec3(q3, l), 0) * k3;
                vec4 v4 = texelFetch(src0, ivec3(q4, l), 0) * k4;
                vec4 v5 = texelFetch(src0, ivec3(q5, l), 0) * k5;
                vec4 v6 = texelFetch(src0, ivec3(q6, l), 0) * k6;
                vec4 v7 = texelFetch(src0, ivec3(q7, l), 0) * k7;
                vec4 v8 = texelFetch(src0, ivec3(q8, l), 0) * k8;
                vec4 v9 = texelFetch(src0, ivec3(q9, l), 0) * k9;
                vec4 v10 = texelFetch(src0, ivec3(q10, l), 0) * k10;
                vec4 v11 = texelFetch(src0, ivec3(q11, l), 0) * k11;
                vec4 v12 = texelFetch(src0, ivec3(q12, l), 0) * k12;
                vec4 v13 = texelFetch(src0, ivec3(q13, l), 0) * k13;
                vec4 v14 = texelFetch(src0, ivec3(q14, l), 0) * k14;
                vec4 v15 = texelFetch(src0, ivec3(q15, l), 0) * k15;
                vec4 v16 = texelFetch(src0, ivec3(q16, l), 0) * k16;
                vec4 v17 = texelFetch(src0, ivec3(q17, l), 0) * k17;
                vec4 v18 = texelFetch(src0, ivec3(q18, l), 0) * k18;
                vec4 v19 = texelFetch(src0, ivec3(q19, l), 0) * k19;
                vec4 v20 = texelFetch(src0, ivec3(q20, l), 0) * k20;
                vec4 v21 = texelFetch(src0, ivec3(q21, l), 0) * k21;
                vec4 v22 = texelFetch(src0, ivec3(q22, l), 0) * k22;
                vec4 v23 = texelFetch(src0, ivec3(q23, l), 0) * k23;
                vec4 v24 = texelFetch(src0, ivec3(q24, l), 0) * k24;
                vec4 v25 = texelFetch(src0, ivec3(q25, l), 0) * k25;
                vec4 v26 = texelFetch(src0, ivec3(q26, l), 0) * k26;
                vec4 v27 = texelFetch(src0, ivec3(q27, l), 0) * k27;
                vec4 v28 = texelFetch(src0, ivec3(q28, l), 0) * k28;
                vec4 v29 = texelFetch(src0, ivec3(q29, l), 0) * k29;
                vec4 v30 = texelFetch(src0, ivec3(q30, l), 0) * k30;
                vec4 v31 = texelFetch(src0, ivec3(q31, l), 0) * k31;
                mat4 m0 = nao_tap(o + 0);
                a0_0 += m0 * v0; a0_1 += m0 * v1; a0_2 += m0 * v2; a0_3 += m0 * v3;
                a0_4 += m0 * v4; a0_5 += m0 * v5; a0_6 += m0 * v6; a0_7 += m0 * v7;
                a0_8 += m0 * v8; a0_9 += m0 * v9; a0_10 += m0 * v10; a0_11 += m0 * v11;
                a0_12 += m0 * v12; a0_13 += m0 * v13; a0_14 += m0 * v14; a0_15 += m0 * v15;
                a0_16 += m0 * v16; a0_17 += m0 * v17; a0_18 += m0 * v18; a0_19 += m0 * v19;
                a0_20 += m0 * v20; a0_21 += m0 * v21; a0_22 += m0 * v22; a0_23 += m0 * v23;
                a0_24 += m0 * v24; a0_25 += m0 * v25; a0_26 += m0 * v26; a0_27 += m0 * v27;
                a0_28 += m0 * v28; a0_29 += m0 * v29; a0_30 += m0 * v30; a0_31 += m0 * v31;
                mat4 m1 = nao_tap(o + 288);
                a1_0 += m1 * v0; a1_1 += m1 * v1; a1_2 += m1 * v2; a1_3 += m1 * v3;
                a1_4 += m1 * v4; a1_5 += m1 * v5; a1_6 += m1 * v6; a1_7 += m1 * v7;
                a1_8 += m1 * v8; a1_9 += m1 * v9; a1_10 += m1 * v10; a1_11 += m1 * v11;
                a1_12 += m1 * v12; a1_13 += m1 * v13; a1_14 += m1 * v14; a1_15 += m1 * v15;
                a1_16 += m1 * v16; a1_17 += m1 * v17; a1_18 += m1 * v18; a1_19 += m1 * v19;
                a1_20 += m1 * v20; a1_21 += m1 * v21; a1_22 += m1 * v22; a1_23 += m1 * v23;
                a1_24 += m1 * v24; a1_25 += m1 * v25; a1_26 += m1 * v26; a1_27 += m1 * v27;
                a1_28 += m1 * v28; a1_29 += m1 * v29; a1_30 += m1 * v30; a1_31 += m1 * v31;
            }
        }
    }
    nao_store(base + ivec2(0, 0), z0 + 0, a0_0);
    nao_store(base + ivec2(1, 0), z0 + 0, a0_1);
    nao_store(base + ivec2(2, 0), z0 + 0, a0_2);
    nao_store(base + ivec2(3, 0), z0 + 0, a0_3);
    nao_store(base + ivec2(4, 0), z0 + 0, a0_4);
    nao_store(base + ivec2(5, 0), z0 + 0, a0_5);
    nao_store(base + ivec2(6, 0), z0 + 0, a0_6);
    nao_store(base + ivec2(7, 0), z0 + 0, a0_7);
    nao_store(base + ivec2(0, 1), z0 + 0, a0_8);
    nao_store(base + ivec2(1, 1), z0 + 0, a0_9);
    nao_store(base + ivec2(2, 1), z0 + 0, a0_10);
    nao_store(base + ivec2(3, 1), z0 + 0, a0_11);
    nao_store(base + ivec2(4, 1), z0 + 0, a0_12);
    nao_store(base + ivec2(5, 1), z0 + 0, a0_13);
    nao_store(base + ivec2(6, 1), z0 + 0, a0_14);
    nao_store(base + ivec2(7, 1), z0 + 0, a0_15);
    nao_store(base + ivec2(0, 2), z0 + 0, a0_16);
    nao_store(base + ivec2(1, 2), z0 + 0, a0_17);
    nao_store(base + ivec2(2, 2), z0 + 0, a0_18);
    nao_store(base + ivec2(3, 2), z0 + 0, a0_19);
    nao_store(base + ivec2(4, 2), z0 + 0, a0_20);
    nao_store(base + ivec2(5, 2), z0 + 0, a0_21);
    nao_store(base + ivec2(6, 2), z0 + 0, a0_22);
    nao_store(base + ivec2(7, 2), z0 + 0, a0_23);
    nao_store(base + ivec2(0, 3), z0 + 0, a0_24);
    nao_store(base + ivec2(1, 3), z0 + 0, a0_25);
    nao_store(base + ivec2(2, 3), z0 + 0, a0_26);
    nao_store(base + ivec2(3, 3), z0 + 0, a0_27);
    nao_store(base + ivec2(4, 3), z0 + 0, a0_28);
    nao_store(base + ivec2(5, 3), z0 + 0, a0_29);
    nao_store(base + ivec2(6, 3), z0 + 0, a0_30);
    nao_store(base + ivec2(7, 3), z0 + 0, a0_31);
    nao_store(base + ivec2(0, 0), z0 + 1, a1_0);
    nao_store(base + ivec2(1, 0), z0 + 1, a1_1);
    nao_store(base + ivec2(2, 0), z0 + 1, a1_2);
    nao_store(base + ivec2(3, 0), z0 + 1, a1_3);
    nao_store(base + ivec2(4, 0), z0 + 1, a1_4);
    nao_store(base + ivec2(5, 0), z0 + 1, a1_5);
    nao_store(base + ivec2(6, 0), z0 + 1, a1_6);
    nao_store(base + ivec2(7, 0), z0 + 1, a1_7);
    nao_store(base + ivec2(0, 1), z0 + 1, a1_8);
    nao_store(base + ivec2(1, 1), z0 + 1, a1_9);
    nao_store(base + ivec2(2, 1), z0 + 1, a1_10);
    nao_store(base + ivec2(3, 1), z0 + 1, a1_11);
    nao_store(base + ivec2(4, 1), z0 + 1, a1_12);
    nao_store(base + ivec2(5, 1), z0 + 1, a1_13);
    nao_store(base + ivec2(6, 1), z0 + 1, a1_14);
    nao_store(base + ivec2(7, 1), z0 + 1, a1_15);
    nao_store(base + ivec2(0, 2), z0 + 1, a1_16);
    nao_store(base + ivec2(1, 2), z0 + 1, a1_17);
    nao_store(base + ivec2(2, 2), z0 + 1, a1_18);
    nao_store(base + ivec2(3, 2), z0 + 1, a1_19);
    nao_store(base + ivec2(4, 2), z0 + 1, a1_20);
    nao_store(base + ivec2(5, 2), z0 + 1, a1_21);
    nao_store(base + ivec2(6, 2), z0 + 1, a1_22);
    nao_store(base + ivec2(7, 2), z0 + 1, a1_23);
    nao_store(base + ivec2(0, 3), z0 + 1, a1_24);
    nao_store(base + ivec2(1, 3), z0 + 1, a1_25);
    nao_store(base + ivec2(2, 3), z0 + 1, a1_26);
    nao_store(base + ivec2(3, 3), z0 + 1, a1_27);
    nao_store(base + ivec2(4, 3), z0 + 1, a1_28);
    nao_store(base + ivec2(5, 3), z0 + 1, a1_29);
    nao_store(base + ivec2(6, 3), z0 + 1, a1_30);
    nao_store(base + ivec2(7, 3), z0 + 1, a1_31);
}
