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

void p04_pool_avg_inner()
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
        _52 = gid.z >= 2;
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
    int2 in_size = int3(spvTextureSize(src0, uint(0), _64_dummy_parameter)).xy;
    float4 r = 0.0f.xxxx;
    int count = 0;
    int count_padded = 0;
    for (int ky = 0; ky < 2; ky++)
    {
        int iy = ((gid.y * 2) - 0) + (ky * 1);
        bool _91 = iy < 0;
        bool _100;
        if (!_91)
        {
            _100 = iy >= (in_size.y + 0);
        }
        else
        {
            _100 = _91;
        }
        if (_100)
        {
            continue;
        }
        for (int kx = 0; kx < 2; kx++)
        {
            int ix = ((gid.x * 2) - 0) + (kx * 1);
            bool _121 = ix < 0;
            bool _130;
            if (!_121)
            {
                _130 = ix >= (in_size.x + 0);
            }
            else
            {
                _130 = _121;
            }
            if (_130)
            {
                continue;
            }
            count_padded++;
            bool _137 = iy < 0;
            bool _145;
            if (!_137)
            {
                _145 = iy >= in_size.y;
            }
            else
            {
                _145 = _137;
            }
            bool _148 = _145 || (ix < 0);
            bool _156;
            if (!_148)
            {
                _156 = ix >= in_size.x;
            }
            else
            {
                _156 = _148;
            }
            if (_156)
            {
                continue;
            }
            float4 v = src0.Load(int4(int3(ix, iy, gid.z), 0));
            r += v;
            count++;
        }
    }
    r /= float(max(count_padded, 1)).xxxx;
    dst[int3(gid.xy, gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p04_pool_avg(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p04_pool_avg_inner();
}
