static const uint3 gl_WorkGroupSize = uint3(8u, 8u, 1u);

static const float2 _385[64] = { float2(0.95628654956817626953125f, 0.29243123531341552734375f), float2(0.4694166481494903564453125f, 0.8829767704010009765625f), float2(-0.29243123531341552734375f, 0.95628654956817626953125f), float2(-0.882976830005645751953125f, 0.46941661834716796875f), float2(0.72424972057342529296875f, 0.6895377635955810546875f), float2(0.02454506792128086090087890625f, 0.999698698520660400390625f), float2(-0.6895377635955810546875f, 0.724249780178070068359375f), float2(-0.999698698520660400390625f, 0.0245450250804424285888671875f), float2(0.997950136661529541015625f, 0.063995897769927978515625f), float2(0.6604053974151611328125f, 0.750909268856048583984375f), float2(-0.0639958679676055908203125f, 0.997950136661529541015625f), float2(-0.750909268856048583984375f, 0.660405337810516357421875f), float2(0.999986708164215087890625f, 0.005155663006007671356201171875f), float2(0.703451812267303466796875f, 0.710742950439453125f), float2(-0.0051557035185396671295166015625f, 0.999986708164215087890625f), float2(-0.71074306964874267578125f, 0.703451693058013916015625f), float2(0.780055701732635498046875f, 0.625710070133209228515625f), float2(0.109138883650302886962890625f, 0.994026482105255126953125f), float2(-0.62571012973785400390625f, 0.780055701732635498046875f), float2(-0.994026482105255126953125f, 0.109138958156108856201171875f), float2(0.807158946990966796875f, 0.5903341770172119140625f), float2(0.15331827104091644287109375f, 0.988176882266998291015625f), float2(-0.590334117412567138671875f, 0.807158946990966796875f), float2(-0.988176882266998291015625f, 0.153318226337432861328125f), float2(0.961661756038665771484375f, 0.2742382586002349853515625f), float2(0.4860818088054656982421875f, 0.873913288116455078125f), float2(-0.2742383778095245361328125f, 0.961661756038665771484375f), float2(-0.87391340732574462890625f, 0.486081659793853759765625f), float2(0.839098155498504638671875f, 0.54398000240325927734375f), float2(0.20867989957332611083984375f, 0.977984011173248291015625f), float2(-0.54398024082183837890625f, 0.839098036289215087890625f), float2(-0.977984011173248291015625f, 0.208679974079132080078125f), float2(0.87093448638916015625f, 0.491399109363555908203125f), float2(0.2683719694614410400390625f, 0.96331536769866943359375f), float2(-0.4913992583751678466796875f, 0.870934426784515380859375f), float2(-0.963315427303314208984375f, 0.2683718204498291015625f), float2(0.994179308414459228515625f, 0.107738263905048370361328125f), float2(0.6268084049224853515625f, 0.779173433780670166015625f), float2(-0.1077382266521453857421875f, 0.994179308414459228515625f), float2(-0.779173374176025390625f, 0.6268084049224853515625f), float2(0.925171077251434326171875f, 0.3795504271984100341796875f), float2(0.3858120441436767578125f, 0.922577381134033203125f), float2(-0.379550516605377197265625f, 0.92517101764678955078125f), float2(-0.922577440738677978515625f, 0.385811984539031982421875f), float2(0.916310012340545654296875f, 0.400469720363616943359375f), float2(0.3647541105747222900390625f, 0.931103885173797607421875f), float2(-0.400469839572906494140625f, 0.91630995273590087890625f), float2(-0.931103885173797607421875f, 0.3647540509700775146484375f), float2(0.74443542957305908203125f, 0.66769444942474365234375f), float2(0.054264061152935028076171875f, 0.998526632785797119140625f), float2(-0.66769444942474365234375f, 0.74443542957305908203125f), float2(-0.998526632785797119140625f, 0.054264016449451446533203125f), float2(0.978735625743865966796875f, 0.20512570440769195556640625f), float2(0.547024786472320556640625f, 0.837116420269012451171875f), float2(-0.20512568950653076171875f, 0.978735625743865966796875f), float2(-0.83711636066436767578125f, 0.54702484607696533203125f), float2(0.987210571765899658203125f, 0.159421741962432861328125f), float2(0.585335075855255126953125f, 0.810791492462158203125f), float2(-0.1594218909740447998046875f, 0.987210571765899658203125f), float2(-0.810791552066802978515625f, 0.5853350162506103515625f), float2(0.896269977092742919921875f, 0.4435088932514190673828125f), float2(0.32015049457550048828125f, 0.9473667144775390625f), float2(-0.4435087740421295166015625f, 0.8962700366973876953125f), float2(-0.9473667144775390625f, 0.3201504647731781005859375f) };
static const float _414[16] = { 0.1678416728973388671875f, 0.7069942951202392578125f, 0.599261462688446044921875f, 0.521755874156951904296875f, 0.293343722820281982421875f, 0.8365204334259033203125f, 0.930650174617767333984375f, 0.747238457202911376953125f, 0.18946956098079681396484375f, 0.517999827861785888671875f, 0.862544834613800048828125f, 0.896280705928802490234375f, 0.195674479007720947265625f, 0.0488224588334560394287109375f, 0.999011993408203125f, 0.251001894474029541015625f };

