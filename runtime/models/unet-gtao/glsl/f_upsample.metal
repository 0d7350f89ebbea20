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
int2 nao_size(texture2d_array<float> t, sampler tSmplr)
{
    return int3(t.get_width(), t.get_height(), t.get_array_size()).xy;
}

static inline __attribute__((always_inline))
int2 nao_texel(thread const int2& p, thread const int2& size, constant FrameUniforms& frame)
{
    int2 _67;
    if (frame.u_flip_y != 0)
    {
        _67 = p;
    }
    else
    {
        _67 = int2(p.x, (size.y - 1) - p.y);
    }
    return _67;
}

static inline __attribute__((always_inline))
int nao_floor_div(thread const int& a, thread const int& b)
{
    int _162;
    if (a >= 0)
    {
        _162 = a / b;
    }
    else
    {
        _162 = -((((-a) + b) - 1) / b);
    }
    return _162;
}

static inline __attribute__((always_inline))
int2 nao_up_base(thread const int2& p, thread const int2& lo, thread const int2& hi)
{
    int2 num = (((int2(2) * p) + int2(1)) * lo) - hi;
    int param = num.x;
    int param_1 = 2 * hi.x;
    int param_2 = num.y;
    int param_3 = 2 * hi.y;
    return int2(nao_floor_div(param, param_1), nao_floor_div(param_2, param_3)) - int2(1);
}

static inline __attribute__((always_inline))
float4 nao_load(texture2d_array<float> t, sampler tSmplr, thread const int2& p, thread const int& layer, constant FrameUniforms& frame)
{
    int2 param = p;
    int2 param_1 = nao_size(t, tSmplr);
    int3 _104 = int3(nao_texel(param, param_1, frame), layer);
    return t.read(uint2(_104.xy), uint(_104.z), 0);
}

static inline __attribute__((always_inline))
void nao_store(thread const int2& p, thread const int& layer, thread const float4& v, constant FrameUniforms& frame, texture2d_array<float, access::write> dst)
{
    int2 param = p;
    int2 param_1 = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    int3 _123 = int3(nao_texel(param, param_1, frame), layer);
    dst.write(v, uint2(_123.xy), uint(_123.z));
}

static inline __attribute__((always_inline))
float3 nao_position(thread const int2& p, thread const int2& size, thread const float& z, constant FrameUniforms& frame)
{
    float2 ndc = (((float2(p) + float2(0.5)) / float2(size)) * 2.0) - float2(1.0);
    return float3((ndc.x / frame.u_proj.x) * z, (ndc.y / frame.u_proj.y) * z, -z);
}

