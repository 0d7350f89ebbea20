static const uint3 gl_WorkGroupSize = uint3(1u, 1u, 1u);

cbuffer FrameUniforms : register(b0)
{
    float2 frame_u_proj : packoffset(c0);
    float frame_u_radius : packoffset(c0.z);
    float frame_u_pixels_per_unit : packoffset(c0.w);
    int frame_u_flip_y : packoffset(c1);
};

RWTexture2DArray<float4> dst : register(u0);

static uint3 gl_GlobalInvocationID;
struct SPIRV_Cross_Input
{
    uint3 gl_GlobalInvocationID : SV_DispatchThreadID;
};

uint3 spvImageSize(RWTexture2DArray<float4> Tex, out uint Param)
{
    uint3 ret;
    Tex.GetDimensions(ret.x, ret.y, ret.z);
    Param = 0u;
    return ret;
}

int2 nao_texel(int2 p, int2 size)
{
    int2 _35;
    if (frame_u_flip_y != 0)
    {
        _35 = p;
    }
    else
    {
        _35 = int2(p.x, (size.y - 1) - p.y);
    }
    return _35;
}

void nao_store(int2 p, int layer, float4 v)
{
    uint _62_dummy_parameter;
    int2 param = p;
    int2 param_1 = int3(spvImageSize(dst, _62_dummy_parameter)).xy;
    dst[int3(nao_texel(param, param_1), layer)] = v;
}

void f_network_radius_inner()
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    uint _83_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _83_dummy_parameter)).xy;
    bool _89 = gid.x >= out_size.x;
    bool _98;
    if (!_89)
    {
        _98 = gid.y >= out_size.y;
    }
    else
    {
        _98 = _89;
    }
    if (_98)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1);
    int2 param_2 = px;
    int param_3 = 0;
    float4 param_4 = float4(log(frame_u_radius * frame_u_proj.y), 0.0f, 0.0f, 0.0f);
    nao_store(param_2, param_3, param_4);
}

[numthreads(1, 1, 1)]
void f_network_radius(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    f_network_radius_inner();
}