cbuffer FrameUniforms : register(b0)
{
    float2 frame_u_proj : packoffset(c0);
    float frame_u_radius : packoffset(c0.z);
    float frame_u_pixels_per_unit : packoffset(c0.w);
    int frame_u_flip_y : packoffset(c1);
};

RWTexture2DArray<float> dst : register(u0);
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

uint3 spvImageSize(RWTexture2DArray<float> Tex, out uint Param)
{
    uint3 ret;
    Tex.GetDimensions(ret.x, ret.y, ret.z);
    Param = 0u;
    return ret;
}

int2 nao_texel(int2 p, int2 size)
{
    int2 _78;
    if (frame_u_flip_y != 0)
    {
        _78 = p;
    }
    else
    {
        _78 = int2(p.x, (size.y - 1) - p.y);
    }
    return _78;
}

int2 nao_size(Texture2DArray<float4> t, SamplerState _t_sampler)
{
    uint _102_dummy_parameter;
    return int3(spvTextureSize(t, uint(0), _102_dummy_parameter)).xy;
}

float4 nao_load(Texture2DArray<float4> t, SamplerState _t_sampler, int2 p, int layer)
{
    int2 param = p;
    int2 param_1 = nao_size(t, _t_sampler);
    return t.Load(int4(int3(nao_texel(param, param_1), layer), 0));
}

void nao_store(int2 p, int layer, float4 v)
{
    uint _125_dummy_parameter;
    int2 param = p;
    int2 param_1 = int3(spvImageSize(dst, _125_dummy_parameter)).xy;
    dst[int3(nao_texel(param, param_1), layer)] = v.x;
}

float3 nao_position(int2 p, int2 size, float z)
{
    float2 ndc = (((float2(p) + 0.5f.xx) / float2(size)) * 2.0f) - 1.0f.xx;
    return float3((ndc.x / frame_u_proj.x) * z, (ndc.y / frame_u_proj.y) * z, -z);
}

int nao_tile(int2 p)
{
    return ((p.y % 4) * 4) + (p.x % 4);
}

float nao_jitter(int tile)
{
    return _414[tile];
}

float2 nao_direction(int tile, int slice)
{
    return _385[(tile * 4) + slice];
}

float nao_acos(float x)
{
    return acos(clamp(x, -1.0f, 1.0f));
}

bool nao_inside(int2 q, int2 size)
{
    bool _140 = all(bool2(q.x >= int2(0, 0).x, q.y >= int2(0, 0).y));
    bool _147;
    if (_140)
    {
        _147 = all(bool2(q.x < size.x, q.y < size.y));
    }
    else
    {
        _147 = _140;
    }
    return _147;
}

