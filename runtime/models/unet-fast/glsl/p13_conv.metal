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
float4 nao_sigmoid(thread const float4& x)
{
    float4 e = exp(-abs(x));
    float4 r = float4(1.0) / (float4(1.0) + e);
    return select(e * r, r, x >= float4(0.0));
}

kernel void p13_conv(constant int& u_flip_y [[buffer(0)]], const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int3 gid = int3(gl_GlobalInvocationID);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _63 = gid.x >= out_size.x;
    bool _73;
    if (!_63)
    {
        _73 = gid.y >= out_size.y;
    }
    else
    {
        _73 = _63;
    }
    bool _82;
    if (!_73)
    {
        _82 = gid.z >= 1;
    }
    else
    {
        _82 = _73;
    }
    if (_82)
    {
        return;
    }
    int2 size0 = int3(src0.get_width(), src0.get_height(), src0.get_array_size()).xy;
    float4 acc = params.prm[8 + gid.z];
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 8);
            bool _152 = iy >= 0;
            bool _159;
            if (_152)
            {
                _159 = iy < size0.y;
            }
            else
            {
                _159 = _152;
            }
            bool _162 = _159 && (ix >= 0);
            bool _169;
            if (_162)
            {
                _169 = ix < size0.x;
            }
            else
            {
                _169 = _162;
            }
            if (_169)
            {
                for (int l = 0; l < 2; l++)
                {
                    int3 _186 = int3(ix, iy, l);
                    float4 v = src0.read(uint2(_186.xy), uint(_186.z), 0);
                    int o = tap + ((0 + l) * 4);
                    float4x4 w = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += float4(float4x4(w[0], w[1], w[2], w[3]) * float4(v));
                }
            }
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    r = nao_sigmoid(param);
    int _279;
    if (u_flip_y != 0)
    {
        _279 = (out_size.y - 1) - gid.y;
    }
    else
    {
        _279 = gid.y;
    }
    int3 _297 = int3(int2(gid.x, _279), gid.z);
    dst.write(r, uint2(_297.xy), uint(_297.z));
}

