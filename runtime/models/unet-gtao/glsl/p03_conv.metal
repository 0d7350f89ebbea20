#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

struct Params
{
    float4 prm[1];
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

kernel void p03_conv(const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
    int2 size1 = int3(src1.get_width(), src1.get_height(), src1.get_array_size()).xy;
    float4 acc = float4(params.prm[12 + gid.z]);
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 12);
            bool _135 = iy >= 0;
            bool _142;
            if (_135)
            {
                _142 = iy < size0.y;
            }
            else
            {
                _142 = _135;
            }
            bool _145 = _142 && (ix >= 0);
            bool _152;
            if (_145)
            {
                _152 = ix < size0.x;
            }
            else
            {
                _152 = _145;
            }
            if (_152)
            {
                for (int l = 0; l < 2; l++)
                {
                    int3 _169 = int3(ix, iy, l);
                    float4 v = src0.read(uint2(_169.xy), uint(_169.z), 0);
                    int o = tap + ((0 + l) * 4);
                    float4x4 _218 = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += (float4x4(_218[0], _218[1], _218[2], _218[3]) * float4(v));
                }
            }
            bool _236 = iy >= 0;
            bool _243;
            if (_236)
            {
                _243 = iy < size1.y;
            }
            else
            {
                _243 = _236;
            }
            bool _246 = _243 && (ix >= 0);
            bool _253;
            if (_246)
            {
                _253 = ix < size1.x;
            }
            else
            {
                _253 = _246;
            }
            if (_253)
            {
                for (int l_1 = 0; l_1 < 1; l_1++)
                {
                    int3 _269 = int3(ix, iy, l_1);
                    float4 v_1 = src1.read(uint2(_269.xy), uint(_269.z), 0);
                    int o_1 = tap + ((2 + l_1) * 4);
                    float4x4 _313 = float4x4(float4(params.prm[o_1]), float4(params.prm[o_1 + 1]), float4(params.prm[o_1 + 2]), float4(params.prm[o_1 + 3]));
                    acc += (float4x4(_313[0], _313[1], _313[2], _313[3]) * float4(v_1));
                }
            }
        }
    }
    float4 r = float4(acc);
    int3 _348 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_348.xy), uint(_348.z));
}

