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
    int2 _56;
    if (frame.u_flip_y != 0)
    {
        _56 = p;
    }
    else
    {
        _56 = int2(p.x, (size.y - 1) - p.y);
    }
    return _56;
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
    int3 _93 = int3(nao_texel(param, param_1, frame), layer);
    return t.read(uint2(_93.xy), uint(_93.z), 0);
}

static inline __attribute__((always_inline))
float3 nao_position(thread const int2& p, thread const int2& size, thread const float& z, constant FrameUniforms& frame)
{
    float2 ndc = (((float2(p) + float2(0.5)) / float2(size)) * 2.0) - float2(1.0);
    return float3((ndc.x / frame.u_proj.x) * z, (ndc.y / frame.u_proj.y) * z, -z);
}

static inline __attribute__((always_inline))
void nao_store(thread const int2& p, thread const int& layer, thread const float4& v, constant FrameUniforms& frame, texture2d_array<float, access::write> dst)
{
    int2 param = p;
    int2 param_1 = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    int3 _112 = int3(nao_texel(param, param_1, frame), layer);
    dst.write(v, uint2(_112.xy), uint(_112.z));
}

kernel void f_downsample(constant FrameUniforms& frame [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], texture2d_array<float> src2 [[texture(3)]], texture2d_array<float> src3 [[texture(4)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], sampler src2Smplr [[sampler(3)]], sampler src3Smplr [[sampler(4)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _165 = gid.x >= out_size.x;
    bool _174;
    if (!_165)
    {
        _174 = gid.y >= out_size.y;
    }
    else
    {
        _174 = _165;
    }
    if (_174)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1, frame);
    int2 hi = nao_size(src0, src0Smplr);
    int2 q = min(((((int2(2) * px) + int2(1)) * hi) / (int2(2) * out_size)), (hi - int2(1)));
    int2 param_2 = q;
    int param_3 = 0;
    float z = nao_load(src0, src0Smplr, param_2, param_3, frame).x;
    if (z > 0.0)
    {
        int2 param_4 = q;
        int2 param_5 = hi;
        float param_6 = z;
        int2 param_7 = px;
        int param_8 = 0;
        float4 param_9 = float4(nao_position(param_4, param_5, param_6, frame), 1.0);
        nao_store(param_7, param_8, param_9, frame, dst);
        int2 param_10 = q;
        int param_11 = 0;
        int2 param_12 = px;
        int param_13 = 1;
        float4 param_14 = float4(nao_load(src1, src1Smplr, param_10, param_11, frame).xyz, 0.0);
        nao_store(param_12, param_13, param_14, frame, dst);
    }
    else
    {
        int2 param_15 = px;
        int param_16 = 0;
        float4 param_17 = float4(0.0);
        nao_store(param_15, param_16, param_17, frame, dst);
        int2 param_18 = px;
        int param_19 = 1;
        float4 param_20 = float4(0.0);
        nao_store(param_18, param_19, param_20, frame, dst);
    }
    int2 param_21 = q;
    int param_22 = 0;
    int2 param_23 = q;
    int param_24 = 0;
    int2 param_25 = px;
    int param_26 = 2;
    float4 param_27 = float4(nao_load(src2, src2Smplr, param_21, param_22, frame).x, nao_load(src3, src3Smplr, param_23, param_24, frame).x, 0.0, 0.0);
    nao_store(param_25, param_26, param_27, frame, dst);
}