kernel void f_upsample(constant FrameUniforms& frame [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], texture2d_array<float> src2 [[texture(3)]], texture2d_array<float> src3 [[texture(4)]], texture2d_array<float> src4 [[texture(5)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], sampler src2Smplr [[sampler(3)]], sampler src3Smplr [[sampler(4)]], sampler src4Smplr [[sampler(5)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]], uint gl_LocalInvocationIndex [[thread_index_in_threadgroup]], uint3 gl_WorkGroupID [[threadgroup_position_in_grid]])
{
    threadgroup float4 nao_tile_a[144];
    threadgroup float4 nao_tile_b[144];
    int2 gid = int2(gl_GlobalInvocationID.xy);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    int lid = int(gl_LocalInvocationIndex);
    int2 group0 = int2(gl_WorkGroupID.xy) * int2(8);
    int2 hi = out_size;
    int2 lo = nao_size(src2, src2Smplr);
    int2 param = min(group0, (out_size - int2(1)));
    int2 param_1 = out_size;
    int2 c0 = nao_texel(param, param_1, frame);
    int2 param_2 = min((group0 + int2(7)), (out_size - int2(1)));
    int2 param_3 = out_size;
    int2 c1 = nao_texel(param_2, param_3, frame);
    int2 param_4 = min(c0, c1);
    int2 param_5 = lo;
    int2 param_6 = hi;
    int2 t0 = nao_up_base(param_4, param_5, param_6);
    int2 param_7 = max(c0, c1);
    int2 param_8 = lo;
    int2 param_9 = hi;
    int2 t_size = (nao_up_base(param_7, param_8, param_9) + int2(4)) - t0;
    bool _295 = t_size.x <= 12;
    bool _301;
    if (_295)
    {
        _301 = t_size.y <= 12;
    }
    else
    {
        _301 = _295;
    }
    bool tiled = _301;
    if (tiled)
    {
        for (int k = lid; k < (t_size.x * t_size.y); k += 64)
        {
            int2 q = clamp(t0 + int2(k % t_size.x, k / t_size.x), int2(0), lo - int2(1));
            int2 param_10 = q;
            int param_11 = 0;
            nao_tile_a[k] = nao_load(src3, src3Smplr, param_10, param_11, frame);
            int2 param_12 = q;
            int param_13 = 1;
            int2 param_14 = q;
            int param_15 = 0;
            int2 param_16 = q;
            int param_17 = 2;
            nao_tile_b[k] = float4(nao_load(src3, src3Smplr, param_12, param_13, frame).xyz, nao_load(src2, src2Smplr, param_14, param_15, frame).x - nao_load(src3, src3Smplr, param_16, param_17, frame).x);
        }
    }
    threadgroup_barrier(mem_flags::mem_threadgroup);
    bool _380 = gid.x >= out_size.x;
    bool _389;
    if (!_380)
    {
        _389 = gid.y >= out_size.y;
    }
    else
    {
        _389 = _380;
    }
    if (_389)
    {
        return;
    }
    int2 param_18 = gid;
    int2 param_19 = out_size;
    int2 px = nao_texel(param_18, param_19, frame);
    int2 param_20 = px;
    int param_21 = 0;
    float z = nao_load(src0, src0Smplr, param_20, param_21, frame).x;
    if (!(z > 0.0))
    {
        int2 param_22 = px;
        int param_23 = 0;
        float4 param_24 = float4(1.0);
        nao_store(param_22, param_23, param_24, frame, dst);
        return;
    }
    int2 param_25 = px;
    int2 param_26 = out_size;
    float param_27 = z;
    float3 p = nao_position(param_25, param_26, param_27, frame);
    int2 param_28 = px;
    int param_29 = 0;
    float3 n = nao_load(src1, src1Smplr, param_28, param_29, frame).xyz;
    float depth = fast::max(z, 1.0000000031710768509710513471353e-30);
    float2 uv = (((float2(px) + float2(0.5)) * float2(lo)) / float2(hi)) - float2(0.5);
    int2 param_30 = px;
    int2 param_31 = lo;
    int2 param_32 = hi;
    int2 base = nao_up_base(param_30, param_31, param_32);
    float sum = 0.0;
    float total = 0.0;
    for (int y = 0; y < 4; y++)
    {
        for (int x = 0; x < 4; x++)
        {
            int2 o = base + int2(x, y);
            float4 qw = float4(0.0);
            float4 qv = float4(0.0);
            if (tiled)
            {
                int k_1 = ((o.y - t0.y) * t_size.x) + (o.x - t0.x);
                qw = nao_tile_a[k_1];
                qv = nao_tile_b[k_1];
            }
            else
            {
                int2 q_1 = clamp(o, int2(0), lo - int2(1));
                int2 param_33 = q_1;
                int param_34 = 0;
                qw = nao_load(src3, src3Smplr, param_33, param_34, frame);
                int2 param_35 = q_1;
                int param_36 = 1;
                int2 param_37 = q_1;
                int param_38 = 0;
                int2 param_39 = q_1;
                int param_40 = 2;
                qv = float4(nao_load(src3, src3Smplr, param_35, param_36, frame).xyz, nao_load(src2, src2Smplr, param_37, param_38, frame).x - nao_load(src3, src3Smplr, param_39, param_40, frame).x);
            }
            if (qw.w < 0.5)
            {
                continue;
            }
            float2 d = float2(o) - uv;
            float spatial = exp((-dot(d, d)) / 0.7200000286102294921875);
            float3 qn = qv.xyz;
            float plane = abs(dot(qn, p - qw.xyz)) / (0.02999999932944774627685546875 * depth);
            float agree = pow(fast::max(dot(qn, n), 0.0), 8.0);
            float w = spatial * (0.001000000047497451305389404296875 + (exp((-plane) * plane) * agree));
            sum += (w * qv.w);
            total += w;
        }
    }
    float up = 0.0;
    if (total > 0.0)
    {
        up = sum / total;
    }
    int2 param_41 = px;
    int param_42 = 0;
    int2 param_43 = px;
    int param_44 = 0;
    float4 param_45 = float4(fast::clamp(nao_load(src4, src4Smplr, param_41, param_42, frame).x + up, 0.0, 1.0));
    nao_store(param_43, param_44, param_45, frame, dst);
}

