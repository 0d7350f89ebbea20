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

void p02_conv_inner()
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
    int2 src_size0 = int3(spvTextureSize(src0, uint(0), _64_dummy_parameter)).xy;
    int2 size0 = ((src_size0 + int2(7, 7)) / int2(8, 8)) * int2(8, 8);
    uint _80_dummy_parameter;
    int2 size1 = int3(spvTextureSize(src1, uint(0), _80_dummy_parameter)).xy;
    float4 acc = float4(asfloat(params.Load4((12 + gid.z) * 16 + 0)));
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 12);
            bool _145 = iy >= 0;
            bool _152;
            if (_145)
            {
                _152 = iy < size0.y;
            }
            else
            {
                _152 = _145;
            }
            bool _155 = _152 && (ix >= 0);
            bool _162;
            if (_155)
            {
                _162 = ix < size0.x;
            }
            else
            {
                _162 = _155;
            }
            if (_162)
            {
                int rx = clamp((src_size0.x - 1) - abs((src_size0.x - 1) - ix), 0, src_size0.x - 1);
                int ry = clamp((src_size0.y - 1) - abs((src_size0.y - 1) - iy), 0, src_size0.y - 1);
                if (u_flip_y != 0)
                {
                    ry = (src_size0.y - 1) - ry;
                }
                for (int l = 0; l < 2; l++)
                {
                    float4 _224 = src0.Load(int4(int3(rx, ry, l), 0));
                    int4 _232 = (4 * l).xxxx + int4(0, 1, 2, 3);
                    bool4 _236 = bool4(_232.x < int4(5, 5, 5, 5).x, _232.y < int4(5, 5, 5, 5).y, _232.z < int4(5, 5, 5, 5).z, _232.w < int4(5, 5, 5, 5).w);
                    float4 v = float4(_236.x ? _224.x : 0.0f.xxxx.x, _236.y ? _224.y : 0.0f.xxxx.y, _236.z ? _224.z : 0.0f.xxxx.z, _236.w ? _224.w : 0.0f.xxxx.w);
                    int o = tap + ((0 + l) * 4);
                    float4x4 _281 = float4x4(float4(asfloat(params.Load4(o * 16 + 0))), float4(asfloat(params.Load4((o + 1) * 16 + 0))), float4(asfloat(params.Load4((o + 2) * 16 + 0))), float4(asfloat(params.Load4((o + 3) * 16 + 0))));
                    acc += mul(float4(v), float4x4(_281[0], _281[1], _281[2], _281[3]));
                }
            }
            bool _299 = iy >= 0;
            bool _306;
            if (_299)
            {
                _306 = iy < size1.y;
            }
            else
            {
                _306 = _299;
            }
            bool _309 = _306 && (ix >= 0);
            bool _316;
            if (_309)
            {
                _316 = ix < size1.x;
            }
            else
            {
                _316 = _309;
            }
            if (_316)
            {
                for (int l_1 = 0; l_1 < 1; l_1++)
                {
                    float4 v_1 = src1.Load(int4(int3(ix, iy, l_1), 0));
                    int o_1 = tap + ((2 + l_1) * 4);
                    float4x4 _376 = float4x4(float4(asfloat(params.Load4(o_1 * 16 + 0))), float4(asfloat(params.Load4((o_1 + 1) * 16 + 0))), float4(asfloat(params.Load4((o_1 + 2) * 16 + 0))), float4(asfloat(params.Load4((o_1 + 3) * 16 + 0))));
                    acc += mul(float4(v_1), float4x4(_376[0], _376[1], _376[2], _376[3]));
                }
            }
        }
    }
    float4 r = float4(acc);
    dst[int3(gid.xy, gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p02_conv(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p02_conv_inner();
}
