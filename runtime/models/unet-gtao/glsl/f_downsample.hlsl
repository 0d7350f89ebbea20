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
Texture2DArray<float4> src2 : register(t2);
SamplerState _src2_sampler : register(s2);
Texture2DArray<float4> src3 : register(t3);
SamplerState _src3_sampler : register(s3);

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
    int2 _56;
    if (frame_u_flip_y != 0)
    {
        _56 = p;
    }
    else
    {
        _56 = int2(p.x, (size.y - 1) - p.y);
    }
    return _56;
}

int2 nao_size(Texture2DArray<float4> t, SamplerState _t_sampler)
{
    uint _80_dummy_parameter;
    return int3(spvTextureSize(t, uint(0), _80_dummy_parameter)).xy;
}

float4 nao_load(Texture2DArray<float4> t, SamplerState _t_sampler, int2 p, int layer)
{
    int2 param = p;
    int2 param_1 = nao_size(t, _t_sampler);
    return t.Load(int4(int3(nao_texel(param, param_1), layer), 0));
}

float3 nao_position(int2 p, int2 size, float z)
{
    float2 ndc = (((float2(p) + 0.5f.xx) / float2(size)) * 2.0f) - 1.0f.xx;
    return float3((ndc.x / frame_u_proj.x) * z, (ndc.y / frame_u_proj.y) * z, -z);
}

void nao_store(int2 p, int layer, float4 v)
{
    uint _103_dummy_parameter;
    int2 param = p;
    int2 param_1 = int3(spvImageSize(dst, _103_dummy_parameter)).xy;
    dst[int3(nao_texel(param, param_1), layer)] = v;
}

void f_downsample_inner()
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    uint _159_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _159_dummy_parameter)).xy;
    bool _165 = gid.x >= out_size.x;
    bool _174;
    if (!_165)
    {
        _174 = gid.y >= out_size.y;
    }
    else
    {
        _174 = _165;
    }
    if (_174)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1);
    int2 hi = nao_size(src0, _src0_sampler);
    int2 q = min(((((int2(2, 2) * px) + int2(1, 1)) * hi) / (int2(2, 2) * out_size)), (hi - int2(1, 1)));
    int2 param_2 = q;
    int param_3 = 0;
    float z = nao_load(src0, _src0_sampler, param_2, param_3).x;
    if (z > 0.0f)
    {
        int2 param_4 = q;
        int2 param_5 = hi;
        float param_6 = z;
        int2 param_7 = px;
        int param_8 = 0;
        float4 param_9 = float4(nao_position(param_4, param_5, param_6), 1.0f);
        nao_store(param_7, param_8, param_9);
        int2 param_10 = q;
        int param_11 = 0;
        int2 param_12 = px;
        int param_13 = 1;
        float4 param_14 = float4(nao_load(src1, _src1_sampler, param_10, param_11).xyz, 0.0f);
        nao_store(param_12, param_13, param_14);
    }
    else
    {
        int2 param_15 = px;
        int param_16 = 0;
        float4 param_17 = 0.0f.xxxx;
        nao_store(param_15, param_16, param_17);
        int2 param_18 = px;
        int param_19 = 1;
        float4 param_20 = 0.0f.xxxx;
        nao_store(param_18, param_19, param_20);
    }
    int2 param_21 = q;
    int param_22 = 0;
    int2 param_23 = q;
    int param_24 = 0;
    int2 param_25 = px;
    int param_26 = 2;
    float4 param_27 = float4(nao_load(src2, _src2_sampler, param_21, param_22).x, nao_load(src3, _src3_sampler, param_23, param_24).x, 0.0f, 0.0f);
    nao_store(param_25, param_26, param_27);
}

[numthreads(8, 8, 1)]
void f_downsample(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    f_downsample_inner();
}
