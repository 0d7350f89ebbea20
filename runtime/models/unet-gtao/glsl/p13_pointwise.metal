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

kernel void p13_pointwise(constant int& u_flip_y [[buffer(0)]], const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], texture2d_array<float> src2 [[texture(3)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], sampler src2Smplr [[sampler(3)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
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
    float4 r = params.prm[12];
    int3 _111 = int3(gid.xy, 0);
    r += (float4x4(float4(params.prm[0]), float4(params.prm[1]), float4(params.prm[2]), float4(params.prm[3])) * src0.read(uint2(_111.xy), uint(_111.z), 0));
    int3 _155 = int3(gid.xy, 1);
    r += (float4x4(float4(params.prm[4]), float4(params.prm[5]), float4(params.prm[6]), float4(params.prm[7])) * src0.read(uint2(_155.xy), uint(_155.z), 0));
    int3 _200 = int3(gid.xy, 0);
    r += (float4x4(float4(params.prm[8]), float4(params.prm[9]), float4(params.prm[10]), float4(params.prm[11])) * src1.read(uint2(_200.xy), uint(_200.z), 0));
    spvUnsafeArray<float4, 1> v0;
    v0[0] = r;
    float4 r_1 = params.prm[17];
    int3 _254 = int3(gid.xy, 0);
    r_1 += (float4x4(float4(params.prm[13]), float4(params.prm[14]), float4(params.prm[15]), float4(params.prm[16])) * src2.read(uint2(_254.xy), uint(_254.z), 0));
    float4 a = v0[0];
    float4 b = r_1;
    r_1 = a + b;
    r_1 = fast::min(fast::max(r_1, float4(0.0)), float4(1.0));
    spvUnsafeArray<float4, 1> v1;
    v1[0] = r_1;
    float4 r_2 = v1[gid.z];
    int _288;
    if (u_flip_y != 0)
    {
        _288 = (out_size.y - 1) - gid.y;
    }
    else
    {
        _288 = gid.y;
    }
    int3 _306 = int3(int2(gid.x, _288), gid.z);
    dst.write(r_2, uint2(_306.xy), uint(_306.z));
}

