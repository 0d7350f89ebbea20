#version 430 core
// neuralao baseline: 4x4 foreground-only box blur of a raw AO image.
layout(binding = 0) uniform sampler2D u_position;  // w = foreground mask
layout(binding = 3) uniform sampler2D u_raw;       // raw AO
layout(location = 0) out float o_ao;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    ivec2 size = textureSize(u_raw, 0);
    if (texelFetch(u_position, px, 0).w < 0.5) { o_ao = 1.0; return; }
    float sum = 0.0;
    float count = 0.0;
    for (int y = -2; y < 4 - 2; ++y) {
        for (int x = -2; x < 4 - 2; ++x) {
            ivec2 q = px + ivec2(x, y);
            if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
            if (texelFetch(u_position, q, 0).w < 0.5) continue;
            sum += texelFetch(u_raw, q, 0).r;
            count += 1.0;
        }
    }
    o_ao = sum / max(count, 1.0);
}
