#pragma clang diagnostic ignored "-Wmissing-prototypes"
#pragma clang diagnostic ignored "-Wmissing-braces"

#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

template<typename T, size_t Num>
struct spvUnsafeArray
{
    T elements[Num ? Num : 1];
    
    thread T& operator [] (size_t pos) thread
    {
        return elements[pos];
    }
    constexpr const thread T& operator [] (size_t pos) const thread
    {
        return elements[pos];
    }
    
    device T& operator [] (size_t pos) device
    {
        return elements[pos];
    }
    constexpr const device T& operator [] (size_t pos) const device
    {
        return elements[pos];
    }
    
    constexpr const constant T& operator [] (size_t pos) const constant
    {
        return elements[pos];
    }
    
    threadgroup T& operator [] (size_t pos) threadgroup
    {
        return elements[pos];
    }
    constexpr const threadgroup T& operator [] (size_t pos) const threadgroup
    {
        return elements[pos];
    }
};

struct Params
{
    float4 prm[1];
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

kernel void p02_pointwise(constant int& u_flip_y [[buffer(0)]], const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
    int2 src_size0 = int3(src0.get_width(), src0.get_height(), src0.get_array_size()).xy;
    int2 size0 = ((src_size0 + int2(7)) / int2(8)) * int2(8);
    int ix = gid.x;
    int iy = gid.y;
    int rx = clamp((src_size0.x - 1) - abs((src_size0.x - 1) - ix), 0, src_size0.x - 1);
    int ry = clamp((src_size0.y - 1) - abs((src_size0.y - 1) - iy), 0, src_size0.y - 1);
    if (u_flip_y != 0)
    {
        ry = (src_size0.y - 1) - ry;
    }
    int3 _132 = int3(rx, ry, 0);
    float4 a = select(float4(0.0), src0.read(uint2(_132.xy), uint(_132.z), 0), bool4(true));
    int3 _143 = int3(rx, ry, 0);
    float4 b = select(float4(0.0), src0.read(uint2(_143.xy), uint(_143.z), 0), bool4(true));
    float4 r = a * b;
    spvUnsafeArray<float4, 2> v0;
    v0[0] = r;
    int3 _160 = int3(rx, ry, 1);
    float4 a_1 = select(float4(0.0), src0.read(uint2(_160.xy), uint(_160.z), 0), bool4(true, true, false, false));
    int3 _170 = int3(rx, ry, 1);
    float4 b_1 = select(float4(0.0), src0.read(uint2(_170.xy), uint(_170.z), 0), bool4(true, true, false, false));
    float4 r_1 = a_1 * b_1;
    v0[1] = r_1;
    float4 r_2 = params.prm[8];
    r_2 += (float4x4(float4(params.prm[0]), float4(params.prm[1]), float4(params.prm[2]), float4(params.prm[3])) * v0[0]);
    r_2 += (float4x4(float4(params.prm[4]), float4(params.prm[5]), float4(params.prm[6]), float4(params.prm[7])) * v0[1]);
    r_2 = fast::min(fast::max(r_2, float4(0.0)), float4(1.0));
    spvUnsafeArray<float4, 1> v1;
    v1[0] = r_2;
    float4 r_3 = params.prm[17];
    int3 _311 = int3(rx, ry, 0);
    r_3 += (float4x4(float4(params.prm[9]), float4(params.prm[10]), float4(params.prm[11]), float4(params.prm[12])) * select(float4(0.0), src0.read(uint2(_311.xy), uint(_311.z), 0), bool4(true)));
    int3 _354 = int3(rx, ry, 1);
    r_3 += (float4x4(float4(params.prm[13]), float4(params.prm[14]), float4(params.prm[15]), float4(params.prm[16])) * select(float4(0.0), src0.read(uint2(_354.xy), uint(_354.z), 0), bool4(true, true, false, false)));
    spvUnsafeArray<float4, 1> v2;
    v2[0] = r_3;
    float4 a_2 = v2[0];
    float4 b_2 = src1.read(uint2(int3(0).xy), uint(int3(0).z), 0);
    float4 r_4 = a_2 - b_2;
    spvUnsafeArray<float4, 1> v3;
    v3[0] = r_4;
    float4 a_3 = v3[0];
    float4 b_3 = v1[0];
    float4 r_5 = a_3 * b_3;
    spvUnsafeArray<float4, 1> v4;
    v4[0] = r_5;
    float4 a_4 = v4[0];
    float4 b_4 = v2[0];
    float4 r_6 = a_4 - b_4;
    spvUnsafeArray<float4, 1> v5;
    v5[0] = r_6;
    float4 r_7 = params.prm[26];
    r_7 += (float4x4(float4(params.prm[18]), float4(params.prm[19]), float4(params.prm[20]), float4(params.prm[21])) * v5[0]);
    int3 _452 = int3(rx, ry, 0);
    float4 a_5 = select(float4(0.0), src0.read(uint2(_452.xy), uint(_452.z), 0), bool4(true));
    float4 b_5 = r_7;
    r_7 = a_5 + b_5;
    spvUnsafeArray<float4, 2> v6;
    v6[0] = r_7;
    float4 r_8 = params.prm[27];
    r_8 += (float4x4(float4(params.prm[22]), float4(params.prm[23]), float4(params.prm[24]), float4(params.prm[25])) * v5[0]);
    int3 _510 = int3(rx, ry, 1);
    float4 a_6 = select(float4(0.0), src0.read(uint2(_510.xy), uint(_510.z), 0), bool4(true, true, false, false));
    float4 b_6 = r_8;
    r_8 = a_6 + b_6;
    v6[1] = r_8;
    float4 r_9 = v6[gid.z];
    int3 _533 = int3(gid.xy, gid.z);
    dst.write(r_9, uint2(_533.xy), uint(_533.z));
}

