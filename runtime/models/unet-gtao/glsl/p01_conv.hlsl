static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

ByteAddressBuffer params : register(t16);
RWTexture2DArray<float4> dst : register(u0);
Texture2DArray<float4> src0 : register(t0);
SamplerState _src0_sampler : register(s0);
uniform int u_flip_y;
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

void p01_conv_inner()
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
    float4 acc = float4(asfloat(params.Load4((8 + gid.z) * 16 + 0)));
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 8);
            bool _138 = iy >= 0;
            bool _145;
            if (_138)
            {
                _145 = iy < size0.y;
            }
            else
            {
                _145 = _138;
            }
            bool _148 = _145 && (ix >= 0);
            bool _155;
            if (_148)
            {
                _155 = ix < size0.x;
            }
            else
            {
                _155 = _148;
            }
            if (_155)
            {
                int rx = clamp((src_size0.x - 1) - abs((src_size0.x - 1) - ix), 0, src_size0.x - 1);
                int ry = clamp((src_size0.y - 1) - abs((src_size0.y - 1) - iy), 0, src_size0.y - 1);
                if (u_flip_y != 0)
                {
                    ry = (src_size0.y - 1) - ry;
                }
                for (int l = 0; l < 2; l++)
                {
                    float4 _217 = src0.Load(int4(int3(rx, ry, l), 0));
                    int4 _225 = (4 * l).xxxx + int4(0, 1, 2, 3);
                    bool4 _229 = bool4(_225.x < int4(5, 5, 5, 5).x, _225.y < int4(5, 5, 5, 5).y, _225.z < int4(5, 5, 5, 5).z, _225.w < int4(5, 5, 5, 5).w);
                    float4 v = float4(_229.x ? _217.x : 0.0f.xxxx.x, _229.y ? _217.y : 0.0f.xxxx.y, _229.z ? _217.z : 0.0f.xxxx.z, _229.w ? _217.w : 0.0f.xxxx.w);
                    int o = tap + ((0 + l) * 4);
                    float4x4 _274 = float4x4(float4(asfloat(params.Load4(o * 16 + 0))), float4(asfloat(params.Load4((o + 1) * 16 + 0))), float4(asfloat(params.Load4((o + 2) * 16 + 0))), float4(asfloat(params.Load4((o + 3) * 16 + 0))));
                    acc += mul(float4(v), float4x4(_274[0], _274[1], _274[2], _274[3]));
                }
            }
        }
    }
    float4 r = float4(acc);
    r = max(r, 0.001000000047497451305389404296875f.xxxx);
    float4 a = src1.Load(int4(int3(0, 0, gid.z), 0));
    float4 b = r;
    int4 _322 = (4 * gid.z).xxxx + int4(0, 1, 2, 3);
    bool4 _324 = bool4(_322.x < int4(1, 1, 1, 1).x, _322.y < int4(1, 1, 1, 1).y, _322.z < int4(1, 1, 1, 1).z, _322.w < int4(1, 1, 1, 1).w);
    b = float4(_324.x ? b.x : 1.0f.xxxx.x, _324.y ? b.y : 1.0f.xxxx.y, _324.z ? b.z : 1.0f.xxxx.z, _324.w ? b.w : 1.0f.xxxx.w);
    r = a / b;
    r = min(max(r, 0.0f.xxxx), 8.0f.xxxx);
    dst[int3(gid.xy, gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p01_conv(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p01_conv_inner();
}
