static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

static const float2 _191[16] = { float2(0.377857029438018798828125f, 0.1678416728973388671875f), float2(0.968745052814483642578125f, 0.7069942951202392578125f), float2(0.08153782784938812255859375f, 0.599261462688446044921875f), float2(0.0065644229762256145477294921875f, 0.521755874156951904296875f), float2(0.86076271533966064453125f, 0.293343722820281982421875f), float2(0.804016172885894775390625f, 0.8365204334259033203125f), float2(0.3537027537822723388671875f, 0.930650174617767333984375f), float2(0.732333123683929443359375f, 0.747238457202911376953125f), float2(0.65405738353729248046875f, 0.18946956098079681396484375f), float2(0.1374433934688568115234375f, 0.517999827861785888671875f), float2(0.4956852495670318603515625f, 0.862544834613800048828125f), float2(0.524612128734588623046875f, 0.896280705928802490234375f), float2(0.93087482452392578125f, 0.195674479007720947265625f), float2(0.2630412876605987548828125f, 0.0488224588334560394287109375f), float2(0.2038518488407135009765625f, 0.999011993408203125f), float2(0.585066139698028564453125f, 0.251001894474029541015625f) };

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
    int2 _62;
    if (frame_u_flip_y != 0)
    {
        _62 = p;
    }
    else
    {
        _62 = int2(p.x, (size.y - 1) - p.y);
    }
    return _62;
}

int2 nao_size(Texture2DArray<float4> t, SamplerState _t_sampler)
{
    uint _86_dummy_parameter;
    return int3(spvTextureSize(t, uint(0), _86_dummy_parameter)).xy;
}

float4 nao_load(Texture2DArray<float4> t, SamplerState _t_sampler, int2 p, int layer)
{
    int2 param = p;
    int2 param_1 = nao_size(t, _t_sampler);
    return t.Load(int4(int3(nao_texel(param, param_1), layer), 0));
}

void nao_store(int2 p, int layer, float4 v)
{
    uint _109_dummy_parameter;
    int2 param = p;
    int2 param_1 = int3(spvImageSize(dst, _109_dummy_parameter)).xy;
    dst[int3(nao_texel(param, param_1), layer)] = v.x;
}

float2 nao_noise(int2 p)
{
    return _191[((p.y % 4) * 4) + (p.x % 4)];
}

float nao_acos(float x)
{
    return acos(clamp(x, -1.0f, 1.0f));
}

bool nao_inside(int2 q, int2 size)
{
    bool _124 = all(bool2(q.x >= int2(0, 0).x, q.y >= int2(0, 0).y));
    bool _131;
    if (_124)
    {
        _131 = all(bool2(q.x < size.x, q.y < size.y));
    }
    else
    {
        _131 = _124;
    }
    return _131;
}

