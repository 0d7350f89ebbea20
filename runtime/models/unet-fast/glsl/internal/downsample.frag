#version 430 core
// neuralao: point-sampled G-buffer at the internal resolution (two targets: position, normal).
layout(binding = 0) uniform sampler2D u_position;  // high res: xyz camera-space position, w mask
layout(binding = 1) uniform sampler2D u_normal;    // high res: xyz camera-space unit normal
uniform ivec2 u_low_size;                          // the internal resolution (this pass's target)
layout(location = 0) out vec4 o_position;
layout(location = 1) out vec4 o_normal;

void main() {
    ivec2 t = ivec2(gl_FragCoord.xy);
    ivec2 hi = textureSize(u_position, 0);
    ivec2 lo = u_low_size;
    ivec2 q = min(((2 * t + 1) * hi) / (2 * lo), hi - 1);  // floor((t + 0.5) * hi / lo), exactly
    o_position = texelFetch(u_position, q, 0);
    o_normal = texelFetch(u_normal, q, 0);
}
