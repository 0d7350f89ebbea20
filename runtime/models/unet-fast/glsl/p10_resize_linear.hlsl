static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

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

float nao_div(float a, float b)
{
    precise float _16 = a / b;
    float q = _16;
    float r = mad(-q, b, a);
    precise float _27 = r / b;
    precise float _28 = q + _27;
    float d = _28;
    return d;
}

void p10_resize_linear_inner()
{
    int3 gid = int3(gl_GlobalInvocationID);
    uint _49_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _49_dummy_parameter)).xy;
    bool _58 = gid.x >= out_size.x;
    bool _68;
    if (!_58)
    {
        _68 = gid.y >= out_size.y;
    }
    else
    {
        _68 = _58;
    }
    bool _77;
    if (!_68)
    {
        _77 = gid.z >= 16;
    }
    else
    {
        _77 = _68;
    }
    if (_77)
    {
        return;
    }
    uint _89_dummy_parameter;
    int2 in_size = int3(spvTextureSize(src0, uint(0), _89_dummy_parameter)).xy;
    precise float _96 = float(gid.y) + 0.5f;
    float param = _96;
    float param_1 = 2.0f;
    precise float _101 = nao_div(param, param_1) - 0.5f;
    float fy = _101;
    precise float _106 = float(gid.x) + 0.5f;
    float param_2 = _106;
    float param_3 = 2.0f;
    precise float _110 = nao_div(param_2, param_3) - 0.5f;
    float fx = _110;
    fy = clamp(fy, 0.0f, float(in_size.y - 1));
    fx = clamp(fx, 0.0f, float(in_size.x - 1));
    int y0 = int(fy);
    int x0 = int(fx);
    int y1 = min((y0 + 1), (in_size.y - 1));
    int x1 = min((x0 + 1), (in_size.x - 1));
    float wy = fy - float(y0);
    float wx = fx - float(x0);
    float4 a = src0.Load(int4(int3(x0, y0, gid.z), 0));
    float4 b = src0.Load(int4(int3(x1, y0, gid.z), 0));
    float4 c = src0.Load(int4(int3(x0, y1, gid.z), 0));
    float4 d = src0.Load(int4(int3(x1, y1, gid.z), 0));
    float4 r = (((a * (1.0f - wx)) + (b * wx)) * (1.0f - wy)) + (((c * (1.0f - wx)) + (d * wx)) * wy);
    if (false)
    {
        r = 0.0f.xxxx;
    }
    dst[int3(gid.xy, gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p10_resize_linear(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p10_resize_linear_inner();
}
