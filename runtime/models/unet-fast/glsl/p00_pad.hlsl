static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

RWTexture2DArray<float4> dst : register(u0);
Texture2DArray<float4> src0 : register(t0);
SamplerState _src0_sampler : register(s0);
uniform int u_flip_y;

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

void p00_pad_inner()
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
        _52 = gid.z >= 1;
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
    int _72;
    if (gid.x < in_size.x)
    {
        _72 = gid.x;
    }
    else
    {
        _72 = (2 * (in_size.x - 1)) - gid.x;
    }
    int x = _72;
    int _93;
    if (gid.y < in_size.y)
    {
        _93 = gid.y;
    }
    else
    {
        _93 = (2 * (in_size.y - 1)) - gid.y;
    }
    int y = _93;
    x = clamp(x, 0, in_size.x - 1);
    y = clamp(y, 0, in_size.y - 1);
    if (u_flip_y != 0)
    {
        y = (in_size.y - 1) - y;
    }
    float4 r = src0.Load(int4(int3(x, y, gid.z), 0));
    dst[int3(gid.xy, gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p00_pad(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p00_pad_inner();
}
