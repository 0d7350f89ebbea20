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

void p03_conv_inner()
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
    uint _70_dummy_parameter;
    int2 size1 = int3(spvTextureSize(src1, uint(0), _70_dummy_parameter)).xy;
    float4 acc = float4(asfloat(params.Load4((12 + gid.z) * 16 + 0)));
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 12);
            bool _135 = iy >= 0;
            bool _142;
            if (_135)
            {
                _142 = iy < size0.y;
            }
            else
            {
                _142 = _135;
            }
            bool _145 = _142 && (ix >= 0);
            bool _152;
            if (_145)
            {
                _152 = ix < size0.x;
            }
            else
            {
                _152 = _145;
            }
            if (_152)
            {
                for (int l = 0; l < 2; l++)
                {
                    float4 v = src0.Load(int4(int3(ix, iy, l), 0));
                    int o = tap + ((0 + l) * 4);
                    float4x4 _218 = float4x4(float4(asfloat(params.Load4(o * 16 + 0))), float4(asfloat(params.Load4((o + 1) * 16 + 0))), float4(asfloat(params.Load4((o + 2) * 16 + 0))), float4(asfloat(params.Load4((o + 3) * 16 + 0))));
                    acc += mul(float4(v), float4x4(_218[0], _218[1], _218[2], _218[3]));
                }
            }
            bool _236 = iy >= 0;
            bool _243;
            if (_236)
            {
                _243 = iy < size1.y;
            }
            else
            {
                _243 = _236;
            }
            bool _246 = _243 && (ix >= 0);
            bool _253;
            if (_246)
            {
                _253 = ix < size1.x;
            }
            else
            {
                _253 = _246;
            }
            if (_253)
            {
                for (int l_1 = 0; l_1 < 1; l_1++)
                {
                    float4 v_1 = src1.Load(int4(int3(ix, iy, l_1), 0));
                    int o_1 = tap + ((2 + l_1) * 4);
                    float4x4 _313 = float4x4(float4(asfloat(params.Load4(o_1 * 16 + 0))), float4(asfloat(params.Load4((o_1 + 1) * 16 + 0))), float4(asfloat(params.Load4((o_1 + 2) * 16 + 0))), float4(asfloat(params.Load4((o_1 + 3) * 16 + 0))));
                    acc += mul(float4(v_1), float4x4(_313[0], _313[1], _313[2], _313[3]));
                }
            }
        }
    }
    float4 r = float4(acc);
    dst[int3(gid.xy, gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p03_conv(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p03_conv_inner();
}
