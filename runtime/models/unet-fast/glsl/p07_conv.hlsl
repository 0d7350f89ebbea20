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

void p07_conv_inner()
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
        _72 = gid.z >= 8;
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
    int2 size0 = src_size0 * int2(2, 2);
    float4 acc = asfloat(params.Load4((4608 + gid.z) * 16 + 0));
    int2 lo = src_size0 - int2(1, 1);
    int2 m = gid.xy / int2(2, 2);
    bool ox = (gid.x & 1) == 1;
    bool oy = (gid.y & 1) == 1;
    int x0 = clamp(m.x - 1, 0, lo.x);
    int x1 = clamp(m.x, 0, lo.x);
    int x2 = clamp(m.x + 1, 0, lo.x);
    int y0 = clamp(m.y - 1, 0, lo.y);
    int y1 = clamp(m.y, 0, lo.y);
    int y2 = clamp(m.y + 1, 0, lo.y);
    float wx = ox ? 0.75f : 0.25f;
    float wy = oy ? 0.75f : 0.25f;
    bool vx0 = gid.x >= 1;
    bool vx2 = (gid.x + 1) < size0.x;
    bool vy0 = gid.y >= 1;
    bool vy2 = (gid.y + 1) < size0.y;
    for (int l = 0; l < 16; l++)
    {
        float4 c00 = src0.Load(int4(int3(x0, y0, l), 0));
        float4 c01 = src0.Load(int4(int3(x1, y0, l), 0));
        float4 c02 = src0.Load(int4(int3(x2, y0, l), 0));
        float4 c10 = src0.Load(int4(int3(x0, y1, l), 0));
        float4 c11 = src0.Load(int4(int3(x1, y1, l), 0));
        float4 c12 = src0.Load(int4(int3(x2, y1, l), 0));
        float4 c20 = src0.Load(int4(int3(x0, y2, l), 0));
        float4 c21 = src0.Load(int4(int3(x1, y2, l), 0));
        float4 c22 = src0.Load(int4(int3(x2, y2, l), 0));
        float4 h00 = lerp(c00, c01, wx.xxxx);
        bool4 _285 = ox.xxxx;
        bool4 _290 = ox.xxxx;
        float4 h01 = lerp(float4(_285.x ? c01.x : c00.x, _285.y ? c01.y : c00.y, _285.z ? c01.z : c00.z, _285.w ? c01.w : c00.w), float4(_290.x ? c02.x : c01.x, _290.y ? c02.y : c01.y, _290.z ? c02.z : c01.z, _290.w ? c02.w : c01.w), (1.0f - wx).xxxx);
        float4 h02 = lerp(c01, c02, wx.xxxx);
        float4 h10 = lerp(c10, c11, wx.xxxx);
        bool4 _313 = ox.xxxx;
        bool4 _318 = ox.xxxx;
        float4 h11 = lerp(float4(_313.x ? c11.x : c10.x, _313.y ? c11.y : c10.y, _313.z ? c11.z : c10.z, _313.w ? c11.w : c10.w), float4(_318.x ? c12.x : c11.x, _318.y ? c12.y : c11.y, _318.z ? c12.z : c11.z, _318.w ? c12.w : c11.w), (1.0f - wx).xxxx);
        float4 h12 = lerp(c11, c12, wx.xxxx);
        float4 h20 = lerp(c20, c21, wx.xxxx);
        bool4 _340 = ox.xxxx;
        bool4 _345 = ox.xxxx;
        float4 h21 = lerp(float4(_340.x ? c21.x : c20.x, _340.y ? c21.y : c20.y, _340.z ? c21.z : c20.z, _340.w ? c21.w : c20.w), float4(_345.x ? c22.x : c21.x, _345.y ? c22.y : c21.y, _345.z ? c22.z : c21.z, _345.w ? c22.w : c21.w), (1.0f - wx).xxxx);
        float4 h22 = lerp(c21, c22, wx.xxxx);
        float4 u00 = lerp(h00, h10, wy.xxxx);
        float4 u01 = lerp(h01, h11, wy.xxxx);
        float4 u02 = lerp(h02, h12, wy.xxxx);
        bool4 _379 = oy.xxxx;
        bool4 _384 = oy.xxxx;
        float4 u10 = lerp(float4(_379.x ? h10.x : h00.x, _379.y ? h10.y : h00.y, _379.z ? h10.z : h00.z, _379.w ? h10.w : h00.w), float4(_384.x ? h20.x : h10.x, _384.y ? h20.y : h10.y, _384.z ? h20.z : h10.z, _384.w ? h20.w : h10.w), (1.0f - wy).xxxx);
        bool4 _394 = oy.xxxx;
        bool4 _399 = oy.xxxx;
        float4 u11 = lerp(float4(_394.x ? h11.x : h01.x, _394.y ? h11.y : h01.y, _394.z ? h11.z : h01.z, _394.w ? h11.w : h01.w), float4(_399.x ? h21.x : h11.x, _399.y ? h21.y : h11.y, _399.z ? h21.z : h11.z, _399.w ? h21.w : h11.w), (1.0f - wy).xxxx);
        bool4 _409 = oy.xxxx;
        bool4 _414 = oy.xxxx;
        float4 u12 = lerp(float4(_409.x ? h12.x : h02.x, _409.y ? h12.y : h02.y, _409.z ? h12.z : h02.z, _409.w ? h12.w : h02.w), float4(_414.x ? h22.x : h12.x, _414.y ? h22.y : h12.y, _414.z ? h22.z : h12.z, _414.w ? h22.w : h12.w), (1.0f - wy).xxxx);
        float4 u20 = lerp(h10, h20, wy.xxxx);
        float4 u21 = lerp(h11, h21, wy.xxxx);
        float4 u22 = lerp(h12, h22, wy.xxxx);
        int o = (0 + ((gid.z * 9) * 64)) + ((0 + l) * 4);
        if (vy0 && vx0)
        {
            int t0 = o + 0;
            float4x4 w0 = float4x4(float4(asfloat(params.Load4(t0 * 16 + 0))), float4(asfloat(params.Load4((t0 + 1) * 16 + 0))), float4(asfloat(params.Load4((t0 + 2) * 16 + 0))), float4(asfloat(params.Load4((t0 + 3) * 16 + 0))));
            acc += float4(mul(float4(u00), float4x4(w0[0], w0[1], w0[2], w0[3])));
        }
        if (vy0)
        {
            int t1 = o + 64;
            float4x4 w1 = float4x4(float4(asfloat(params.Load4(t1 * 16 + 0))), float4(asfloat(params.Load4((t1 + 1) * 16 + 0))), float4(asfloat(params.Load4((t1 + 2) * 16 + 0))), float4(asfloat(params.Load4((t1 + 3) * 16 + 0))));
            acc += float4(mul(float4(u01), float4x4(w1[0], w1[1], w1[2], w1[3])));
        }
        if (vy0 && vx2)
        {
            int t2 = o + 128;
            float4x4 w2 = float4x4(float4(asfloat(params.Load4(t2 * 16 + 0))), float4(asfloat(params.Load4((t2 + 1) * 16 + 0))), float4(asfloat(params.Load4((t2 + 2) * 16 + 0))), float4(asfloat(params.Load4((t2 + 3) * 16 + 0))));
            acc += float4(mul(float4(u02), float4x4(w2[0], w2[1], w2[2], w2[3])));
        }
        if (vx0)
        {
            int t3 = o + 192;
            float4x4 w3 = float4x4(float4(asfloat(params.Load4(t3 * 16 + 0))), float4(asfloat(params.Load4((t3 + 1) * 16 + 0))), float4(asfloat(params.Load4((t3 + 2) * 16 + 0))), float4(asfloat(params.Load4((t3 + 3) * 16 + 0))));
            acc += float4(mul(float4(u10), float4x4(w3[0], w3[1], w3[2], w3[3])));
        }
        if (true)
        {
            int t4 = o + 256;
            float4x4 w4 = float4x4(float4(asfloat(params.Load4(t4 * 16 + 0))), float4(asfloat(params.Load4((t4 + 1) * 16 + 0))), float4(asfloat(params.Load4((t4 + 2) * 16 + 0))), float4(asfloat(params.Load4((t4 + 3) * 16 + 0))));
            acc += float4(mul(float4(u11), float4x4(w4[0], w4[1], w4[2], w4[3])));
        }
        if (vx2)
        {
            int t5 = o + 320;
            float4x4 w5 = float4x4(float4(asfloat(params.Load4(t5 * 16 + 0))), float4(asfloat(params.Load4((t5 + 1) * 16 + 0))), float4(asfloat(params.Load4((t5 + 2) * 16 + 0))), float4(asfloat(params.Load4((t5 + 3) * 16 + 0))));
            acc += float4(mul(float4(u12), float4x4(w5[0], w5[1], w5[2], w5[3])));
        }
        if (vy2 && vx0)
        {
            int t6 = o + 384;
            float4x4 w6 = float4x4(float4(asfloat(params.Load4(t6 * 16 + 0))), float4(asfloat(params.Load4((t6 + 1) * 16 + 0))), float4(asfloat(params.Load4((t6 + 2) * 16 + 0))), float4(asfloat(params.Load4((t6 + 3) * 16 + 0))));
            acc += float4(mul(float4(u20), float4x4(w6[0], w6[1], w6[2], w6[3])));
        }
        if (vy2)
        {
            int t7 = o + 448;
            float4x4 w7 = float4x4(float4(asfloat(params.Load4(t7 * 16 + 0))), float4(asfloat(params.Load4((t7 + 1) * 16 + 0))), float4(asfloat(params.Load4((t7 + 2) * 16 + 0))), float4(asfloat(params.Load4((t7 + 3) * 16 + 0))));
            acc += float4(mul(float4(u21), float4x4(w7[0], w7[1], w7[2], w7[3])));
        }
        if (vy2 && vx2)
        {
            int t8 = o + 512;
            float4x4 w8 = float4x4(float4(asfloat(params.Load4(t8 * 16 + 0))), float4(asfloat(params.Load4((t8 + 1) * 16 + 0))), float4(asfloat(params.Load4((t8 + 2) * 16 + 0))), float4(asfloat(params.Load4((t8 + 3) * 16 + 0))));
            acc += float4(mul(float4(u22), float4x4(w8[0], w8[1], w8[2], w8[3])));
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    float param_1 = 0.00999999977648258209228515625f;
    r = nao_leaky_relu(param, param_1);
    dst[int3(gid.xy, gid.z)] = r;
}

[numthreads(8, 8, 1)]
void p07_conv(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    p07_conv_inner();
}
