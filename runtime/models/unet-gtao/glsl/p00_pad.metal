#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

kernel void p00_pad(constant int& u_flip_y [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
    int _72;
    if (gid.x < in_size.x)
    {
        _72 = gid.x;
    }
    else
    {
        _72 = (2 * (in_size.x - 1)) - gid.x;
    }
    int x = _72;
    int _93;
    if (gid.y < in_size.y)
    {
        _93 = gid.y;
    }
    else
    {
        _93 = (2 * (in_size.y - 1)) - gid.y;
    }
    int y = _93;
    x = clamp(x, 0, in_size.x - 1);
    y = clamp(y, 0, in_size.y - 1);
    if (u_flip_y != 0)
    {
        y = (in_size.y - 1) - y;
    }
    int3 _136 = int3(x, y, gid.z);
    float4 r = src0.read(uint2(_136.xy), uint(_136.z), 0);
    r = select(float4(0.0), r, (int4(4 * gid.z) + int4(0, 1, 2, 3)) < int4(5));
    int3 _163 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_163.xy), uint(_163.z));
}

