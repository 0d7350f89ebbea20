#pragma clang diagnostic ignored "-Wmissing-prototypes"

#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

struct Params
{
    float4 prm[1];
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

static inline __attribute__((always_inline))
float4 nao_leaky_relu(thread const float4& x, thread const float& alpha)
{
    return select(x * alpha, x, x >= float4(0.0));
}

kernel void p11_conv(const device Params& params [[buffer(1)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], sampler src0Smplr [[sampler(1)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int3 gid = int3(gl_GlobalInvocationID);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
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
    int2 src_size0 = int3(src0.get_width(), src0.get_height(), src0.get_array_size()).xy;
    int2 size0 = src_size0 * int2(2);
    float4 acc = params.prm[288 + gid.z];
    int2 lo = src_size0 - int2(1);
    int2 m = gid.xy / int2(2);
    bool ox = (gid.x & 1) == 1;
    bool oy = (gid.y & 1) == 1;
    int x0 = clamp(m.x - 1, 0, lo.x);
    int x1 = clamp(m.x, 0, lo.x);
    int x2 = clamp(m.x + 1, 0, lo.x);
    int y0 = clamp(m.y - 1, 0, lo.y);
    int y1 = clamp(m.y, 0, lo.y);
    int y2 = clamp(m.y + 1, 0, lo.y);
    float wx = ox ? 0.75 : 0.25;
    float wy = oy ? 0.75 : 0.25;
    bool vx0 = gid.x >= 1;
    bool vx2 = (gid.x + 1) < size0.x;
    bool vy0 = gid.y >= 1;
    bool vy2 = (gid.y + 1) < size0.y;
    for (int l = 0; l < 4; l++)
    {
        int3 _207 = int3(x0, y0, l);
        float4 c00 = src0.read(uint2(_207.xy), uint(_207.z), 0);
        int3 _215 = int3(x1, y0, l);
        float4 c01 = src0.read(uint2(_215.xy), uint(_215.z), 0);
        int3 _223 = int3(x2, y0, l);
        float4 c02 = src0.read(uint2(_223.xy), uint(_223.z), 0);
        int3 _231 = int3(x0, y1, l);
        float4 c10 = src0.read(uint2(_231.xy), uint(_231.z), 0);
        int3 _239 = int3(x1, y1, l);
        float4 c11 = src0.read(uint2(_239.xy), uint(_239.z), 0);
        int3 _247 = int3(x2, y1, l);
        float4 c12 = src0.read(uint2(_247.xy), uint(_247.z), 0);
        int3 _255 = int3(x0, y2, l);
        float4 c20 = src0.read(uint2(_255.xy), uint(_255.z), 0);
        int3 _263 = int3(x1, y2, l);
        float4 c21 = src0.read(uint2(_263.xy), uint(_263.z), 0);
        int3 _271 = int3(x2, y2, l);
        float4 c22 = src0.read(uint2(_271.xy), uint(_271.z), 0);
        float4 h00 = mix(c00, c01, float4(wx));
        float4 h01 = mix(select(c00, c01, bool4(ox)), select(c01, c02, bool4(ox)), float4(1.0 - wx));
        float4 h02 = mix(c01, c02, float4(wx));
        float4 h10 = mix(c10, c11, float4(wx));
        float4 h11 = mix(select(c10, c11, bool4(ox)), select(c11, c12, bool4(ox)), float4(1.0 - wx));
        float4 h12 = mix(c11, c12, float4(wx));
        float4 h20 = mix(c20, c21, float4(wx));
        float4 h21 = mix(select(c20, c21, bool4(ox)), select(c21, c22, bool4(ox)), float4(1.0 - wx));
        float4 h22 = mix(c21, c22, float4(wx));
        float4 u00 = mix(h00, h10, float4(wy));
        float4 u01 = mix(h01, h11, float4(wy));
        float4 u02 = mix(h02, h12, float4(wy));
        float4 u10 = mix(select(h00, h10, bool4(oy)), select(h10, h20, bool4(oy)), float4(1.0 - wy));
        float4 u11 = mix(select(h01, h11, bool4(oy)), select(h11, h21, bool4(oy)), float4(1.0 - wy));
        float4 u12 = mix(select(h02, h12, bool4(oy)), select(h12, h22, bool4(oy)), float4(1.0 - wy));
        float4 u20 = mix(h10, h20, float4(wy));
        float4 u21 = mix(h11, h21, float4(wy));
        float4 u22 = mix(h12, h22, float4(wy));
        int o = (0 + ((gid.z * 9) * 16)) + ((0 + l) * 4);
        if (vy0 && vx0)
        {
            int t0 = o + 0;
            float4x4 w0 = float4x4(float4(params.prm[t0]), float4(params.prm[t0 + 1]), float4(params.prm[t0 + 2]), float4(params.prm[t0 + 3]));
            acc += float4(float4x4(w0[0], w0[1], w0[2], w0[3]) * float4(u00));
        }
        if (vy0)
        {
            int t1 = o + 16;
            float4x4 w1 = float4x4(float4(params.prm[t1]), float4(params.prm[t1 + 1]), float4(params.prm[t1 + 2]), float4(params.prm[t1 + 3]));
            acc += float4(float4x4(w1[0], w1[1], w1[2], w1[3]) * float4(u01));
        }
        if (vy0 && vx2)
        {
            int t2 = o + 32;
            float4x4 w2 = float4x4(float4(params.prm[t2]), float4(params.prm[t2 + 1]), float4(params.prm[t2 + 2]), float4(params.prm[t2 + 3]));
            acc += float4(float4x4(w2[0], w2[1], w2[2], w2[3]) * float4(u02));
        }
        if (vx0)
        {
            int t3 = o + 48;
            float4x4 w3 = float4x4(float4(params.prm[t3]), float4(params.prm[t3 + 1]), float4(params.prm[t3 + 2]), float4(params.prm[t3 + 3]));
            acc += float4(float4x4(w3[0], w3[1], w3[2], w3[3]) * float4(u10));
        }
        if (true)
        {
            int t4 = o + 64;
            float4x4 w4 = float4x4(float4(params.prm[t4]), float4(params.prm[t4 + 1]), float4(params.prm[t4 + 2]), float4(params.prm[t4 + 3]));
            acc += float4(float4x4(w4[0], w4[1], w4[2], w4[3]) * float4(u11));
        }
        if (vx2)
        {
            int t5 = o + 80;
            float4x4 w5 = float4x4(float4(params.prm[t5]), float4(params.prm[t5 + 1]), float4(params.prm[t5 + 2]), float4(params.prm[t5 + 3]));
            acc += float4(float4x4(w5[0], w5[1], w5[2], w5[3]) * float4(u12));
        }
        if (vy2 && vx0)
        {
            int t6 = o + 96;
            float4x4 w6 = float4x4(float4(params.prm[t6]), float4(params.prm[t6 + 1]), float4(params.prm[t6 + 2]), float4(params.prm[t6 + 3]));
            acc += float4(float4x4(w6[0], w6[1], w6[2], w6[3]) * float4(u20));
        }
        if (vy2)
        {
            int t7 = o + 112;
            float4x4 w7 = float4x4(float4(params.prm[t7]), float4(params.prm[t7 + 1]), float4(params.prm[t7 + 2]), float4(params.prm[t7 + 3]));
            acc += float4(float4x4(w7[0], w7[1], w7[2], w7[3]) * float4(u21));
        }
        if (vy2 && vx2)
        {
            int t8 = o + 128;
            float4x4 w8 = float4x4(float4(params.prm[t8]), float4(params.prm[t8 + 1]), float4(params.prm[t8 + 2]), float4(params.prm[t8 + 3]));
            acc += float4(float4x4(w8[0], w8[1], w8[2], w8[3]) * float4(u22));
        }
    }
    float4 r = float4(acc);
    float4 param = r;
    float param_1 = 0.00999999977648258209228515625;
    r = nao_leaky_relu(param, param_1);
    int3 _1055 = int3(gid.xy, gid.z);
    dst.write(r, uint2(_1055.xy), uint(_1055.z));
}