void f_gtao_inner()
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    uint _218_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _218_dummy_parameter)).xy;
    bool _224 = gid.x >= out_size.x;
    bool _233;
    if (!_224)
    {
        _233 = gid.y >= out_size.y;
    }
    else
    {
        _233 = _224;
    }
    if (_233)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1);
    int2 param_2 = px;
    int param_3 = 0;
    float4 pw = nao_load(src0, _src0_sampler, param_2, param_3);
    if (pw.w < 0.5f)
    {
        int2 param_4 = px;
        int param_5 = 0;
        float4 param_6 = 1.0f.xxxx;
        nao_store(param_4, param_5, param_6);
        return;
    }
    float3 p = pw.xyz;
    int2 param_7 = px;
    int param_8 = 1;
    float3 n = nao_load(src0, _src0_sampler, param_7, param_8).xyz;
    float ln = length(n);
    if (ln > 9.9999996826552253889678874634872e-21f)
    {
        n /= ln.xxx;
    }
    else
    {
        n = float3(0.0f, 0.0f, 1.0f);
    }
    float3 view_v = normalize(-p);
    float radius_px = (frame_u_radius * frame_u_pixels_per_unit) / max(-p.z, 1.0000000031710768509710513471353e-30f);
    if (!(radius_px > 1.0f))
    {
        int2 param_9 = px;
        int param_10 = 0;
        float4 param_11 = 1.0f.xxxx;
        nao_store(param_9, param_10, param_11);
        return;
    }
    int2 param_12 = px;
    float2 _noise = nao_noise(param_12);
    float falloff_range = 0.20000000298023223876953125f * frame_u_radius;
    float falloff_mul = (-1.0f) / falloff_range;
    float falloff_add = ((frame_u_radius - falloff_range) / falloff_range) + 1.0f;
    float min_s = 1.2999999523162841796875f / radius_px;
    float2 centre = float2(px) + 0.5f.xx;
    float visibility = 0.0f;
    for (int slice = 0; slice < 4; slice++)
    {
        float phi = (float(slice) + _noise.x) * 0.785398185253143310546875f;
        float2 omega = float2(cos(phi), sin(phi));
        float3 dir_v = float3(omega, 0.0f);
        float3 ortho_v = dir_v - (view_v * dot(dir_v, view_v));
        float3 axis_v = normalize(cross(dir_v, view_v));
        float3 proj_n = n - (axis_v * dot(n, axis_v));
        float proj_len = length(proj_n);
        float sign_n = -1.0f;
        if (dot(ortho_v, proj_n) >= 0.0f)
        {
            sign_n = 1.0f;
        }
        float cos_n = clamp(dot(proj_n, view_v) / max(proj_len, 9.9999996826552253889678874634872e-21f), 0.0f, 1.0f);
        float param_13 = cos_n;
        float ang_n = sign_n * nao_acos(param_13);
        float low0 = cos(ang_n + 1.57079637050628662109375f);
        float low1 = cos(ang_n - 1.57079637050628662109375f);
        float hc0 = low0;
        float hc1 = low1;
        for (int k = 0; k < 8; k++)
        {
            float s = (float(k) + _noise.y) / 8.0f;
            s = min_s + (((1.0f - min_s) * s) * s);
            float2 off = omega * (s * radius_px);
            int2 q0 = int2(floor(centre + off));
            int2 q1 = int2(floor(centre - off));
            int2 param_14 = q0;
            int2 param_15 = out_size;
            if (nao_inside(param_14, param_15))
            {
                int2 param_16 = q0;
                int param_17 = 0;
                float4 sw = nao_load(src0, _src0_sampler, param_16, param_17);
                if (sw.w >= 0.5f)
                {
                    float3 d = sw.xyz - p;
                    float dist = length(d);
                    if (dist > 1.0000000031710768509710513471353e-30f)
                    {
                        float w = clamp((dist * falloff_mul) + falloff_add, 0.0f, 1.0f);
                        hc0 = max(hc0, lerp(low0, dot(d / dist.xxx, view_v), w));
                    }
                }
            }
            int2 param_18 = q1;
            int2 param_19 = out_size;
            if (nao_inside(param_18, param_19))
            {
                int2 param_20 = q1;
                int param_21 = 0;
                float4 sw_1 = nao_load(src0, _src0_sampler, param_20, param_21);
                if (sw_1.w >= 0.5f)
                {
                    float3 d_1 = sw_1.xyz - p;
                    float dist_1 = length(d_1);
                    if (dist_1 > 1.0000000031710768509710513471353e-30f)
                    {
                        float w_1 = clamp((dist_1 * falloff_mul) + falloff_add, 0.0f, 1.0f);
                        hc1 = max(hc1, lerp(low1, dot(d_1 / dist_1.xxx, view_v), w_1));
                    }
                }
            }
        }
        float param_22 = hc1;
        float h0 = -nao_acos(param_22);
        float param_23 = hc0;
        float h1 = nao_acos(param_23);
        h0 = ang_n + clamp(h0 - ang_n, -1.57079637050628662109375f, 1.57079637050628662109375f);
        h1 = ang_n + clamp(h1 - ang_n, -1.57079637050628662109375f, 1.57079637050628662109375f);
        float sin_n = sin(ang_n);
        float arc0 = ((cos_n + ((2.0f * h0) * sin_n)) - cos((2.0f * h0) - ang_n)) * 0.25f;
        float arc1 = ((cos_n + ((2.0f * h1) * sin_n)) - cos((2.0f * h1) - ang_n)) * 0.25f;
        visibility += (proj_len * (arc0 + arc1));
    }
    int2 param_24 = px;
    int param_25 = 0;
    float4 param_26 = clamp(visibility / 4.0f, 0.0f, 1.0f).xxxx;
    nao_store(param_24, param_25, param_26);
}

[numthreads(8, 8, 1)]
void f_gtao(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    f_gtao_inner();
}
