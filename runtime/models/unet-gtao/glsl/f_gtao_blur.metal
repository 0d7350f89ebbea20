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
bool nao_inside(thread const int2& q, thread const int2& size)
{
    bool _115 = all(q >= int2(0));
    bool _122;
    if (_115)
    {
        _122 = all(q < size);
    }
    else
    {
        _122 = _115;
    }
    return _122;
}

kernel void f_gtao_blur(constant FrameUniforms& frame [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _141 = gid.x >= out_size.x;
    bool _150;
    if (!_141)
    {
        _150 = gid.y >= out_size.y;
    }
    else
    {
        _150 = _141;
    }
    if (_150)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1, frame);
    int2 param_2 = px;
    int param_3 = 0;
    if (!(nao_load(src0, src0Smplr, param_2, param_3, frame).x > 0.0))
    {
        int2 param_4 = px;
        int param_5 = 0;
        float4 param_6 = float4(1.0);
        nao_store(param_4, param_5, param_6, frame, dst);
        return;
    }
    float sum = 0.0;
    float count = 0.0;
    for (int y = -2; y < 2; y++)
    {
        for (int x = -2; x < 2; x++)
        {
            int2 q = px + int2(x, y);
            int2 param_7 = q;
            int2 param_8 = out_size;
            if (!nao_inside(param_7, param_8))
            {
                continue;
            }
            int2 param_9 = q;
            int param_10 = 0;
            if (!(nao_load(src0, src0Smplr, param_9, param_10, frame).x > 0.0))
            {
                continue;
            }
            int2 param_11 = q;
            int param_12 = 0;
            sum += nao_load(src1, src1Smplr, param_11, param_12, frame).x;
            count += 1.0;
        }
    }
    int2 param_13 = px;
    int param_14 = 0;
    float4 param_15 = float4(sum / fast::max(count, 1.0));
    nao_store(param_13, param_14, param_15, frame, dst);
}

