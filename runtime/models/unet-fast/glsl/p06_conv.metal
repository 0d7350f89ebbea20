#pragma clang diagnostic ignored "-Wmissing-prototypes"

#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

struct Params
{
    float4 prm[1];
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

static inline __attribute__((always_inline))
float4 nao_leaky_relu(thread const float4& x, thread const float& alpha)
{
    return select(x * alpha, x, x >= float4(0.0));
}

kernel void p06_conv(const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int3 gid = int3(gl_GlobalInvocationID);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _53 = gid.x >= out_size.x;
    bool _63;
    if (!_53)
    {
        _63 = gid.y >= out_size.y;
    }
    else
    {
        _63 = _53;
    }
    bool _72;
    if (!_63)
    {
        _72 = gid.z >= 16;
    }
    else
    {
        _72 = _63;
    }
    if (_72)
    {
        return;
    }
    int2 src_size0 = int3(src0.get_width(), src0.get_height(), src0.get_array_size()).xy;
    int2 size0 = src_size0 / int2(2);
    float4 acc = params.prm[4608 + gid.z];
    for (int ky = 0; ky < 3; ky++)
    {
        int iy = ((gid.y * 1) - 1) + (ky * 1);
        for (int kx = 0; kx < 3; kx++)
        {
            int ix = ((gid.x * 1) - 1) + (kx * 1);
            int tap = 0 + (((((gid.z * 3) + ky) * 3) + kx) * 32);
            bool _150 = iy >= 0;
            bool _157;
            if (_150)
            {
                _157 = iy < size0.y;
            }
            else
            {
                _157 = _150;
            }
            bool _160 = _157 && (ix >= 0);
            bool _167;
            if (_160)
            {
                _167 = ix < size0.x;
            }
            else
            {
                _167 = _160;
            }
            if (_167)
            {
                for (int l = 0; l < 8; l++)
                {
                    int3 _186 = int3(2 * ix, 2 * iy, l);
                    int3 _196 = int3((2 * ix) + 1, 2 * iy, l);
                    int3 _207 = int3(2 * ix, (2 * iy) + 1, l);
                    int3 _219 = int3((2 * ix) + 1, (2 * iy) + 1, l);
                    float4 v = (((src0.read(uint2(_186.xy), uint(_186.z), 0) + src0.read(uint2(_196.xy), uint(_196.z), 0)) + src0.read(uint2(_207.xy), uint(_207.z), 0)) + src0.read(uint2(_219.xy), uint(_219.z), 0)) / float4(4.0);
                    int o = tap + ((0 + l) * 4);
                    float4x4 w = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += float4(float4x4(w[0], w[1], w[2], w[3]) * float4(v));
                }
            }
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    float param_1 = 0.00999999977648258209228515625;
    r = nao_leaky_relu(param, param_1);
    int3 _318 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_318.xy), uint(_318.z));
}