void f_gtao_inner()
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    uint _432_dummy_parameter;
    int2 out_size = int3(spvImageSize(dst, _432_dummy_parameter)).xy;
    bool _438 = gid.x >= out_size.x;
    bool _447;
    if (!_438)
    {
        _447 = gid.y >= out_size.y;
    }
    else
    {
        _447 = _438;
    }
    if (_447)
    {
        return;
    }
    int2 param = gid;
    int2 param_1 = out_size;
    int2 px = nao_texel(param, param_1);
    int2 param_2 = px;
    int param_3 = 0;
    float z = nao_load(src0, _src0_sampler, param_2, param_3).x;
    if (!(z > 0.0f))
    {
        int2 param_4 = px;
        int param_5 = 0;
        float4 param_6 = 1.0f.xxxx;
        nao_store(param_4, param_5, param_6);
        return;
    }
    int2 param_7 = px;
    int2 param_8 = out_size;
    float param_9 = z;
    float3 p = nao_position(param_7, param_8, param_9);
    int2 param_10 = px;
    int param_11 = 0;
    float3 n = nao_load(src1, _src1_sampler, param_10, param_11).xyz;
    float ln = length(n);
    if (ln > 9.9999996826552253889678874634872e-21f)
    {
        n /= ln.xxx;
    }
    else
    {
        n = float3(0.0f, 0.0f, 1.0f);
    }
    float3 view_v = normalize(-p);
    float radius_px = (frame_u_radius * frame_u_pixels_per_unit) / max(-p.z, 1.0000000031710768509710513471353e-30f);
    if (!(radius_px > 1.0f))
    {
        int2 param_12 = px;
        int param_13 = 0;
        float4 param_14 = 1.0f.xxxx;
        nao_store(param_12, param_13, param_14);
        return;
    }
    int2 param_15 = px;
    int tile = nao_tile(param_15);
    int param_16 = tile;
    float jitter = nao_jitter(param_16);
    float falloff_range = 0.20000000298023223876953125f * frame_u_radius;
    float falloff_mul = (-1.0f) / falloff_range;
    float falloff_add = ((frame_u_radius - falloff_range) / falloff_range) + 1.0f;
    float min_s = 1.2999999523162841796875f / radius_px;
    float2 centre = float2(px) + 0.5f.xx;
    float visibility = 0.0f;
    for (int slice = 0; slice < 4; slice++)
    {
        int param_17 = tile;
        int param_18 = slice;
        float2 omega = nao_direction(param_17, param_18);
        float3 dir_v = float3(omega, 0.0f);
        float3 ortho_v = dir_v - (view_v * dot(dir_v, view_v));
        float3 axis_v = normalize(cross(dir_v, view_v));
        float3 proj_n = n - (axis_v * dot(n, axis_v));
        float proj_len = length(proj_n);
        float sign_n = -1.0f;
        if (dot(ortho_v, proj_n) >= 0.0f)
        {
            sign_n = 1.0f;
        }
        float cos_n = clamp(dot(proj_n, view_v) / max(proj_len, 9.9999996826552253889678874634872e-21f), 0.0f, 1.0f);
        float param_19 = cos_n;
        float ang_n = sign_n * nao_acos(param_19);
        float low0 = cos(ang_n + 1.57079637050628662109375f);
        float low1 = cos(ang_n - 1.57079637050628662109375f);
        float hc0 = low0;
        float hc1 = low1;
        for (int k = 0; k < 8; k++)
        {
            float s = (float(k) + jitter) / 8.0f;
            s = min_s + (((1.0f - min_s) * s) * s);
            float2 off = omega * (s * radius_px);
            int2 q0 = int2(floor(centre + off));
            int2 q1 = int2(floor(centre - off));
            int2 param_20 = q0;
            int2 param_21 = out_size;
            if (nao_inside(param_20, param_21))
            {
                int2 param_22 = q0;
                int param_23 = 0;
                float zq = nao_load(src0, _src0_sampler, param_22, param_23).x;
                if (zq > 0.0f)
                {
                    int2 param_24 = q0;
                    int2 param_25 = out_size;
                    float param_26 = zq;
                    float3 d = nao_position(param_24, param_25, param_26) - p;
                    float dist = length(d);
                    if (dist > 1.0000000031710768509710513471353e-30f)
                    {
                        float w = clamp((dist * falloff_mul) + falloff_add, 0.0f, 1.0f);
                        hc0 = max(hc0, lerp(low0, dot(d / dist.xxx, view_v), w));
                    }
                }
            }
            int2 param_27 = q1;
            int2 param_28 = out_size;
            if (nao_inside(param_27, param_28))
            {
                int2 param_29 = q1;
                int param_30 = 0;
                float zq_1 = nao_load(src0, _src0_sampler, param_29, param_30).x;
                if (zq_1 > 0.0f)
                {
                    int2 param_31 = q1;
                    int2 param_32 = out_size;
                    float param_33 = zq_1;
                    float3 d_1 = nao_position(param_31, param_32, param_33) - p;
                    float dist_1 = length(d_1);
                    if (dist_1 > 1.0000000031710768509710513471353e-30f)
                    {
                        float w_1 = clamp((dist_1 * falloff_mul) + falloff_add, 0.0f, 1.0f);
                        hc1 = max(hc1, lerp(low1, dot(d_1 / dist_1.xxx, view_v), w_1));
                    }
                }
            }
        }
        float param_34 = hc1;
        float h0 = -nao_acos(param_34);
        float param_35 = hc0;
        float h1 = nao_acos(param_35);
        h0 = ang_n + clamp(h0 - ang_n, -1.57079637050628662109375f, 1.57079637050628662109375f);
        h1 = ang_n + clamp(h1 - ang_n, -1.57079637050628662109375f, 1.57079637050628662109375f);
        float sin_n = sin(ang_n);
        float arc0 = ((cos_n + ((2.0f * h0) * sin_n)) - cos((2.0f * h0) - ang_n)) * 0.25f;
        float arc1 = ((cos_n + ((2.0f * h1) * sin_n)) - cos((2.0f * h1) - ang_n)) * 0.25f;
        visibility += (proj_len * (arc0 + arc1));
    }
    int2 param_36 = px;
    int param_37 = 0;
    float4 param_38 = clamp(visibility / 4.0f, 0.0f, 1.0f).xxxx;
    nao_store(param_36, param_37, param_38);
}

[numthreads(8, 8, 1)]
void f_gtao(SPIRV_Cross_Input stage_input)
{
    gl_GlobalInvocationID = stage_input.gl_GlobalInvocationID;
    f_gtao_inner();
}
