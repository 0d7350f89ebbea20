static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

ByteAddressBuffer params : register(t16);
RWTexture2DArray<float4> dst : register(u0);
Texture2DArray<float4> src0 : register(t0);
SamplerState _src0_sampler : register(s0);
Texture2DArray<float4> src1 : register(t1);
SamplerState _src1_sampler : register(s1);
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

void p13_conv_inner()
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
    int2 size0 = int3(spvTextureSize(src0, uint(0), _64_dummy_parameter)).xy;
    float4 acc = float4(asfloat(params.Load4((4 + gid.z) * 16 + 0)));
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 4);
            bool _129 = iy >= 0;
            bool _136;
            if (_129)
            {
                _136 = iy < size0.y;
            }
            else
            {
                _136 = _129;
            }
            bool _139 = _136 && (ix >= 0);
            bool _146;
            if (_139)
            {
                _146 = ix < size0.x;
            }
            else
            {
                _146 = _139;
            }
            if (_146)
            {
                for (int l = 0; l < 1; l++)
                {
                    float4 v = src0.Load(int4(int3(ix, iy, l), 0));
                    int o = tap + ((0 + l) * 4);
                    float4x4 _211 = float4x4(float4(asfloat(params.Load4(o * 16 + 0))), float4(asfloat(params.Load4((o + 1) * 16 + 0))), float4(asfloat(params.Load4((o + 2) * 16 + 0))), float4(asfloat(params.Load4((o + 3) * 16 + 0))));
                    acc += mul(float4(v), float4x4(_211[0], _211[1], _211[2], _211[3]));
                }
            }
        }
    }
    float4 r = float4(acc);
    float4 a = src1.Load(int4(int3(gid.xy, gid.z), 0));
    float4 b = r;
    r = a + b;
    r = min(max(r, 0.0f.xxxx), 1.0f.xxxx);
    int _268;
    if (u_flip_y != 0)
    {
        _268 = (out_size.y - 1) - gid.y;
    }
    else
    {
        _268 = gid.y;
    }
    dst[int3(int2(gid.x, _268), gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p13_conv(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p13_conv_inner();
}
