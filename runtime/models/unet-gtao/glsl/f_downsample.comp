#version 430 core
// neuralao frame pass f_downsample: point sampling to the network's size, position from depth, GTAO
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(binding = 0) uniform highp sampler2DArray src0;
layout(binding = 1) uniform highp sampler2DArray src1;
layout(binding = 2) uniform highp sampler2DArray src2;
layout(binding = 3) uniform highp sampler2DArray src3;
layout(binding = 4, rgba32f) writeonly uniform highp image2DArray dst;
layout(std140, binding = 5) uniform FrameUniforms {
    vec2 u_proj;               // (P00, P11) of the projection matrix
    float u_radius;            // R, the AO radius in scene units
    float u_pixels_per_unit;   // 0.5 * H * P11: pixels spanned by one scene unit at depth 1
    int u_flip_y;              // 1: textures bottom-up (GL), 0: row 0 at the top
};

// GL-order pixel (row 0 at the bottom) <-> texel of a texture of this frame (its own row order).
ivec2 nao_texel(ivec2 p, ivec2 size) {
    return u_flip_y != 0 ? p : ivec2(p.x, size.y - 1 - p.y);
}

ivec2 nao_size(highp sampler2DArray t) {
    return textureSize(t, 0).xy;
}

vec4 nao_load(highp sampler2DArray t, ivec2 p, int layer) {
    return texelFetch(t, ivec3(nao_texel(p, nao_size(t)), layer), 0);
}

void nao_store(ivec2 p, int layer, vec4 v) {
    imageStore(dst, ivec3(nao_texel(p, imageSize(dst).xy), layer), v);
}

bool nao_inside(ivec2 q, ivec2 size) {
    return all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size));
}

float nao_acos(float x) {
    return acos(clamp(x, -1.0, 1.0));
}

// Camera-space position of GL-order pixel p of a size-pixel frame at linear depth z (OpenGL camera, -z
// forward): the pixel centre's ray at depth z.
vec3 nao_position(ivec2 p, ivec2 size, float z) {
    vec2 ndc = (vec2(p) + 0.5) / vec2(size) * 2.0 - 1.0;
    return vec3(ndc.x / u_proj.x * z, ndc.y / u_proj.y * z, -z);
}

// floor(a / b) for b > 0 (GLSL's int division truncates toward 0)
int nao_floor_div(int a, int b) {
    return a >= 0 ? a / b : -((-a + b - 1) / b);
}


void main() {
    ivec2 gid = ivec2(gl_GlobalInvocationID.xy);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y) {
        return;
    }
    ivec2 px = nao_texel(gid, out_size);  // this invocation's pixel, GL order
    ivec2 hi = nao_size(src0);
    ivec2 q = min(((2 * px + 1) * hi) / (2 * out_size), hi - 1);
    float z = nao_load(src0, q, 0).x;
    if (z > 0.0) {
        nao_store(px, 0, vec4(nao_position(q, hi, z), 1.0));
        nao_store(px, 1, vec4(nao_load(src1, q, 0).xyz, 0.0));
    } else {
        nao_store(px, 0, vec4(0.0));
        nao_store(px, 1, vec4(0.0));
    }
    nao_store(px, 2, vec4(nao_load(src2, q, 0).x, nao_load(src3, q, 0).x, 0.0, 0.0));
}
