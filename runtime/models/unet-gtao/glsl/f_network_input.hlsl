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

void f_network_input_inner()
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
    float4 pw = nao_load(src0, _src0_sampler, param_2, param_3);
    float4 x = 0.0f.xxxx;
    bool _155 = pw.w >= 0.5f;
    bool _163;
    if (_155)
    {
        _163 = (-pw.z) > 0.0f;
    }
    else
    {
        _163 = _155;
    }
    if (_163)
    {
        int2 param_4 = px;
        int param_5 = 1;
        x = float4(log(-pw.z), nao_load(src0, _src0_sampler, param_4, param_5).xyz);
    }
    int2 param_6 = px;
    int param_7 = 0;
    float4 param_8 = x;
    nao_store(param_6, param_7, param_8);
    float g = 1.0f;
    float r = 1.0f;
    if (pw.w >= 0.5f)
    {
        int2 param_9 = px;
        int param_10 = 2;
        g = nao_load(src0, _src0_sampler, param_9, param_10).x;
        int2 param_11 = px;
        int param_12 = 2;
        r = nao_load(src0, _src0_sampler, param_11, param_12).y;
    }
    int2 param_13 = px;
    int param_14 = 1;
    float4 param_15 = float4(r, g, 0.0f, 0.0f);
    nao_store(param_13, param_14, param_15);
}

[numthreads(8, 8, 1)]
void f_network_input(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    f_network_input_inner();
}
