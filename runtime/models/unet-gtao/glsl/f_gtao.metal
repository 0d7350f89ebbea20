#pragma clang diagnostic ignored "-Wmissing-prototypes"
#pragma clang diagnostic ignored "-Wmissing-braces"

#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

template<typename T, size_t Num>
struct spvUnsafeArray
{
    T elements[Num ? Num : 1];
    
    thread T& operator [] (size_t pos) thread
    {
        return elements[pos];
    }
    constexpr const thread T& operator [] (size_t pos) const thread
    {
        return elements[pos];
    }
    
    device T& operator [] (size_t pos) device
    {
        return elements[pos];
    }
    constexpr const device T& operator [] (size_t pos) const device
    {
        return elements[pos];
    }
    
    constexpr const constant T& operator [] (size_t pos) const constant
    {
        return elements[pos];
    }
    
    threadgroup T& operator [] (size_t pos) threadgroup
    {
        return elements[pos];
    }
    constexpr const threadgroup T& operator [] (size_t pos) const threadgroup
    {
        return elements[pos];
    }
};

struct FrameUniforms
{
    float2 u_proj;
    float u_radius;
    float u_pixels_per_unit;
    int u_flip_y;
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

constant spvUnsafeArray<float2, 16> _191 = spvUnsafeArray<float2, 16>({ float2(0.377857029438018798828125, 0.1678416728973388671875), float2(0.968745052814483642578125, 0.7069942951202392578125), float2(0.08153782784938812255859375, 0.599261462688446044921875), float2(0.0065644229762256145477294921875, 0.521755874156951904296875), float2(0.86076271533966064453125, 0.293343722820281982421875), float2(0.804016172885894775390625, 0.8365204334259033203125), float2(0.3537027537822723388671875, 0.930650174617767333984375), float2(0.732333123683929443359375, 0.747238457202911376953125), float2(0.65405738353729248046875, 0.18946956098079681396484375), float2(0.1374433934688568115234375, 0.517999827861785888671875), float2(0.4956852495670318603515625, 0.862544834613800048828125), float2(0.524612128734588623046875, 0.896280705928802490234375), float2(0.93087482452392578125, 0.195674479007720947265625), float2(0.2630412876605987548828125, 0.0488224588334560394287109375), float2(0.2038518488407135009765625, 0.999011993408203125), float2(0.585066139698028564453125, 0.251001894474029541015625) });

static inline __attribute__((always_inline))
int2 nao_texel(thread const int2& p, thread const int2& size, constant FrameUniforms& frame)
{
    int2 _62;
    if (frame.u_flip_y != 0)
    {
        _62 = p;
    }
    else
    {
        _62 = int2(p.x, (size.y - 1) - p.y);
    }
    return _62;
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
    int3 _99 = int3(nao_texel(param, param_1, frame), layer);
    return t.read(uint2(_99.xy), uint(_99.z), 0);
}

static inline __attribute__((always_inline))
void nao_store(thread const int2& p, thread const int& layer, thread const float4& v, constant FrameUniforms& frame, texture2d_array<float, access::write> dst)
{
    int2 param = p;
    int2 param_1 = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    int3 _118 = int3(nao_texel(param, param_1, frame), layer);
    dst.write(v, uint2(_118.xy), uint(_118.z));
}

static inline __attribute__((always_inline))
float2 nao_noise(thread const int2& p)
{
    return _191[((p.y % 4) * 4) + (p.x % 4)];
}

static inline __attribute__((always_inline))
float nao_acos(thread const float& x)
{
    return acos(fast::clamp(x, -1.0, 1.0));
}

static inline __attribute__((always_inline))
bool nao_inside(thread const int2& q, thread const int2& size)
{
    bool _124 = all(q >= int2(0));
    bool _131;
    if (_124)
    {
        _131 = all(q < size);
    }
    else
    {
        _131 = _124;
    }
    return _131;
}

kernel void f_gtao(constant FrameUniforms& frame [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _224 = gid.x >= out_size.x;
    bool _233;
    if (!_224)
    {
        _233 = gid.y >= out_size.y;
    }
    else
    {
        _233 = _224;
    }
    if (_233)
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
    float3 p = pw.xyz;
    int2 param_7 = px;
    int param_8 = 1;
    float3 n = nao_load(src0, src0Smplr, param_7, param_8, frame).xyz;
    float ln = length(n);
    if (ln > 9.9999996826552253889678874634872e-21)
    {
        n /= float3(ln);
    }
    else
    {
        n = float3(0.0, 0.0, 1.0);
    }
    float3 view_v = fast::normalize(-p);
    float radius_px = (frame.u_radius * frame.u_pixels_per_unit) / fast::max(-p.z, 1.0000000031710768509710513471353e-30);
    if (!(radius_px > 1.0))
    {
        int2 param_9 = px;
        int param_10 = 0;
        float4 param_11 = float4(1.0);
        nao_store(param_9, param_10, param_11, frame, dst);
        return;
    }
    int2 param_12 = px;
    float2 _noise = nao_noise(param_12);
    float falloff_range = 0.20000000298023223876953125 * frame.u_radius;
    float falloff_mul = (-1.0) / falloff_range;
    float falloff_add = ((frame.u_radius - falloff_range) / falloff_range) + 1.0;
    float min_s = 1.2999999523162841796875 / radius_px;
    float2 centre = float2(px) + float2(0.5);
    float visibility = 0.0;
    for (int slice = 0; slice < 4; slice++)
    {
        float phi = (float(slice) + _noise.x) * 0.785398185253143310546875;
        float2 omega = float2(cos(phi), sin(phi));
        float3 dir_v = float3(omega, 0.0);
        float3 ortho_v = dir_v - (view_v * dot(dir_v, view_v));
        float3 axis_v = fast::normalize(cross(dir_v, view_v));
        float3 proj_n = n - (axis_v * dot(n, axis_v));
        float proj_len = length(proj_n);
        float sign_n = -1.0;
        if (dot(ortho_v, proj_n) >= 0.0)
        {
            sign_n = 1.0;
        }
        float cos_n = fast::clamp(dot(proj_n, view_v) / fast::max(proj_len, 9.9999996826552253889678874634872e-21), 0.0, 1.0);
        float param_13 = cos_n;
        float ang_n = sign_n * nao_acos(param_13);
        float low0 = cos(ang_n + 1.57079637050628662109375);
        float low1 = cos(ang_n - 1.57079637050628662109375);
        float hc0 = low0;
        float hc1 = low1;
        for (int k = 0; k < 8; k++)
        {
            float s = (float(k) + _noise.y) / 8.0;
            s = min_s + (((1.0 - min_s) * s) * s);
            float2 off = omega * (s * radius_px);
            int2 q0 = int2(floor(centre + off));
            int2 q1 = int2(floor(centre - off));
            int2 param_14 = q0;
            int2 param_15 = out_size;
            if (nao_inside(param_14, param_15))
            {
                int2 param_16 = q0;
                int param_17 = 0;
                float4 sw = nao_load(src0, src0Smplr, param_16, param_17, frame);
                if (sw.w >= 0.5)
                {
                    float3 d = sw.xyz - p;
                    float dist = length(d);
                    if (dist > 1.0000000031710768509710513471353e-30)
                    {
                        float w = fast::clamp((dist * falloff_mul) + falloff_add, 0.0, 1.0);
                        hc0 = fast::max(hc0, mix(low0, dot(d / float3(dist), view_v), w));
                    }
                }
            }
            int2 param_18 = q1;
            int2 param_19 = out_size;
            if (nao_inside(param_18, param_19))
            {
                int2 param_20 = q1;
                int param_21 = 0;
                float4 sw_1 = nao_load(src0, src0Smplr, param_20, param_21, frame);
                if (sw_1.w >= 0.5)
                {
                    float3 d_1 = sw_1.xyz - p;
                    float dist_1 = length(d_1);
                    if (dist_1 > 1.0000000031710768509710513471353e-30)
                    {
                        float w_1 = fast::clamp((dist_1 * falloff_mul) + falloff_add, 0.0, 1.0);
                        hc1 = fast::max(hc1, mix(low1, dot(d_1 / float3(dist_1), view_v), w_1));
                    }
                }
            }
        }
        float param_22 = hc1;
        float h0 = -nao_acos(param_22);
        float param_23 = hc0;
        float h1 = nao_acos(param_23);
        h0 = ang_n + fast::clamp(h0 - ang_n, -1.57079637050628662109375, 1.57079637050628662109375);
        h1 = ang_n + fast::clamp(h1 - ang_n, -1.57079637050628662109375, 1.57079637050628662109375);
        float sin_n = sin(ang_n);
        float arc0 = ((cos_n + ((2.0 * h0) * sin_n)) - cos((2.0 * h0) - ang_n)) * 0.25;
        float arc1 = ((cos_n + ((2.0 * h1) * sin_n)) - cos((2.0 * h1) - ang_n)) * 0.25;
        visibility += (proj_len * (arc0 + arc1));
    }
    int2 param_24 = px;
    int param_25 = 0;
    float4 param_26 = float4(fast::clamp(visibility / 4.0, 0.0, 1.0));
    nao_store(param_24, param_25, param_26, frame, dst);
}

