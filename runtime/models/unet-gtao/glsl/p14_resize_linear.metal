#pragma clang diagnostic ignored "-Wmissing-prototypes"

#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

template<typename T>
[[clang::optnone]] T spvFAdd(T l, T r)
{
    return fma(T(1), l, r);
}

template<typename T>
[[clang::optnone]] T spvFSub(T l, T r)
{
    return fma(T(-1), r, l);
}

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

static inline __attribute__((always_inline))
float nao_div(thread const float& a, thread const float& b)
{
    float q = a / b;
    float r = fma(-q, b, a);
    float d = spvFAdd(q, r / b);
    return d;
}

kernel void p14_resize_linear(texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int3 gid = int3(gl_GlobalInvocationID);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _58 = gid.x >= out_size.x;
    bool _68;
    if (!_58)
    {
        _68 = gid.y >= out_size.y;
    }
    else
    {
        _68 = _58;
    }
    bool _77;
    if (!_68)
    {
        _77 = gid.z >= 4;
    }
    else
    {
        _77 = _68;
    }
    if (_77)
    {
        return;
    }
    int2 in_size = int3(src0.get_width(), src0.get_height(), src0.get_array_size()).xy;
    float param = spvFAdd(float(gid.y), 0.5);
    float param_1 = 2.0;
    float fy = spvFSub(nao_div(param, param_1), 0.5);
    float param_2 = spvFAdd(float(gid.x), 0.5);
    float param_3 = 2.0;
    float fx = spvFSub(nao_div(param_2, param_3), 0.5);
    fy = fast::clamp(fy, 0.0, float(in_size.y - 1));
    fx = fast::clamp(fx, 0.0, float(in_size.x - 1));
    int y0 = int(fy);
    int x0 = int(fx);
    int y1 = min((y0 + 1), (in_size.y - 1));
    int x1 = min((x0 + 1), (in_size.x - 1));
    float wy = fy - float(y0);
    float wx = fx - float(x0);
    int3 _163 = int3(x0, y0, gid.z);
    float4 a = src0.read(uint2(_163.xy), uint(_163.z), 0);
    int3 _172 = int3(x1, y0, gid.z);
    float4 b = src0.read(uint2(_172.xy), uint(_172.z), 0);
    int3 _181 = int3(x0, y1, gid.z);
    float4 c = src0.read(uint2(_181.xy), uint(_181.z), 0);
    int3 _190 = int3(x1, y1, gid.z);
    float4 d = src0.read(uint2(_190.xy), uint(_190.z), 0);
    float4 r = (((a * (1.0 - wx)) + (b * wx)) * (1.0 - wy)) + (((c * (1.0 - wx)) + (d * wx)) * wy);
    if (false)
    {
        r = float4(0.0);
    }
    int3 _228 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_228.xy), uint(_228.z));
}

