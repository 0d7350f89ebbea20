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
    int2 _61;
    if (frame.u_flip_y != 0)
    {
        _61 = p;
    }
    else
    {
        _61 = int2(p.x, (size.y - 1) - p.y);
    }
    return _61;
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
    int3 _98 = int3(nao_texel(param, param_1, frame), layer);
    return t.read(uint2(_98.xy), uint(_98.z), 0);
}

static inline __attribute__((always_inline))
void nao_store(thread const int2& p, thread const int& layer, thread const float4& v, constant FrameUniforms& frame, texture2d_array<float, access::write> dst)
{
    int2 param = p;
    int2 param_1 = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    int3 _117 = int3(nao_texel(param, param_1, frame), layer);
    dst.write(v, uint2(_117.xy), uint(_117.z));
}

static inline __attribute__((always_inline))
float3 nao_position(thread const int2& p, thread const int2& size, thread const float& z, constant FrameUniforms& frame)
{
    float2 ndc = (((float2(p) + float2(0.5)) / float2(size)) * 2.0) - float2(1.0);
    return float3((ndc.x / frame.u_proj.x) * z, (ndc.y / frame.u_proj.y) * z, -z);
}

static inline __attribute__((always_inline))
int nao_floor_div(thread const int& a, thread const int& b)
{
    int _156;
    if (a >= 0)
    {
        _156 = a / b;
    }
    else
    {
        _156 = -((((-a) + b) - 1) / b);
    }
    return _156;
}

kernel void f_upsample(constant FrameUniforms& frame [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], texture2d_array<float> src2 [[texture(3)]], texture2d_array<float> src3 [[texture(4)]], texture2d_array<float> src4 [[texture(5)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], sampler src2Smplr [[sampler(3)]], sampler src3Smplr [[sampler(4)]], sampler src4Smplr [[sampler(5)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _190 = gid.x >= out_size.x;
    bool _199;
    if (!_190)
    {
        _199 = gid.y >= out_size.y;
    }
    else
    {
        _199 = _190;
    }
    if (_199)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1, frame);
    int2 param_2 = px;
    int param_3 = 0;
    float z = nao_load(src0, src0Smplr, param_2, param_3, frame).x;
    if (!(z > 0.0))
    {
        int2 param_4 = px;
        int param_5 = 0;
        float4 param_6 = float4(1.0);
        nao_store(param_4, param_5, param_6, frame, dst);
        return;
    }
    int2 param_7 = px;
    int2 param_8 = out_size;
    float param_9 = z;
    float3 p = nao_position(param_7, param_8, param_9, frame);
    int2 param_10 = px;
    int param_11 = 0;
    float3 n = nao_load(src1, src1Smplr, param_10, param_11, frame).xyz;
    float depth = fast::max(z, 1.0000000031710768509710513471353e-30);
    int2 hi = out_size;
    int2 lo = nao_size(src2, src2Smplr);
    float2 uv = (((float2(px) + float2(0.5)) * float2(lo)) / float2(hi)) - float2(0.5);
    int2 num = (((int2(2) * px) + int2(1)) * lo) - hi;
    int param_12 = num.x;
    int param_13 = 2 * hi.x;
    int param_14 = num.y;
    int param_15 = 2 * hi.y;
    int2 base = int2(nao_floor_div(param_12, param_13), nao_floor_div(param_14, param_15)) - int2(1);
    float sum = 0.0;
    float total = 0.0;
    for (int y = 0; y < 4; y++)
    {
        for (int x = 0; x < 4; x++)
        {
            int2 q = clamp(base + int2(x, y), int2(0), lo - int2(1));
            int2 param_16 = q;
            int param_17 = 0;
            float4 qw = nao_load(src3, src3Smplr, param_16, param_17, frame);
            if (qw.w < 0.5)
            {
                continue;
            }
            float2 d = float2(base + int2(x, y)) - uv;
            float spatial = exp((-dot(d, d)) / 0.7200000286102294921875);
            int2 param_18 = q;
            int param_19 = 1;
            float3 qn = nao_load(src3, src3Smplr, param_18, param_19, frame).xyz;
            float plane = abs(dot(qn, p - qw.xyz)) / (0.02999999932944774627685546875 * depth);
            float agree = pow(fast::max(dot(qn, n), 0.0), 8.0);
            float w = spatial * (0.001000000047497451305389404296875 + (exp((-plane) * plane) * agree));
            int2 param_20 = q;
            int param_21 = 0;
            int2 param_22 = q;
            int param_23 = 2;
            sum += (w * (nao_load(src2, src2Smplr, param_20, param_21, frame).x - nao_load(src3, src3Smplr, param_22, param_23, frame).x));
            total += w;
        }
    }
    float up = 0.0;
    if (total > 0.0)
    {
        up = sum / total;
    }
    int2 param_24 = px;
    int param_25 = 0;
    int2 param_26 = px;
    int param_27 = 0;
    float4 param_28 = float4(fast::clamp(nao_load(src4, src4Smplr, param_24, param_25, frame).x + up, 0.0, 1.0));
    nao_store(param_26, param_27, param_28, frame, dst);
}

