#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

struct Params
{
    float4 prm[1];
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

kernel void p01_conv(constant int& u_flip_y [[buffer(0)]], const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
    int2 src_size0 = int3(src0.get_width(), src0.get_height(), src0.get_array_size()).xy;
    int2 size0 = ((src_size0 + int2(7)) / int2(8)) * int2(8);
    float4 acc = float4(params.prm[8 + gid.z]);
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 8);
            bool _138 = iy >= 0;
            bool _145;
            if (_138)
            {
                _145 = iy < size0.y;
            }
            else
            {
                _145 = _138;
            }
            bool _148 = _145 && (ix >= 0);
            bool _155;
            if (_148)
            {
                _155 = ix < size0.x;
            }
            else
            {
                _155 = _148;
            }
            if (_155)
            {
                int rx = clamp((src_size0.x - 1) - abs((src_size0.x - 1) - ix), 0, src_size0.x - 1);
                int ry = clamp((src_size0.y - 1) - abs((src_size0.y - 1) - iy), 0, src_size0.y - 1);
                if (u_flip_y != 0)
                {
                    ry = (src_size0.y - 1) - ry;
                }
                for (int l = 0; l < 2; l++)
                {
                    int3 _215 = int3(rx, ry, l);
                    float4 v = select(float4(0.0), src0.read(uint2(_215.xy), uint(_215.z), 0), (int4(4 * l) + int4(0, 1, 2, 3)) < int4(5));
                    int o = tap + ((0 + l) * 4);
                    float4x4 _274 = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += (float4x4(_274[0], _274[1], _274[2], _274[3]) * float4(v));
                }
            }
        }
    }
    float4 r = float4(acc);
    r = fast::max(r, float4(0.001000000047497451305389404296875));
    int3 _311 = int3(0, 0, gid.z);
    float4 a = src1.read(uint2(_311.xy), uint(_311.z), 0);
    float4 b = r;
    b = select(float4(1.0), b, (int4(4 * gid.z) + int4(0, 1, 2, 3)) < int4(1));
    r = a / b;
    r = fast::min(fast::max(r, float4(0.0)), float4(8.0));
    int3 _341 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_341.xy), uint(_341.z));
}

