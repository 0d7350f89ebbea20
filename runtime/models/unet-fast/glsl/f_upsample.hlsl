static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

cbuffer FrameUniforms : register(b0)
{
    float2 frame_u_proj : packoffset(c0);
    float frame_u_radius : packoffset(c0.z);
    float frame_u_pixels_per_unit : packoffset(c0.w);
    int frame_u_flip_y : packoffset(c1);
};

RWTexture2DArray<float> dst : register(u0);
Texture2DArray<float4> src2 : register(t2);
SamplerState _src2_sampler : register(s2);
Texture2DArray<float4> src3 : register(t3);
SamplerState _src3_sampler : register(s3);
Texture2DArray<float4> src0 : register(t0);
SamplerState _src0_sampler : register(s0);
Texture2DArray<float4> src1 : register(t1);
SamplerState _src1_sampler : register(s1);

static uint3 gl_WorkGroupID;
static uint3 gl_GlobalInvocationID;
static uint gl_LocalInvocationIndex;
struct SPIRV_Cross_Input
{
    uint3 gl_WorkGroupID : SV_GroupID;
    uint3 gl_GlobalInvocationID : SV_DispatchThreadID;
    uint gl_LocalInvocationIndex : SV_GroupIndex;
};

groupshared float4 nao_tile_a[144];
groupshared float4 nao_tile_b[144];

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

int2 nao_size(Texture2DArray<float4> t, SamplerState _t_sampler)
{
    uint _91_dummy_parameter;
    return int3(spvTextureSize(t, uint(0), _91_dummy_parameter)).xy;
}

int2 nao_texel(int2 p, int2 size)
{
    int2 _67;
    if (frame_u_flip_y != 0)
    {
        _67 = p;
    }
    else
    {
        _67 = int2(p.x, (size.y - 1) - p.y);
    }
    return _67;
}

int nao_floor_div(int a, int b)
{
    int _162;
    if (a >= 0)
    {
        _162 = a / b;
    }
    else
    {
        _162 = -((((-a) + b) - 1) / b);
    }
    return _162;
}

int2 nao_up_base(int2 p, int2 lo, int2 hi)
{
    int2 num = (((int2(2, 2) * p) + int2(1, 1)) * lo) - hi;
    int param = num.x;
    int param_1 = 2 * hi.x;
    int param_2 = num.y;
    int param_3 = 2 * hi.y;
    return int2(nao_floor_div(param, param_1), nao_floor_div(param_2, param_3)) - int2(1, 1);
}

float4 nao_load(Texture2DArray<float4> t, SamplerState _t_sampler, int2 p, int layer)
{
    int2 param = p;
    int2 param_1 = nao_size(t, _t_sampler);
    return t.Load(int4(int3(nao_texel(param, param_1), layer), 0));
}

void nao_store(int2 p, int layer, float4 v)
{
    uint _114_dummy_parameter;
    int2 param = p;
    int2 param_1 = int3(spvImageSize(dst, _114_dummy_parameter)).xy;
    dst[int3(nao_texel(param, param_1), layer)] = v.x;
}

float3 nao_position(int2 p, int2 size, float z)
{
    float2 ndc = (((float2(p) + 0.5f.xx) / float2(size)) * 2.0f) - 1.0f.xx;
    return float3((ndc.x / frame_u_proj.x) * z, (ndc.y / frame_u_proj.y) * z, -z);
}

