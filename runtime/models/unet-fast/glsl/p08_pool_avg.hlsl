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

void p08_pool_avg_inner()
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
        _52 = gid.z >= 8;
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
        bool _92 = iy < 0;
        bool _101;
        if (!_92)
        {
            _101 = iy >= (in_size.y + 0);
        }
        else
        {
            _101 = _92;
        }
        if (_101)
        {
            continue;
        }
        for (int kx = 0; kx < 2; kx++)
        {
            int ix = ((gid.x * 2) - 0) + (kx * 1);
            bool _122 = ix < 0;
            bool _131;
            if (!_122)
            {
                _131 = ix >= (in_size.x + 0);
            }
            else
            {
                _131 = _122;
            }
            if (_131)
            {
                continue;
            }
            count_padded++;
            bool _138 = iy < 0;
            bool _146;
            if (!_138)
            {
                _146 = iy >= in_size.y;
            }
            else
            {
                _146 = _138;
            }
            bool _149 = _146 || (ix < 0);
            bool _157;
            if (!_149)
            {
                _157 = ix >= in_size.x;
            }
            else
            {
                _157 = _149;
            }
            if (_157)
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
void p08_pool_avg(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p08_pool_avg_inner();
}
