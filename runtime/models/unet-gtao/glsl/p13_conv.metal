#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

struct Params
{
    float4 prm[1];
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

kernel void p13_conv(constant int& u_flip_y [[buffer(0)]], const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int3 gid = int3(gl_GlobalInvocationID);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    bool _33 = gid.x >= out_size.x;
    bool _43;
    if (!_33)
    {
        _43 = gid.y >= out_size.y;
    }
    else
    {
        _43 = _33;
    }
    bool _52;
    if (!_43)
    {
        _52 = gid.z >= 1;
    }
    else
    {
        _52 = _43;
    }
    if (_52)
    {
        return;
    }
    int2 size0 = int3(src0.get_width(), src0.get_height(), src0.get_array_size()).xy;
    float4 acc = float4(params.prm[4 + gid.z]);
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 4);
            bool _129 = iy >= 0;
            bool _136;
            if (_129)
            {
                _136 = iy < size0.y;
            }
            else
            {
                _136 = _129;
            }
            bool _139 = _136 && (ix >= 0);
            bool _146;
            if (_139)
            {
                _146 = ix < size0.x;
            }
            else
            {
                _146 = _139;
            }
            if (_146)
            {
                for (int l = 0; l < 1; l++)
                {
                    int3 _162 = int3(ix, iy, l);
                    float4 v = src0.read(uint2(_162.xy), uint(_162.z), 0);
                    int o = tap + ((0 + l) * 4);
                    float4x4 _211 = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += (float4x4(_211[0], _211[1], _211[2], _211[3]) * float4(v));
                }
            }
        }
    }
    float4 r = float4(acc);
    int3 _248 = int3(gid.xy, gid.z);
    float4 a = src1.read(uint2(_248.xy), uint(_248.z), 0);
    float4 b = r;
    r = a + b;
    r = fast::min(fast::max(r, float4(0.0)), float4(1.0));
    int _268;
    if (u_flip_y != 0)
    {
        _268 = (out_size.y - 1) - gid.y;
    }
    else
    {
        _268 = gid.y;
    }
    int3 _286 = int3(int2(gid.x, _268), gid.z);
    dst.write(r, uint2(_286.xy), uint(_286.z));
}

