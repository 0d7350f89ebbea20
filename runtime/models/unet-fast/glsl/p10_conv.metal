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

kernel void p10_conv(const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
        _72 = gid.z >= 4;
    }
    else
    {
        _72 = _63;
    }
    if (_72)
    {
        return;
    }
    int2 size0 = int3(src0.get_width(), src0.get_height(), src0.get_array_size()).xy;
    int2 size1 = int3(src1.get_width(), src1.get_height(), src1.get_array_size()).xy;
    float4 acc = params.prm[1152 + gid.z];
    for (int ky = 0; ky < 3; ky++)
    {
        int iy = ((gid.y * 1) - 1) + (ky * 1);
        for (int kx = 0; kx < 3; kx++)
        {
            int ix = ((gid.x * 1) - 1) + (kx * 1);
            int tap = 0 + (((((gid.z * 3) + ky) * 3) + kx) * 32);
            bool _151 = iy >= 0;
            bool _158;
            if (_151)
            {
                _158 = iy < size0.y;
            }
            else
            {
                _158 = _151;
            }
            bool _161 = _158 && (ix >= 0);
            bool _168;
            if (_161)
            {
                _168 = ix < size0.x;
            }
            else
            {
                _168 = _161;
            }
            if (_168)
            {
                for (int l = 0; l < 4; l++)
                {
                    int3 _184 = int3(ix, iy, l);
                    float4 v = src0.read(uint2(_184.xy), uint(_184.z), 0);
                    int o = tap + ((0 + l) * 4);
                    float4x4 w = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += float4(float4x4(w[0], w[1], w[2], w[3]) * float4(v));
                }
            }
            bool _257 = iy >= 0;
            bool _264;
            if (_257)
            {
                _264 = iy < size1.y;
            }
            else
            {
                _264 = _257;
            }
            bool _267 = _264 && (ix >= 0);
            bool _274;
            if (_267)
            {
                _274 = ix < size1.x;
            }
            else
            {
                _274 = _267;
            }
            if (_274)
            {
                for (int l_1 = 0; l_1 < 4; l_1++)
                {
                    int3 _290 = int3(ix, iy, l_1);
                    float4 v_1 = src1.read(uint2(_290.xy), uint(_290.z), 0);
                    int o_1 = tap + ((4 + l_1) * 4);
                    float4x4 w_1 = float4x4(float4(params.prm[o_1]), float4(params.prm[o_1 + 1]), float4(params.prm[o_1 + 2]), float4(params.prm[o_1 + 3]));
                    acc += float4(float4x4(w_1[0], w_1[1], w_1[2], w_1[3]) * float4(v_1));
                }
            }
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    float param_1 = 0.00999999977648258209228515625;
    r = nao_leaky_relu(param, param_1);
    int3 _381 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_381.xy), uint(_381.z));
}

