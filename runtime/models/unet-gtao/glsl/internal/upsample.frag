#version 430 core
// neuralao: joint bilateral upsampling of low-resolution AO to the G-buffer's resolution.
layout(binding = 0) uniform sampler2D u_position;      // high res: xyz camera-space position, w mask
layout(binding = 1) uniform sampler2D u_normal;        // high res: xyz camera-space unit normal
layout(binding = 4) uniform sampler2D u_low_ao;        // low res: AO
layout(binding = 5) uniform sampler2D u_low_position;  // low res: point-sampled u_position
layout(binding = 6) uniform sampler2D u_low_normal;    // low res: point-sampled u_normal
layout(location = 0) out float o_ao;

const float SPATIAL_SIGMA = 0.6;  // low-resolution texels
const float PLANE_SIGMA = 0.03;      // tangent-plane distance / depth
const float NORMAL_POWER = 8.0;
const float FLOOR = 0.001;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 pw = texelFetch(u_position, px, 0);
    if (pw.w < 0.5) { o_ao = 1.0; return; }
    vec3 n = texelFetch(u_normal, px, 0).xyz;
    float depth = max(-pw.z, 1e-30);
    ivec2 hi = textureSize(u_position, 0);
    ivec2 lo = textureSize(u_low_ao, 0);
    vec2 uv = (vec2(px) + 0.5) * vec2(lo) / vec2(hi) - 0.5;
    // floor(uv) in integers (exact where uv is a whole number; int division truncates toward 0)
    ivec2 num = (2 * px + 1) * lo - hi;
    ivec2 fl = ivec2(num.x >= 0 ? num.x / (2 * hi.x) : -((-num.x + 2 * hi.x - 1) / (2 * hi.x)),
                     num.y >= 0 ? num.y / (2 * hi.y) : -((-num.y + 2 * hi.y - 1) / (2 * hi.y)));
    ivec2 base = fl - 1;
    float sum = 0.0;
    float total = 0.0;
    for (int y = 0; y < 4; ++y) {
        for (int x = 0; x < 4; ++x) {
            ivec2 q = clamp(base + ivec2(x, y), ivec2(0), lo - 1);
            vec4 qw = texelFetch(u_low_position, q, 0);
            if (qw.w < 0.5) continue;
            vec2 d = vec2(base + ivec2(x, y)) - uv;
            float spatial = exp(-dot(d, d) / (2.0 * SPATIAL_SIGMA * SPATIAL_SIGMA));
            vec3 qn = texelFetch(u_low_normal, q, 0).xyz;
            float plane = abs(dot(qn, pw.xyz - qw.xyz)) / (PLANE_SIGMA * depth);
            float agree = pow(max(dot(qn, n), 0.0), NORMAL_POWER);
            float w = spatial * (FLOOR + exp(-plane * plane) * agree);
            sum += w * texelFetch(u_low_ao, q, 0).r;
            total += w;
        }
    }
    o_ao = total > 0.0 ? sum / total : 0.0;
}
