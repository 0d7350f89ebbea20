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

float4 nao_leaky_relu(float4 x, float alpha)
{
    float4 _17 = x * alpha;
    bool4 _24 = bool4(x.x >= 0.0f.xxxx.x, x.y >= 0.0f.xxxx.y, x.z >= 0.0f.xxxx.z, x.w >= 0.0f.xxxx.w);
    return float4(_24.x ? x.x : _17.x, _24.y ? x.y : _17.y, _24.z ? x.z : _17.z, _24.w ? x.w : _17.w);
}

void p02_conv_inner()
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
    int2 src_size0 = int3(spvTextureSize(src0, uint(0), _84_dummy_parameter)).xy;
    int2 size0 = ((src_size0 + int2(7, 7)) / int2(8, 8)) * int2(8, 8);
    uint _100_dummy_parameter;
    int2 size1 = int3(spvTextureSize(src1, uint(0), _100_dummy_parameter)).xy;
    float4 acc = float4(asfloat(params.Load4((144 + gid.z) * 16 + 0)));
    for (int ky = 0; ky < 3; ky++)
    {
        int iy = ((gid.y * 1) - 1) + (ky * 1);
        for (int kx = 0; kx < 3; kx++)
        {
            int ix = ((gid.x * 1) - 1) + (kx * 1);
            int tap = 0 + (((((gid.z * 3) + ky) * 3) + kx) * 8);
            bool _165 = iy >= 0;
            bool _172;
            if (_165)
            {
                _172 = iy < size0.y;
            }
            else
            {
                _172 = _165;
            }
            bool _175 = _172 && (ix >= 0);
            bool _182;
            if (_175)
            {
                _182 = ix < size0.x;
            }
            else
            {
                _182 = _175;
            }
            if (_182)
            {
                int rx = clamp((src_size0.x - 1) - abs((src_size0.x - 1) - ix), 0, src_size0.x - 1);
                int ry = clamp((src_size0.y - 1) - abs((src_size0.y - 1) - iy), 0, src_size0.y - 1);
                if (u_flip_y != 0)
                {
                    ry = (src_size0.y - 1) - ry;
                }
                for (int l = 0; l < 1; l++)
                {
                    float4 v = src0.Load(int4(int3(rx, ry, l), 0));
                    int o = tap + ((0 + l) * 4);
                    float4x4 _286 = float4x4(float4(asfloat(params.Load4(o * 16 + 0))), float4(asfloat(params.Load4((o + 1) * 16 + 0))), float4(asfloat(params.Load4((o + 2) * 16 + 0))), float4(asfloat(params.Load4((o + 3) * 16 + 0))));
                    acc += mul(float4(v), float4x4(_286[0], _286[1], _286[2], _286[3]));
                }
            }
            bool _304 = iy >= 0;
            bool _311;
            if (_304)
            {
                _311 = iy < size1.y;
            }
            else
            {
                _311 = _304;
            }
            bool _314 = _311 && (ix >= 0);
            bool _321;
            if (_314)
            {
                _321 = ix < size1.x;
            }
            else
            {
                _321 = _314;
            }
            if (_321)
            {
                for (int l_1 = 0; l_1 < 1; l_1++)
                {
                    float4 v_1 = src1.Load(int4(int3(ix, iy, l_1), 0));
                    int o_1 = tap + ((1 + l_1) * 4);
                    float4x4 _381 = float4x4(float4(asfloat(params.Load4(o_1 * 16 + 0))), float4(asfloat(params.Load4((o_1 + 1) * 16 + 0))), float4(asfloat(params.Load4((o_1 + 2) * 16 + 0))), float4(asfloat(params.Load4((o_1 + 3) * 16 + 0))));
                    acc += mul(float4(v_1), float4x4(_381[0], _381[1], _381[2], _381[3]));
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
void p02_conv(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p02_conv_inner();
}
