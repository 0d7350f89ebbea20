static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

ByteAddressBuffer params : register(t16);
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

float4 nao_sigmoid(float4 x)
{
    float4 e = exp(-abs(x));
    float4 r = 1.0f.xxxx / (1.0f.xxxx + e);
    float4 _27 = e * r;
    bool4 _34 = bool4(x.x >= 0.0f.xxxx.x, x.y >= 0.0f.xxxx.y, x.z >= 0.0f.xxxx.z, x.w >= 0.0f.xxxx.w);
    return float4(_34.x ? r.x : _27.x, _34.y ? r.y : _27.y, _34.z ? r.z : _27.z, _34.w ? r.w : _27.w);
}

void p13_conv_inner()
{
    int3 gid = int3(gl_GlobalInvocationID);
    uint _55_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _55_dummy_parameter)).xy;
    bool _63 = gid.x >= out_size.x;
    bool _73;
    if (!_63)
    {
        _73 = gid.y >= out_size.y;
    }
    else
    {
        _73 = _63;
    }
    bool _82;
    if (!_73)
    {
        _82 = gid.z >= 1;
    }
    else
    {
        _82 = _73;
    }
    if (_82)
    {
        return;
    }
    uint _94_dummy_parameter;
    int2 size0 = int3(spvTextureSize(src0, uint(0), _94_dummy_parameter)).xy;
    float4 acc = asfloat(params.Load4((8 + gid.z) * 16 + 0));
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 8);
            bool _152 = iy >= 0;
            bool _159;
            if (_152)
            {
                _159 = iy < size0.y;
            }
            else
            {
                _159 = _152;
            }
            bool _162 = _159 && (ix >= 0);
            bool _169;
            if (_162)
            {
                _169 = ix < size0.x;
            }
            else
            {
                _169 = _162;
            }
            if (_169)
            {
                for (int l = 0; l < 2; l++)
                {
                    float4 v = src0.Load(int4(int3(ix, iy, l), 0));
                    int o = tap + ((0 + l) * 4);
                    float4x4 w = float4x4(float4(asfloat(params.Load4(o * 16 + 0))), float4(asfloat(params.Load4((o + 1) * 16 + 0))), float4(asfloat(params.Load4((o + 2) * 16 + 0))), float4(asfloat(params.Load4((o + 3) * 16 + 0))));
                    acc += float4(mul(float4(v), float4x4(w[0], w[1], w[2], w[3])));
                }
            }
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    r = nao_sigmoid(param);
    int _279;
    if (u_flip_y != 0)
    {
        _279 = (out_size.y - 1) - gid.y;
    }
    else
    {
        _279 = gid.y;
    }
    dst[int3(int2(gid.x, _279), gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p13_conv(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p13_conv_inner();
}
