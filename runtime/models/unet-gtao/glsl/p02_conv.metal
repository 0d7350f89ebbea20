#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

struct Params
{
    float4 prm[1];
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

kernel void p02_conv(constant int& u_flip_y [[buffer(0)]], const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
    int2 size1 = int3(src1.get_width(), src1.get_height(), src1.get_array_size()).xy;
    float4 acc = float4(params.prm[12 + gid.z]);
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 12);
            bool _145 = iy >= 0;
            bool _152;
            if (_145)
            {
                _152 = iy < size0.y;
            }
            else
            {
                _152 = _145;
            }
            bool _155 = _152 && (ix >= 0);
            bool _162;
            if (_155)
            {
                _162 = ix < size0.x;
            }
            else
            {
                _162 = _155;
            }
            if (_162)
            {
                int rx = clamp((src_size0.x - 1) - abs((src_size0.x - 1) - ix), 0, src_size0.x - 1);
                int ry = clamp((src_size0.y - 1) - abs((src_size0.y - 1) - iy), 0, src_size0.y - 1);
                if (u_flip_y != 0)
                {
                    ry = (src_size0.y - 1) - ry;
                }
                for (int l = 0; l < 2; l++)
                {
                    int3 _222 = int3(rx, ry, l);
                    float4 v = select(float4(0.0), src0.read(uint2(_222.xy), uint(_222.z), 0), (int4(4 * l) + int4(0, 1, 2, 3)) < int4(5));
                    int o = tap + ((0 + l) * 4);
                    float4x4 _281 = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += (float4x4(_281[0], _281[1], _281[2], _281[3]) * float4(v));
                }
            }
            bool _299 = iy >= 0;
            bool _306;
            if (_299)
            {
                _306 = iy < size1.y;
            }
            else
            {
                _306 = _299;
            }
            bool _309 = _306 && (ix >= 0);
            bool _316;
            if (_309)
            {
                _316 = ix < size1.x;
            }
            else
            {
                _316 = _309;
            }
            if (_316)
            {
                for (int l_1 = 0; l_1 < 1; l_1++)
                {
                    int3 _332 = int3(ix, iy, l_1);
                    float4 v_1 = src1.read(uint2(_332.xy), uint(_332.z), 0);
                    int o_1 = tap + ((2 + l_1) * 4);
                    float4x4 _376 = float4x4(float4(params.prm[o_1]), float4(params.prm[o_1 + 1]), float4(params.prm[o_1 + 2]), float4(params.prm[o_1 + 3]));
                    acc += (float4x4(_376[0], _376[1], _376[2], _376[3]) * float4(v_1));
                }
            }
        }
    }
    float4 r = float4(acc);
    int3 _411 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_411.xy), uint(_411.z));
}

