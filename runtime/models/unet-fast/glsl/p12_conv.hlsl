static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

ByteAddressBuffer params : register(t16);
RWTexture2DArray<float4> dst : register(u0);
Texture2DArray<float4> src0 : register(t0);
SamplerState _src0_sampler : register(s0);
Texture2DArray<float4> src1 : register(t1);
SamplerState _src1_sampler : register(s1);

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

void p12_conv_inner()
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
        _72 = gid.z >= 2;
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
    int2 size0 = int3(spvTextureSize(src0, uint(0), _84_dummy_parameter)).xy;
    uint _90_dummy_parameter;
    int2 size1 = int3(spvTextureSize(src1, uint(0), _90_dummy_parameter)).xy;
    float4 acc = asfloat(params.Load4((288 + gid.z) * 16 + 0));
    for (int ky = 0; ky < 3; ky++)
    {
        int iy = ((gid.y * 1) - 1) + (ky * 1);
        for (int kx = 0; kx < 3; kx++)
        {
            int ix = ((gid.x * 1) - 1) + (kx * 1);
            int tap = 0 + (((((gid.z * 3) + ky) * 3) + kx) * 16);
            bool _151 = iy >= 0;
            bool _158;
            if (_151)
            {
                _158 = iy < size0.y;
            }
            else
            {
                _158 = _151;
            }
            bool _161 = _158 && (ix >= 0);
            bool _168;
            if (_161)
            {
                _168 = ix < size0.x;
            }
            else
            {
                _168 = _161;
            }
            if (_168)
            {
                for (int l = 0; l < 2; l++)
                {
                    float4 v = src0.Load(int4(int3(ix, iy, l), 0));
                    int o = tap + ((0 + l) * 4);
                    float4x4 w = float4x4(float4(asfloat(params.Load4(o * 16 + 0))), float4(asfloat(params.Load4((o + 1) * 16 + 0))), float4(asfloat(params.Load4((o + 2) * 16 + 0))), float4(asfloat(params.Load4((o + 3) * 16 + 0))));
                    acc += float4(mul(float4(v), float4x4(w[0], w[1], w[2], w[3])));
                }
            }
            bool _257 = iy >= 0;
            bool _264;
            if (_257)
            {
                _264 = iy < size1.y;
            }
            else
            {
                _264 = _257;
            }
            bool _267 = _264 && (ix >= 0);
            bool _274;
            if (_267)
            {
                _274 = ix < size1.x;
            }
            else
            {
                _274 = _267;
            }
            if (_274)
            {
                for (int l_1 = 0; l_1 < 2; l_1++)
                {
                    float4 v_1 = src1.Load(int4(int3(ix, iy, l_1), 0));
                    int o_1 = tap + ((2 + l_1) * 4);
                    float4x4 w_1 = float4x4(float4(asfloat(params.Load4(o_1 * 16 + 0))), float4(asfloat(params.Load4((o_1 + 1) * 16 + 0))), float4(asfloat(params.Load4((o_1 + 2) * 16 + 0))), float4(asfloat(params.Load4((o_1 + 3) * 16 + 0))));
                    acc += float4(mul(float4(v_1), float4x4(w_1[0], w_1[1], w_1[2], w_1[3])));
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
void p12_conv(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p12_conv_inner();
}
