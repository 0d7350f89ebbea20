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

kernel void p02_conv(constant int& u_flip_y [[buffer(0)]], const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
        _72 = gid.z >= 2;
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
    int2 size0 = ((src_size0 + int2(7)) / int2(8)) * int2(8);
    int2 size1 = int3(src1.get_width(), src1.get_height(), src1.get_array_size()).xy;
    float4 acc = float4(params.prm[144 + gid.z]);
    for (int ky = 0; ky < 3; ky++)
    {
        int iy = ((gid.y * 1) - 1) + (ky * 1);
        for (int kx = 0; kx < 3; kx++)
        {
            int ix = ((gid.x * 1) - 1) + (kx * 1);
            int tap = 0 + (((((gid.z * 3) + ky) * 3) + kx) * 8);
            bool _165 = iy >= 0;
            bool _172;
            if (_165)
            {
                _172 = iy < size0.y;
            }
            else
            {
                _172 = _165;
            }
            bool _175 = _172 && (ix >= 0);
            bool _182;
            if (_175)
            {
                _182 = ix < size0.x;
            }
            else
            {
                _182 = _175;
            }
            if (_182)
            {
                int rx = clamp((src_size0.x - 1) - abs((src_size0.x - 1) - ix), 0, src_size0.x - 1);
                int ry = clamp((src_size0.y - 1) - abs((src_size0.y - 1) - iy), 0, src_size0.y - 1);
                if (u_flip_y != 0)
                {
                    ry = (src_size0.y - 1) - ry;
                }
                for (int l = 0; l < 1; l++)
                {
                    int3 _239 = int3(rx, ry, l);
                    float4 v = src0.read(uint2(_239.xy), uint(_239.z), 0);
                    int o = tap + ((0 + l) * 4);
                    float4x4 _286 = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += (float4x4(_286[0], _286[1], _286[2], _286[3]) * float4(v));
                }
            }
            bool _304 = iy >= 0;
            bool _311;
            if (_304)
            {
                _311 = iy < size1.y;
            }
            else
            {
                _311 = _304;
            }
            bool _314 = _311 && (ix >= 0);
            bool _321;
            if (_314)
            {
                _321 = ix < size1.x;
            }
            else
            {
                _321 = _314;
            }
            if (_321)
            {
                for (int l_1 = 0; l_1 < 1; l_1++)
                {
                    int3 _337 = int3(ix, iy, l_1);
                    float4 v_1 = src1.read(uint2(_337.xy), uint(_337.z), 0);
                    int o_1 = tap + ((1 + l_1) * 4);
                    float4x4 _381 = float4x4(float4(params.prm[o_1]), float4(params.prm[o_1 + 1]), float4(params.prm[o_1 + 2]), float4(params.prm[o_1 + 3]));
                    acc += (float4x4(_381[0], _381[1], _381[2], _381[3]) * float4(v_1));
                }
            }
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    float param_1 = 0.00999999977648258209228515625;
    r = nao_leaky_relu(param, param_1);
    int3 _421 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_421.xy), uint(_421.z));
}

