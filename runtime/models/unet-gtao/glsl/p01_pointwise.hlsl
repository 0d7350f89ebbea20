static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

ByteAddressBuffer params : register(t16);
RWTexture2DArray<float4> dst : register(u0);
Texture2DArray<float4> src0 : register(t0);
SamplerState _src0_sampler : register(s0);
uniform int u_flip_y;
Texture2DArray<float4> src1 : register(t1);
SamplerState _src1_sampler : register(s1);

static uint3 gl_GlobalInvocationID;
struct SPIRV_Cross_Input
{
    uint3 gl_GlobalInvocationID : SV_DispatchThreadID;
};

uint3 spvTextureSize(Texture2DArray<float4> Tex, uint Level, out uint Param)
{
    uint3 ret;
    Tex.GetDimensions(Level, ret.x, ret.y, ret.z, Param);
    return ret;
}

uint3 spvImageSize(RWTexture2DArray<float4> Tex, out uint Param)
{
    uint3 ret;
    Tex.GetDimensions(ret.x, ret.y, ret.z);
    Param = 0u;
    return ret;
}

void p01_pointwise_inner()
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
    uint _64_dummy_parameter;
    int2 src_size0 = int3(spvTextureSize(src0, uint(0), _64_dummy_parameter)).xy;
    int2 size0 = ((src_size0 + int2(7, 7)) / int2(8, 8)) * int2(8, 8);
    int ix = gid.x;
    int iy = gid.y;
    int rx = clamp((src_size0.x - 1) - abs((src_size0.x - 1) - ix), 0, src_size0.x - 1);
    int ry = clamp((src_size0.y - 1) - abs((src_size0.y - 1) - iy), 0, src_size0.y - 1);
    if (u_flip_y != 0)
    {
        ry = (src_size0.y - 1) - ry;
    }
    float4 _133 = src0.Load(int4(int3(rx, ry, 0), 0));
    float4 a = float4(bool4(true, true, true, true).x ? _133.x : 0.0f.xxxx.x, bool4(true, true, true, true).y ? _133.y : 0.0f.xxxx.y, bool4(true, true, true, true).z ? _133.z : 0.0f.xxxx.z, bool4(true, true, true, true).w ? _133.w : 0.0f.xxxx.w);
    float4 _144 = src0.Load(int4(int3(rx, ry, 0), 0));
    float4 b = float4(bool4(true, true, true, true).x ? _144.x : 0.0f.xxxx.x, bool4(true, true, true, true).y ? _144.y : 0.0f.xxxx.y, bool4(true, true, true, true).z ? _144.z : 0.0f.xxxx.z, bool4(true, true, true, true).w ? _144.w : 0.0f.xxxx.w);
    float4 r = a * b;
    float4 v0[2];
    v0[0] = r;
    float4 _161 = src0.Load(int4(int3(rx, ry, 1), 0));
    float4 a_1 = float4(bool4(true, true, false, false).x ? _161.x : 0.0f.xxxx.x, bool4(true, true, false, false).y ? _161.y : 0.0f.xxxx.y, bool4(true, true, false, false).z ? _161.z : 0.0f.xxxx.z, bool4(true, true, false, false).w ? _161.w : 0.0f.xxxx.w);
    float4 _171 = src0.Load(int4(int3(rx, ry, 1), 0));
    float4 b_1 = float4(bool4(true, true, false, false).x ? _171.x : 0.0f.xxxx.x, bool4(true, true, false, false).y ? _171.y : 0.0f.xxxx.y, bool4(true, true, false, false).z ? _171.z : 0.0f.xxxx.z, bool4(true, true, false, false).w ? _171.w : 0.0f.xxxx.w);
    float4 r_1 = a_1 * b_1;
    v0[1] = r_1;
    float4 r_2 = asfloat(params.Load4(128));
    r_2 += mul(v0[0], float4x4(float4(asfloat(params.Load4(0))), float4(asfloat(params.Load4(16))), float4(asfloat(params.Load4(32))), float4(asfloat(params.Load4(48)))));
    r_2 += mul(v0[1], float4x4(float4(asfloat(params.Load4(64))), float4(asfloat(params.Load4(80))), float4(asfloat(params.Load4(96))), float4(asfloat(params.Load4(112)))));
    r_2 = min(max(r_2, 0.0f.xxxx), 1.0f.xxxx);
    float4 v1[1];
    v1[0] = r_2;
    float4 r_3 = asfloat(params.Load4(272));
    float4 _313 = src0.Load(int4(int3(rx, ry, 0), 0));
    r_3 += mul(float4(bool4(true, true, true, true).x ? _313.x : 0.0f.xxxx.x, bool4(true, true, true, true).y ? _313.y : 0.0f.xxxx.y, bool4(true, true, true, true).z ? _313.z : 0.0f.xxxx.z, bool4(true, true, true, true).w ? _313.w : 0.0f.xxxx.w), float4x4(float4(asfloat(params.Load4(144))), float4(asfloat(params.Load4(160))), float4(asfloat(params.Load4(176))), float4(asfloat(params.Load4(192)))));
    float4 _356 = src0.Load(int4(int3(rx, ry, 1), 0));
    r_3 += mul(float4(bool4(true, true, false, false).x ? _356.x : 0.0f.xxxx.x, bool4(true, true, false, false).y ? _356.y : 0.0f.xxxx.y, bool4(true, true, false, false).z ? _356.z : 0.0f.xxxx.z, bool4(true, true, false, false).w ? _356.w : 0.0f.xxxx.w), float4x4(float4(asfloat(params.Load4(208))), float4(asfloat(params.Load4(224))), float4(asfloat(params.Load4(240))), float4(asfloat(params.Load4(256)))));
    float4 v2[1];
    v2[0] = r_3;
    float4 a_2 = v2[0];
    float4 b_2 = src1.Load(int4(int3(0, 0, 0), 0));
    float4 r_4 = a_2 - b_2;
    float4 v3[1];
    v3[0] = r_4;
    float4 a_3 = v3[0];
    float4 b_3 = v1[0];
    float4 r_5 = a_3 * b_3;
    float4 v4[1];
    v4[0] = r_5;
    float4 r_6 = v4[0];
    r_6 = -r_6;
    r_6 = exp(r_6);
    r_6 = float4(bool4(true, false, false, false).x ? r_6.x : 0.0f.xxxx.x, bool4(true, false, false, false).y ? r_6.y : 0.0f.xxxx.y, bool4(true, false, false, false).z ? r_6.z : 0.0f.xxxx.z, bool4(true, false, false, false).w ? r_6.w : 0.0f.xxxx.w);
    r_6 = min(max(r_6, 0.0f.xxxx), 8.0f.xxxx);
    float4 v5[1];
    v5[0] = r_6;
    float4 a_4 = v5[0];
    float4 b_4 = v1[0];
    float4 r_7 = a_4 * b_4;
    float4 v6[1];
    v6[0] = r_7;
    float4 r_8 = v6[gid.z];
    dst[int3(gid.xy, gid.z)] = r_8;
}

[numthreads(8, 8, 1)]
void p01_pointwise(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p01_pointwise_inner();
}
