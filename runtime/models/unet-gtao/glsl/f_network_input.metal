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

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

static inline __attribute__((always_inline))
int2 nao_texel(thread const int2& p, thread const int2& size, constant FrameUniforms& frame)
{
    int2 _48;
    if (frame.u_flip_y != 0)
    {
        _48 = p;
    }
    else
    {
        _48 = int2(p.x, (size.y - 1) - p.y);
    }
    return _48;
}

static inline __attribute__((always_inline))
int2 nao_size(texture2d_array<float> t, sampler tSmplr)
{
    return int3(t.get_width(), t.get_height(), t.get_array_size()).xy;
}

static inline __attribute__((always_inline))
float4 nao_load(texture2d_array<float> t, sampler tSmplr, thread const int2& p, thread const int& layer, constant FrameUniforms& frame)
{
    int2 param = p;
    int2 param_1 = nao_size(t, tSmplr);
    int3 _85 = int3(nao_texel(param, param_1, frame), layer);
    return t.read(uint2(_85.xy), uint(_85.z), 0);
}

static inline __attribute__((always_inline))
void nao_store(thread const int2& p, thread const int& layer, thread const float4& v, constant FrameUniforms& frame, texture2d_array<float, access::write> dst)
{
    int2 param = p;
    int2 param_1 = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    int3 _104 = int3(nao_texel(param, param_1, frame), layer);
    dst.write(v, uint2(_104.xy), uint(_104.z));
}

kernel void f_network_input(constant FrameUniforms& frame [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _122 = gid.x >= out_size.x;
    bool _131;
    if (!_122)
    {
        _131 = gid.y >= out_size.y;
    }
    else
    {
        _131 = _122;
    }
    if (_131)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1, frame);
    int2 param_2 = px;
    int param_3 = 0;
    float4 pw = nao_load(src0, src0Smplr, param_2, param_3, frame);
    float4 x = float4(0.0);
    bool _155 = pw.w >= 0.5;
    bool _163;
    if (_155)
    {
        _163 = (-pw.z) > 0.0;
    }
    else
    {
        _163 = _155;
    }
    if (_163)
    {
        int2 param_4 = px;
        int param_5 = 1;
        x = float4(log(-pw.z), nao_load(src0, src0Smplr, param_4, param_5, frame).xyz);
    }
    int2 param_6 = px;
    int param_7 = 0;
    float4 param_8 = x;
    nao_store(param_6, param_7, param_8, frame, dst);
    float g = 1.0;
    float r = 1.0;
    if (pw.w >= 0.5)
    {
        int2 param_9 = px;
        int param_10 = 2;
        g = nao_load(src0, src0Smplr, param_9, param_10, frame).x;
        int2 param_11 = px;
        int param_12 = 2;
        r = nao_load(src0, src0Smplr, param_11, param_12, frame).y;
    }
    int2 param_13 = px;
    int param_14 = 1;
    float4 param_15 = float4(r, g, 0.0, 0.0);
    nao_store(param_13, param_14, param_15, frame, dst);
}

