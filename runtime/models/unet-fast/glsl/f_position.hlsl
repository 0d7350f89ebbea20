static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

cbuffer FrameUniforms : register(b0)
{
    float2 frame_u_proj : packoffset(c0);
    float frame_u_radius : packoffset(c0.z);
    float frame_u_pixels_per_unit : packoffset(c0.w);
    int frame_u_flip_y : packoffset(c1);
};

RWTexture2DArray<float4> dst : register(u0);
Texture2DArray<float4> src0 : register(t0);
SamplerState _src0_sampler : register(s0);
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

int2 nao_texel(int2 p, int2 size)
{
    int2 _48;
    if (frame_u_flip_y != 0)
    {
        _48 = p;
    }
    else
    {
        _48 = int2(p.x, (size.y - 1) - p.y);
    }
    return _48;
}

int2 nao_size(Texture2DArray<float4> t, SamplerState _t_sampler)
{
    uint _72_dummy_parameter;
    return int3(spvTextureSize(t, uint(0), _72_dummy_parameter)).xy;
}

float4 nao_load(Texture2DArray<float4> t, SamplerState _t_sampler, int2 p, int layer)
{
    int2 param = p;
    int2 param_1 = nao_size(t, _t_sampler);
    return t.Load(int4(int3(nao_texel(param, param_1), layer), 0));
}

void nao_store(int2 p, int layer, float4 v)
{
    uint _95_dummy_parameter;
    int2 param = p;
    int2 param_1 = int3(spvImageSize(dst, _95_dummy_parameter)).xy;
    dst[int3(nao_texel(param, param_1), layer)] = v;
}

void f_position_inner()
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    uint _116_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _116_dummy_parameter)).xy;
    bool _122 = gid.x >= out_size.x;
    bool _131;
    if (!_122)
    {
        _131 = gid.y >= out_size.y;
    }
    else
    {
        _131 = _122;
    }
    if (_131)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1);
    int2 param_2 = px;
    int param_3 = 0;
    float z = nao_load(src0, _src0_sampler, param_2, param_3).x;
    if (!(z > 0.0f))
    {
        int2 param_4 = px;
        int param_5 = 0;
        float4 param_6 = 0.0f.xxxx;
        nao_store(param_4, param_5, param_6);
        int2 param_7 = px;
        int param_8 = 1;
        float4 param_9 = 0.0f.xxxx;
        nao_store(param_7, param_8, param_9);
        return;
    }
    float2 ndc = (((float2(px) + 0.5f.xx) / float2(out_size)) * 2.0f) - 1.0f.xx;
    int2 param_10 = px;
    int param_11 = 0;
    float4 param_12 = float4((ndc.x / frame_u_proj.x) * z, (ndc.y / frame_u_proj.y) * z, -z, 1.0f);
    nao_store(param_10, param_11, param_12);
    int2 param_13 = px;
    int param_14 = 0;
    int2 param_15 = px;
    int param_16 = 1;
    float4 param_17 = float4(nao_load(src1, _src1_sampler, param_13, param_14).xyz, 0.0f);
    nao_store(param_15, param_16, param_17);
}

[numthreads(8, 8, 1)]
void f_position(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    f_position_inner();
}
