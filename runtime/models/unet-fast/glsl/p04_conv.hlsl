static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

ByteAddressBuffer params : register(t16);
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

float4 nao_leaky_relu(float4 x, float alpha)
{
    float4 _17 = x * alpha;
    bool4 _24 = bool4(x.x >= 0.0f.xxxx.x, x.y >= 0.0f.xxxx.y, x.z >= 0.0f.xxxx.z, x.w >= 0.0f.xxxx.w);
    return float4(_24.x ? x.x : _17.x, _24.y ? x.y : _17.y, _24.z ? x.z : _17.z, _24.w ? x.w : _17.w);
}

void p04_conv_inner()
{
    int3 gid = int3(gl_GlobalInvocationID);
    uint _45_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _45_dummy_parameter)).xy;
    bool _53 = gid.x >= out_size.x;
    bool _63;
    if (!_53)
    {
        _63 = gid.y >= out_size.y;
    }
    else
    {
        _63 = _53;
    }
    bool _72;
    if (!_63)
    {
        _72 = gid.z >= 4;
    }
    else
    {
        _72 = _63;
    }
    if (_72)
    {
        return;
    }
    uint _84_dummy_parameter;
    int2 src_size0 = int3(spvTextureSize(src0, uint(0), _84_dummy_parameter)).xy;
    int2 size0 = src_size0 / int2(2, 2);
    float4 acc = asfloat(params.Load4((288 + gid.z) * 16 + 0));
    for (int ky = 0; ky < 3; ky++)
    {
        int iy = ((gid.y * 1) - 1) + (ky * 1);
        for (int kx = 0; kx < 3; kx++)
        {
            int ix = ((gid.x * 1) - 1) + (kx * 1);
            int tap = 0 + (((((gid.z * 3) + ky) * 3) + kx) * 8);
            bool _150 = iy >= 0;
            bool _157;
            if (_150)
            {
                _157 = iy < size0.y;
            }
            else
            {
                _157 = _150;
            }
            bool _160 = _157 && (ix >= 0);
            bool _167;
            if (_160)
            {
                _167 = ix < size0.x;
            }
            else
            {
                _167 = _160;
            }
            if (_167)
            {
                for (int l = 0; l < 2; l++)
                {
                    float4 v = (((src0.Load(int4(int3(2 * ix, 2 * iy, l), 0)) + src0.Load(int4(int3((2 * ix) + 1, 2 * iy, l), 0))) + src0.Load(int4(int3(2 * ix, (2 * iy) + 1, l), 0))) + src0.Load(int4(int3((2 * ix) + 1, (2 * iy) + 1, l), 0))) / 4.0f.xxxx;
                    int o = tap + ((0 + l) * 4);
                    float4x4 w = float4x4(float4(asfloat(params.Load4(o * 16 + 0))), float4(asfloat(params.Load4((o + 1) * 16 + 0))), float4(asfloat(params.Load4((o + 2) * 16 + 0))), float4(asfloat(params.Load4((o + 3) * 16 + 0))));
                    acc += float4(mul(float4(v), float4x4(w[0], w[1], w[2], w[3])));
                }
            }
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    float param_1 = 0.00999999977648258209228515625f;
    r = nao_leaky_relu(param, param_1);
    dst[int3(gid.xy, gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p04_conv(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p04_conv_inner();
}
