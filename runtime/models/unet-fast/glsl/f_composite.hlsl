static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

cbuffer FrameUniforms : register(b0)
{
    float2 frame_u_proj : packoffset(c0);
    float frame_u_radius : packoffset(c0.z);
    float frame_u_pixels_per_unit : packoffset(c0.w);
    int frame_u_flip_y : packoffset(c1);
};

RWTexture2DArray<float> dst : register(u0);
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

uint3 spvImageSize(RWTexture2DArray<float> Tex, out uint Param)
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
    dst[int3(nao_texel(param, param_1), layer)] = v.x;
}

void f_composite_inner()
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
    if (!(nao_load(src0, _src0_sampler, param_2, param_3).x > 0.0f))
    {
        int2 param_4 = px;
        int param_5 = 0;
        float4 param_6 = 1.0f.xxxx;
        nao_store(param_4, param_5, param_6);
        return;
    }
    int2 param_7 = px;
    int param_8 = 0;
    int2 param_9 = px;
    int param_10 = 0;
    float4 param_11 = nao_load(src1, _src1_sampler, param_7, param_8).x.xxxx;
    nao_store(param_9, param_10, param_11);
}

[numthreads(8, 8, 1)]
void f_composite(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    f_composite_inner();
}
