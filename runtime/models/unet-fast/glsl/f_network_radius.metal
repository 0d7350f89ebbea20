#pragma clang diagnostic ignored "-Wmissing-prototypes"

#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

struct FrameUniforms
{
    float2 u_proj;
    float u_radius;
    float u_pixels_per_unit;
    int u_flip_y;
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(1u);

static inline __attribute__((always_inline))
int2 nao_texel(thread const int2& p, thread const int2& size, constant FrameUniforms& frame)
{
    int2 _35;
    if (frame.u_flip_y != 0)
    {
        _35 = p;
    }
    else
    {
        _35 = int2(p.x, (size.y - 1) - p.y);
    }
    return _35;
}

static inline __attribute__((always_inline))
void nao_store(thread const int2& p, thread const int& layer, thread const float4& v, constant FrameUniforms& frame, texture2d_array<float, access::write> dst)
{
    int2 param = p;
    int2 param_1 = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    int3 _71 = int3(nao_texel(param, param_1, frame), layer);
    dst.write(v, uint2(_71.xy), uint(_71.z));
}

kernel void f_network_radius(constant FrameUniforms& frame [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _89 = gid.x >= out_size.x;
    bool _98;
    if (!_89)
    {
        _98 = gid.y >= out_size.y;
    }
    else
    {
        _98 = _89;
    }
    if (_98)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1, frame);
    int2 param_2 = px;
    int param_3 = 0;
    float4 param_4 = float4(log(frame.u_radius * frame.u_proj.y), 0.0, 0.0, 0.0);
    nao_store(param_2, param_3, param_4, frame, dst);
}

