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
    float4 acc = float4(asfloat(params.Load4((4 + gid.z) * 16 + 0)));
    for (int ky = 0; ky < 1; ky++)
    {
        int iy = ((gid.y * 1) - 0) + (ky * 1);
        for (int kx = 0; kx < 1; kx++)
        {
            int ix = ((gid.x * 1) - 0) + (kx * 1);
            int tap = 0 + (((((gid.z * 1) + ky) * 1) + kx) * 4);
            bool _139 = iy >= 0;
            bool _146;
            if (_139)
            {
                _146 = iy < size0.y;
            }
            else
            {
                _146 = _139;
            }
            bool _149 = _146 && (ix >= 0);
            bool _156;
            if (_149)
            {
                _156 = ix < size0.x;
            }
            else
            {
                _156 = _149;
            }
            if (_156)
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
                    float4x4 _262 = float4x4(float4(asfloat(params.Load4(o * 16 + 0))), float4(asfloat(params.Load4((o + 1) * 16 + 0))), float4(asfloat(params.Load4((o + 2) * 16 + 0))), float4(asfloat(params.Load4((o + 3) * 16 + 0))));
                    acc += mul(float4(v), float4x4(_262[0], _262[1], _262[2], _262[3]));
                }
            }
        }
    }
    float4 r = float4(acc);
    r = max(r, 0.001000000047497451305389404296875f.xxxx);
    float4 a = src1.Load(int4(int3(0, 0, gid.z), 0));
    float4 b = r;
    int4 _312 = (4 * gid.z).xxxx + int4(0, 1, 2, 3);
    bool4 _315 = bool4(_312.x < int4(1, 1, 1, 1).x, _312.y < int4(1, 1, 1, 1).y, _312.z < int4(1, 1, 1, 1).z, _312.w < int4(1, 1, 1, 1).w);
    b = float4(_315.x ? b.x : 1.0f.xxxx.x, _315.y ? b.y : 1.0f.xxxx.y, _315.z ? b.z : 1.0f.xxxx.z, _315.w ? b.w : 1.0f.xxxx.w);
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
