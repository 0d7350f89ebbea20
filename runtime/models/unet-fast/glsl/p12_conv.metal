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

kernel void p12_conv(constant int& u_flip_y [[buffer(0)]], const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
    float4 acc = float4(params.prm[8 + gid.z]);
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 8);
            bool _157 = iy >= 0;
            bool _164;
            if (_157)
            {
                _164 = iy < size0.y;
            }
            else
            {
                _164 = _157;
            }
            bool _167 = _164 && (ix >= 0);
            bool _174;
            if (_167)
            {
                _174 = ix < size0.x;
            }
            else
            {
                _174 = _167;
            }
            if (_174)
            {
                for (int l = 0; l < 2; l++)
                {
                    int3 _191 = int3(ix, iy, l);
                    float4 v = src0.read(uint2(_191.xy), uint(_191.z), 0);
                    int o = tap + ((0 + l) * 4);
                    float4x4 _238 = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += (float4x4(_238[0], _238[1], _238[2], _238[3]) * float4(v));
                }
            }
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    r = nao_sigmoid(param);
    int _276;
    if (u_flip_y != 0)
    {
        _276 = (out_size.y - 1) - gid.y;
    }
    else
    {
        _276 = gid.y;
    }
    int3 _294 = int3(int2(gid.x, _276), gid.z);
    dst.write(r, uint2(_294.xy), uint(_294.z));
}

