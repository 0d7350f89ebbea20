#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

kernel void p09_pool_avg(texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
        _52 = gid.z >= 4;
    }
    else
    {
        _52 = _43;
    }
    if (_52)
    {
        return;
    }
    int2 in_size = int3(src0.get_width(), src0.get_height(), src0.get_array_size()).xy;
    float4 r = float4(0.0);
    int count = 0;
    int count_padded = 0;
    for (int ky = 0; ky < 2; ky++)
    {
        int iy = ((gid.y * 2) - 0) + (ky * 1);
        bool _92 = iy < 0;
        bool _101;
        if (!_92)
        {
            _101 = iy >= (in_size.y + 0);
        }
        else
        {
            _101 = _92;
        }
        if (_101)
        {
            continue;
        }
        for (int kx = 0; kx < 2; kx++)
        {
            int ix = ((gid.x * 2) - 0) + (kx * 1);
            bool _122 = ix < 0;
            bool _131;
            if (!_122)
            {
                _131 = ix >= (in_size.x + 0);
            }
            else
            {
                _131 = _122;
            }
            if (_131)
            {
                continue;
            }
            count_padded++;
            bool _138 = iy < 0;
            bool _146;
            if (!_138)
            {
                _146 = iy >= in_size.y;
            }
            else
            {
                _146 = _138;
            }
            bool _149 = _146 || (ix < 0);
            bool _157;
            if (!_149)
            {
                _157 = ix >= in_size.x;
            }
            else
            {
                _157 = _149;
            }
            if (_157)
            {
                continue;
            }
            int3 _167 = int3(ix, iy, gid.z);
            float4 v = src0.read(uint2(_167.xy), uint(_167.z), 0);
            r += v;
            count++;
        }
    }
    r /= float4(float(max(count_padded, 1)));
    int3 _192 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_192.xy), uint(_192.z));
}

