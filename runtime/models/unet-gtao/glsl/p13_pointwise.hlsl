static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

ByteAddressBuffer params : register(t16);
RWTexture2DArray<float4> dst : register(u0);
Texture2DArray<float4> src0 : register(t0);
SamplerState _src0_sampler : register(s0);
Texture2DArray<float4> src1 : register(t1);
SamplerState _src1_sampler : register(s1);
Texture2DArray<float4> src2 : register(t2);
SamplerState _src2_sampler : register(s2);
uniform int u_flip_y;

static uint3 gl_GlobalInvocationID;
struct SPIRV_Cross_Input
{
    uint3 gl_GlobalInvocationID : SV_DispatchThreadID;
};

uint3 spvImageSize(RWTexture2DArray<float4> Tex, out uint Param)
{
    uint3 ret;
    Tex.GetDimensions(ret.x, ret.y, ret.z);
    Param = 0u;
    return ret;
}

void p13_pointwise_inner()
{
    int3 gid = int3(gl_GlobalInvocationID);
    uint _24_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _24_dummy_parameter)).xy;
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
    float4 r = asfloat(params.Load4(192));
    r += mul(src0.Load(int4(int3(gid.xy, 0), 0)), float4x4(float4(asfloat(params.Load4(0))), float4(asfloat(params.Load4(16))), float4(asfloat(params.Load4(32))), float4(asfloat(params.Load4(48)))));
    r += mul(src0.Load(int4(int3(gid.xy, 1), 0)), float4x4(float4(asfloat(params.Load4(64))), float4(asfloat(params.Load4(80))), float4(asfloat(params.Load4(96))), float4(asfloat(params.Load4(112)))));
    r += mul(src1.Load(int4(int3(gid.xy, 0), 0)), float4x4(float4(asfloat(params.Load4(128))), float4(asfloat(params.Load4(144))), float4(asfloat(params.Load4(160))), float4(asfloat(params.Load4(176)))));
    float4 v0[1];
    v0[0] = r;
    float4 r_1 = asfloat(params.Load4(272));
    r_1 += mul(src2.Load(int4(int3(gid.xy, 0), 0)), float4x4(float4(asfloat(params.Load4(208))), float4(asfloat(params.Load4(224))), float4(asfloat(params.Load4(240))), float4(asfloat(params.Load4(256)))));
    float4 a = v0[0];
    float4 b = r_1;
    r_1 = a + b;
    r_1 = min(max(r_1, 0.0f.xxxx), 1.0f.xxxx);
    float4 v1[1];
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
    dst[int3(int2(gid.x, _288), gid.z)] = r_2;
}

[numthreads(8, 8, 1)]
void p13_pointwise(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p13_pointwise_inner();
}
