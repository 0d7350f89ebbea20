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
    int2 _53;
    if (frame.u_flip_y != 0)
    {
        _53 = p;
    }
    else
    {
        _53 = int2(p.x, (size.y - 1) - p.y);
    }
    return _53;
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
    int3 _90 = int3(nao_texel(param, param_1, frame), layer);
    return t.read(uint2(_90.xy), uint(_90.z), 0);
}

static inline __attribute__((always_inline))
void nao_store(thread const int2& p, thread const int& layer, thread const float4& v, constant FrameUniforms& frame, texture2d_array<float, access::write> dst)
{
    int2 param = p;
    int2 param_1 = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    int3 _109 = int3(nao_texel(param, param_1, frame), layer);
    dst.write(v, uint2(_109.xy), uint(_109.z));
}

static inline __attribute__((always_inline))
int nao_floor_div(thread const int& a, thread const int& b)
{
    int _113;
    if (a >= 0)
    {
        _113 = a / b;
    }
    else
    {
        _113 = -((((-a) + b) - 1) / b);
    }
    return _113;
}

kernel void f_upsample(constant FrameUniforms& frame [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], texture2d_array<float> src2 [[texture(3)]], texture2d_array<float> src3 [[texture(4)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], sampler src2Smplr [[sampler(3)]], sampler src3Smplr [[sampler(4)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _147 = gid.x >= out_size.x;
    bool _156;
    if (!_147)
    {
        _156 = gid.y >= out_size.y;
    }
    else
    {
        _156 = _147;
    }
    if (_156)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1, frame);
    int2 param_2 = px;
    int param_3 = 0;
    float4 pw = nao_load(src0, src0Smplr, param_2, param_3, frame);
    if (pw.w < 0.5)
    {
        int2 param_4 = px;
        int param_5 = 0;
        float4 param_6 = float4(1.0);
        nao_store(param_4, param_5, param_6, frame, dst);
        return;
    }
    int2 param_7 = px;
    int param_8 = 1;
    float3 n = nao_load(src0, src0Smplr, param_7, param_8, frame).xyz;
    float depth = fast::max(-pw.z, 1.0000000031710768509710513471353e-30);
    int2 hi = out_size;
    int2 lo = nao_size(src1, src1Smplr);
    float2 uv = (((float2(px) + float2(0.5)) * float2(lo)) / float2(hi)) - float2(0.5);
    int2 num = (((int2(2) * px) + int2(1)) * lo) - hi;
    int param_9 = num.x;
    int param_10 = 2 * hi.x;
    int param_11 = num.y;
    int param_12 = 2 * hi.y;
    int2 base = int2(nao_floor_div(param_9, param_10), nao_floor_div(param_11, param_12)) - int2(1);
    float sum = 0.0;
    float total = 0.0;
    for (int y = 0; y < 4; y++)
    {
        for (int x = 0; x < 4; x++)
        {
            int2 q = clamp(base + int2(x, y), int2(0), lo - int2(1));
            int2 param_13 = q;
            int param_14 = 0;
            float4 qw = nao_load(src2, src2Smplr, param_13, param_14, frame);
            if (qw.w < 0.5)
            {
                continue;
            }
            float2 d = float2(base + int2(x, y)) - uv;
            float spatial = exp((-dot(d, d)) / 0.7200000286102294921875);
            int2 param_15 = q;
            int param_16 = 1;
            float3 qn = nao_load(src2, src2Smplr, param_15, param_16, frame).xyz;
            float plane = abs(dot(qn, pw.xyz - qw.xyz)) / (0.02999999932944774627685546875 * depth);
            float agree = pow(fast::max(dot(qn, n), 0.0), 8.0);
            float w = spatial * (0.001000000047497451305389404296875 + (exp((-plane) * plane) * agree));
            int2 param_17 = q;
            int param_18 = 0;
            int2 param_19 = q;
            int param_20 = 2;
            sum += (w * (nao_load(src1, src1Smplr, param_17, param_18, frame).x - nao_load(src2, src2Smplr, param_19, param_20, frame).x));
            total += w;
        }
    }
    float up = 0.0;
    if (total > 0.0)
    {
        up = sum / total;
    }
    int2 param_21 = px;
    int param_22 = 0;
    int2 param_23 = px;
    int param_24 = 0;
    float4 param_25 = float4(fast::clamp(nao_load(src3, src3Smplr, param_21, param_22, frame).x + up, 0.0, 1.0));
    nao_store(param_23, param_24, param_25, frame, dst);
}

