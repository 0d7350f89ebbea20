#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

kernel void p07_pool_avg(texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
        _52 = gid.z >= 2;
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
        bool _91 = iy < 0;
        bool _100;
        if (!_91)
        {
            _100 = iy >= (in_size.y + 0);
        }
        else
        {
            _100 = _91;
        }
        if (_100)
        {
            continue;
        }
        for (int kx = 0; kx < 2; kx++)
        {
            int ix = ((gid.x * 2) - 0) + (kx * 1);
            bool _121 = ix < 0;
            bool _130;
            if (!_121)
            {
                _130 = ix >= (in_size.x + 0);
            }
            else
            {
                _130 = _121;
            }
            if (_130)
            {
                continue;
            }
            count_padded++;
            bool _137 = iy < 0;
            bool _145;
            if (!_137)
            {
                _145 = iy >= in_size.y;
            }
            else
            {
                _145 = _137;
            }
            bool _148 = _145 || (ix < 0);
            bool _156;
            if (!_148)
            {
                _156 = ix >= in_size.x;
            }
            else
            {
                _156 = _148;
            }
            if (_156)
            {
                continue;
            }
            int3 _166 = int3(ix, iy, gid.z);
            float4 v = src0.read(uint2(_166.xy), uint(_166.z), 0);
            r += v;
            count++;
        }
    }
    r /= float4(float(max(count_padded, 1)));
    int3 _191 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_191.xy), uint(_191.z));
}

