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
        _72 = gid.z >= 8;
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
    int2 size0 = src_size0 * int2(2);
    float4 acc = float4(params.prm[4608 + gid.z]);
    for (int ky = 0; ky < 3; ky++)
    {
        int iy = ((gid.y * 1) - 1) + (ky * 1);
        for (int kx = 0; kx < 3; kx++)
        {
            int ix = ((gid.x * 1) - 1) + (kx * 1);
            int tap = 0 + (((((gid.z * 3) + ky) * 3) + kx) * 64);
            bool _155 = iy >= 0;
            bool _162;
            if (_155)
            {
                _162 = iy < size0.y;
            }
            else
            {
                _162 = _155;
            }
            bool _165 = _162 && (ix >= 0);
            bool _172;
            if (_165)
            {
                _172 = ix < size0.x;
            }
            else
            {
                _172 = _165;
            }
            if (_172)
            {
                float fy = fast::clamp((float(iy) * 0.5) - 0.25, 0.0, float(src_size0.y - 1));
                float fx = fast::clamp((float(ix) * 0.5) - 0.25, 0.0, float(src_size0.x - 1));
                int y0 = int(fy);
                int x0 = int(fx);
                int y1 = min((y0 + 1), (src_size0.y - 1));
                int x1 = min((x0 + 1), (src_size0.x - 1));
                float wy = fy - float(y0);
                float wx = fx - float(x0);
                for (int l = 0; l < 16; l++)
                {
                    int3 _241 = int3(x0, y0, l);
                    int3 _252 = int3(x1, y0, l);
                    int3 _265 = int3(x0, y1, l);
                    int3 _275 = int3(x1, y1, l);
                    float4 v = (((src0.read(uint2(_241.xy), uint(_241.z), 0) * (1.0 - wx)) + (src0.read(uint2(_252.xy), uint(_252.z), 0) * wx)) * (1.0 - wy)) + (((src0.read(uint2(_265.xy), uint(_265.z), 0) * (1.0 - wx)) + (src0.read(uint2(_275.xy), uint(_275.z), 0) * wx)) * wy);
                    int o = tap + ((0 + l) * 4);
                    float4x4 _327 = float4x4(float4(params.prm[o]), float4(params.prm[o + 1]), float4(params.prm[o + 2]), float4(params.prm[o + 3]));
                    acc += (float4x4(_327[0], _327[1], _327[2], _327[3]) * float4(v));
                }
            }
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    float param_1 = 0.00999999977648258209228515625;
    r = nao_leaky_relu(param, param_1);
    int3 _367 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_367.xy), uint(_367.z));
}