void f_upsample_inner()
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    uint _222_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _222_dummy_parameter)).xy;
    int lid = int(gl_LocalInvocationIndex);
    int2 group0 = int2(gl_WorkGroupID.xy) * int2(8, 8);
    int2 hi = out_size;
    int2 lo = nao_size(src2, _src2_sampler);
    int2 param = min(group0, (out_size - int2(1, 1)));
    int2 param_1 = out_size;
    int2 c0 = nao_texel(param, param_1);
    int2 param_2 = min((group0 + int2(7, 7)), (out_size - int2(1, 1)));
    int2 param_3 = out_size;
    int2 c1 = nao_texel(param_2, param_3);
    int2 param_4 = min(c0, c1);
    int2 param_5 = lo;
    int2 param_6 = hi;
    int2 t0 = nao_up_base(param_4, param_5, param_6);
    int2 param_7 = max(c0, c1);
    int2 param_8 = lo;
    int2 param_9 = hi;
    int2 t_size = (nao_up_base(param_7, param_8, param_9) + int2(4, 4)) - t0;
    bool _295 = t_size.x <= 12;
    bool _301;
    if (_295)
    {
        _301 = t_size.y <= 12;
    }
    else
    {
        _301 = _295;
    }
    bool tiled = _301;
    if (tiled)
    {
        for (int k = lid; k < (t_size.x * t_size.y); k += 64)
        {
            int2 q = clamp(t0 + int2(k % t_size.x, k / t_size.x), int2(0, 0), lo - int2(1, 1));
            int2 param_10 = q;
            int param_11 = 0;
            nao_tile_a[k] = nao_load(src3, _src3_sampler, param_10, param_11);
            int2 param_12 = q;
            int param_13 = 1;
            int2 param_14 = q;
            int param_15 = 0;
            nao_tile_b[k] = float4(nao_load(src3, _src3_sampler, param_12, param_13).xyz, nao_load(src2, _src2_sampler, param_14, param_15).x);
        }
    }
    GroupMemoryBarrierWithGroupSync();
    bool _374 = gid.x >= out_size.x;
    bool _383;
    if (!_374)
    {
        _383 = gid.y >= out_size.y;
    }
    else
    {
        _383 = _374;
    }
    if (_383)
    {
        return;
    }
    int2 param_16 = gid;
    int2 param_17 = out_size;
    int2 px = nao_texel(param_16, param_17);
    int2 param_18 = px;
    int param_19 = 0;
    float z = nao_load(src0, _src0_sampler, param_18, param_19).x;
    if (!(z > 0.0f))
    {
        int2 param_20 = px;
        int param_21 = 0;
        float4 param_22 = 1.0f.xxxx;
        nao_store(param_20, param_21, param_22);
        return;
    }
    int2 param_23 = px;
    int2 param_24 = out_size;
    float param_25 = z;
    float3 p = nao_position(param_23, param_24, param_25);
    int2 param_26 = px;
    int param_27 = 0;
    float3 n = nao_load(src1, _src1_sampler, param_26, param_27).xyz;
    float depth = max(z, 1.0000000031710768509710513471353e-30f);
    float2 uv = (((float2(px) + 0.5f.xx) * float2(lo)) / float2(hi)) - 0.5f.xx;
    int2 param_28 = px;
    int2 param_29 = lo;
    int2 param_30 = hi;
    int2 base = nao_up_base(param_28, param_29, param_30);
    float sum = 0.0f;
    float total = 0.0f;
    for (int y = 0; y < 4; y++)
    {
        for (int x = 0; x < 4; x++)
        {
            int2 o = base + int2(x, y);
            float4 qw = 0.0f.xxxx;
            float4 qv = 0.0f.xxxx;
            if (tiled)
            {
                int k_1 = ((o.y - t0.y) * t_size.x) + (o.x - t0.x);
                qw = nao_tile_a[k_1];
                qv = nao_tile_b[k_1];
            }
            else
            {
                int2 q_1 = clamp(o, int2(0, 0), lo - int2(1, 1));
                int2 param_31 = q_1;
                int param_32 = 0;
                qw = nao_load(src3, _src3_sampler, param_31, param_32);
                int2 param_33 = q_1;
                int param_34 = 1;
                int2 param_35 = q_1;
                int param_36 = 0;
                qv = float4(nao_load(src3, _src3_sampler, param_33, param_34).xyz, nao_load(src2, _src2_sampler, param_35, param_36).x);
            }
            if (qw.w < 0.5f)
            {
                continue;
            }
            float2 d = float2(o) - uv;
            float spatial = exp((-dot(d, d)) / 0.7200000286102294921875f);
            float3 qn = qv.xyz;
            float plane = abs(dot(qn, p - qw.xyz)) / (0.02999999932944774627685546875f * depth);
            float agree = pow(max(dot(qn, n), 0.0f), 8.0f);
            float w = spatial * (0.001000000047497451305389404296875f + (exp((-plane) * plane) * agree));
            sum += (w * qv.w);
            total += w;
        }
    }
    float up = 1.0f;
    if (total > 0.0f)
    {
        up = sum / total;
    }
    int2 param_37 = px;
    int param_38 = 0;
    float4 param_39 = up.xxxx;
    nao_store(param_37, param_38, param_39);
}

[numthreads(8, 8, 1)]
void f_upsample(SPIRV_Cross_Input stage_input)
{
    gl_WorkGroupID = stage_input.gl_WorkGroupID;
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    gl_LocalInvocationIndex = stage_input.gl_LocalInvocationIndex;
    f_upsample_inner();
}
