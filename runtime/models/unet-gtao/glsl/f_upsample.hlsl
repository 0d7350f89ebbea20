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
Texture2DArray<float4> src2 : register(t2);
SamplerState _src2_sampler : register(s2);
Texture2DArray<float4> src3 : register(t3);
SamplerState _src3_sampler : register(s3);
Texture2DArray<float4> src4 : register(t4);
SamplerState _src4_sampler : register(s4);

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
    int2 _61;
    if (frame_u_flip_y != 0)
    {
        _61 = p;
    }
    else
    {
        _61 = int2(p.x, (size.y - 1) - p.y);
    }
    return _61;
}

int2 nao_size(Texture2DArray<float4> t, SamplerState _t_sampler)
{
    uint _85_dummy_parameter;
    return int3(spvTextureSize(t, uint(0), _85_dummy_parameter)).xy;
}

float4 nao_load(Texture2DArray<float4> t, SamplerState _t_sampler, int2 p, int layer)
{
    int2 param = p;
    int2 param_1 = nao_size(t, _t_sampler);
    return t.Load(int4(int3(nao_texel(param, param_1), layer), 0));
}

void nao_store(int2 p, int layer, float4 v)
{
    uint _108_dummy_parameter;
    int2 param = p;
    int2 param_1 = int3(spvImageSize(dst, _108_dummy_parameter)).xy;
    dst[int3(nao_texel(param, param_1), layer)] = v.x;
}

float3 nao_position(int2 p, int2 size, float z)
{
    float2 ndc = (((float2(p) + 0.5f.xx) / float2(size)) * 2.0f) - 1.0f.xx;
    return float3((ndc.x / frame_u_proj.x) * z, (ndc.y / frame_u_proj.y) * z, -z);
}

int nao_floor_div(int a, int b)
{
    int _156;
    if (a >= 0)
    {
        _156 = a / b;
    }
    else
    {
        _156 = -((((-a) + b) - 1) / b);
    }
    return _156;
}

void f_upsample_inner()
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    uint _184_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _184_dummy_parameter)).xy;
    bool _190 = gid.x >= out_size.x;
    bool _199;
    if (!_190)
    {
        _199 = gid.y >= out_size.y;
    }
    else
    {
        _199 = _190;
    }
    if (_199)
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
        float4 param_6 = 1.0f.xxxx;
        nao_store(param_4, param_5, param_6);
        return;
    }
    int2 param_7 = px;
    int2 param_8 = out_size;
    float param_9 = z;
    float3 p = nao_position(param_7, param_8, param_9);
    int2 param_10 = px;
    int param_11 = 0;
    float3 n = nao_load(src1, _src1_sampler, param_10, param_11).xyz;
    float depth = max(z, 1.0000000031710768509710513471353e-30f);
    int2 hi = out_size;
    int2 lo = nao_size(src2, _src2_sampler);
    float2 uv = (((float2(px) + 0.5f.xx) * float2(lo)) / float2(hi)) - 0.5f.xx;
    int2 num = (((int2(2, 2) * px) + int2(1, 1)) * lo) - hi;
    int param_12 = num.x;
    int param_13 = 2 * hi.x;
    int param_14 = num.y;
    int param_15 = 2 * hi.y;
    int2 base = int2(nao_floor_div(param_12, param_13), nao_floor_div(param_14, param_15)) - int2(1, 1);
    float sum = 0.0f;
    float total = 0.0f;
    for (int y = 0; y < 4; y++)
    {
        for (int x = 0; x < 4; x++)
        {
            int2 q = clamp(base + int2(x, y), int2(0, 0), lo - int2(1, 1));
            int2 param_16 = q;
            int param_17 = 0;
            float4 qw = nao_load(src3, _src3_sampler, param_16, param_17);
            if (qw.w < 0.5f)
            {
                continue;
            }
            float2 d = float2(base + int2(x, y)) - uv;
            float spatial = exp((-dot(d, d)) / 0.7200000286102294921875f);
            int2 param_18 = q;
            int param_19 = 1;
            float3 qn = nao_load(src3, _src3_sampler, param_18, param_19).xyz;
            float plane = abs(dot(qn, p - qw.xyz)) / (0.02999999932944774627685546875f * depth);
            float agree = pow(max(dot(qn, n), 0.0f), 8.0f);
            float w = spatial * (0.001000000047497451305389404296875f + (exp((-plane) * plane) * agree));
            int2 param_20 = q;
            int param_21 = 0;
            int2 param_22 = q;
            int param_23 = 2;
            sum += (w * (nao_load(src2, _src2_sampler, param_20, param_21).x - nao_load(src3, _src3_sampler, param_22, param_23).x));
            total += w;
        }
    }
    float up = 0.0f;
    if (total > 0.0f)
    {
        up = sum / total;
    }
    int2 param_24 = px;
    int param_25 = 0;
    int2 param_26 = px;
    int param_27 = 0;
    float4 param_28 = clamp(nao_load(src4, _src4_sampler, param_24, param_25).x + up, 0.0f, 1.0f).xxxx;
    nao_store(param_26, param_27, param_28);
}

[numthreads(8, 8, 1)]
void f_upsample(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    f_upsample_inner();
}
