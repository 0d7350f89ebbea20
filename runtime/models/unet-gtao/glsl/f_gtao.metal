#pragma clang diagnostic ignored "-Wmissing-prototypes"
#pragma clang diagnostic ignored "-Wmissing-braces"

#include <metal_stdlib>
#include <simd/simd.h>

using namespace metal;

template<typename T, size_t Num>
struct spvUnsafeArray
{
    T elements[Num ? Num : 1];
    
    thread T& operator [] (size_t pos) thread
    {
        return elements[pos];
    }
    constexpr const thread T& operator [] (size_t pos) const thread
    {
        return elements[pos];
    }
    
    device T& operator [] (size_t pos) device
    {
        return elements[pos];
    }
    constexpr const device T& operator [] (size_t pos) const device
    {
        return elements[pos];
    }
    
    constexpr const constant T& operator [] (size_t pos) const constant
    {
        return elements[pos];
    }
    
    threadgroup T& operator [] (size_t pos) threadgroup
    {
        return elements[pos];
    }
    constexpr const threadgroup T& operator [] (size_t pos) const threadgroup
    {
        return elements[pos];
    }
};

struct FrameUniforms
{
    float2 u_proj;
    float u_radius;
    float u_pixels_per_unit;
    int u_flip_y;
};

constant uint3 gl_WorkGroupSize [[maybe_unused]] = uint3(8u, 8u, 1u);

constant spvUnsafeArray<float2, 64> _385 = spvUnsafeArray<float2, 64>({ float2(0.95628654956817626953125, 0.29243123531341552734375), float2(0.4694166481494903564453125, 0.8829767704010009765625), float2(-0.29243123531341552734375, 0.95628654956817626953125), float2(-0.882976830005645751953125, 0.46941661834716796875), float2(0.72424972057342529296875, 0.6895377635955810546875), float2(0.02454506792128086090087890625, 0.999698698520660400390625), float2(-0.6895377635955810546875, 0.724249780178070068359375), float2(-0.999698698520660400390625, 0.0245450250804424285888671875), float2(0.997950136661529541015625, 0.063995897769927978515625), float2(0.6604053974151611328125, 0.750909268856048583984375), float2(-0.0639958679676055908203125, 0.997950136661529541015625), float2(-0.750909268856048583984375, 0.660405337810516357421875), float2(0.999986708164215087890625, 0.005155663006007671356201171875), float2(0.703451812267303466796875, 0.710742950439453125), float2(-0.0051557035185396671295166015625, 0.999986708164215087890625), float2(-0.71074306964874267578125, 0.703451693058013916015625), float2(0.780055701732635498046875, 0.625710070133209228515625), float2(0.109138883650302886962890625, 0.994026482105255126953125), float2(-0.62571012973785400390625, 0.780055701732635498046875), float2(-0.994026482105255126953125, 0.109138958156108856201171875), float2(0.807158946990966796875, 0.5903341770172119140625), float2(0.15331827104091644287109375, 0.988176882266998291015625), float2(-0.590334117412567138671875, 0.807158946990966796875), float2(-0.988176882266998291015625, 0.153318226337432861328125), float2(0.961661756038665771484375, 0.2742382586002349853515625), float2(0.4860818088054656982421875, 0.873913288116455078125), float2(-0.2742383778095245361328125, 0.961661756038665771484375), float2(-0.87391340732574462890625, 0.486081659793853759765625), float2(0.839098155498504638671875, 0.54398000240325927734375), float2(0.20867989957332611083984375, 0.977984011173248291015625), float2(-0.54398024082183837890625, 0.839098036289215087890625), float2(-0.977984011173248291015625, 0.208679974079132080078125), float2(0.87093448638916015625, 0.491399109363555908203125), float2(0.2683719694614410400390625, 0.96331536769866943359375), float2(-0.4913992583751678466796875, 0.870934426784515380859375), float2(-0.963315427303314208984375, 0.2683718204498291015625), float2(0.994179308414459228515625, 0.107738263905048370361328125), float2(0.6268084049224853515625, 0.779173433780670166015625), float2(-0.1077382266521453857421875, 0.994179308414459228515625), float2(-0.779173374176025390625, 0.6268084049224853515625), float2(0.925171077251434326171875, 0.3795504271984100341796875), float2(0.3858120441436767578125, 0.922577381134033203125), float2(-0.379550516605377197265625, 0.92517101764678955078125), float2(-0.922577440738677978515625, 0.385811984539031982421875), float2(0.916310012340545654296875, 0.400469720363616943359375), float2(0.3647541105747222900390625, 0.931103885173797607421875), float2(-0.400469839572906494140625, 0.91630995273590087890625), float2(-0.931103885173797607421875, 0.3647540509700775146484375), float2(0.74443542957305908203125, 0.66769444942474365234375), float2(0.054264061152935028076171875, 0.998526632785797119140625), float2(-0.66769444942474365234375, 0.74443542957305908203125), float2(-0.998526632785797119140625, 0.054264016449451446533203125), float2(0.978735625743865966796875, 0.20512570440769195556640625), float2(0.547024786472320556640625, 0.837116420269012451171875), float2(-0.20512568950653076171875, 0.978735625743865966796875), float2(-0.83711636066436767578125, 0.54702484607696533203125), float2(0.987210571765899658203125, 0.159421741962432861328125), float2(0.585335075855255126953125, 0.810791492462158203125), float2(-0.1594218909740447998046875, 0.987210571765899658203125), float2(-0.810791552066802978515625, 0.5853350162506103515625), float2(0.896269977092742919921875, 0.4435088932514190673828125), float2(0.32015049457550048828125, 0.9473667144775390625), float2(-0.4435087740421295166015625, 0.8962700366973876953125), float2(-0.9473667144775390625, 0.3201504647731781005859375) });
constant spvUnsafeArray<float, 16> _414 = spvUnsafeArray<float, 16>({ 0.1678416728973388671875, 0.7069942951202392578125, 0.599261462688446044921875, 0.521755874156951904296875, 0.293343722820281982421875, 0.8365204334259033203125, 0.930650174617767333984375, 0.747238457202911376953125, 0.18946956098079681396484375, 0.517999827861785888671875, 0.862544834613800048828125, 0.896280705928802490234375, 0.195674479007720947265625, 0.0488224588334560394287109375, 0.999011993408203125, 0.251001894474029541015625 });

static inline __attribute__((always_inline))
int2 nao_texel(thread const int2& p, thread const int2& size, constant FrameUniforms& frame)
{
    int2 _78;
    if (frame.u_flip_y != 0)
    {
        _78 = p;
    }
    else
    {
        _78 = int2(p.x, (size.y - 1) - p.y);
    }
    return _78;
}

static inline __attribute__((always_inline))
int2 nao_size(texture2d_array<float> t, sampler tSmplr)
{
    return int3(t.get_width(), t.get_height(), t.get_array_size()).xy;
}

static inline __attribute__((always_inline))
float4 nao_load(texture2d_array<float> t, sampler tSmplr, thread const int2& p, thread const int& layer, constant FrameUniforms& frame)
{
    int2 param = p;
    int2 param_1 = nao_size(t, tSmplr);
    int3 _115 = int3(nao_texel(param, param_1, frame), layer);
    return t.read(uint2(_115.xy), uint(_115.z), 0);
}

static inline __attribute__((always_inline))
void nao_store(thread const int2& p, thread const int& layer, thread const float4& v, constant FrameUniforms& frame, texture2d_array<float, access::write> dst)
{
    int2 param = p;
    int2 param_1 = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
    int3 _134 = int3(nao_texel(param, param_1, frame), layer);
    dst.write(v, uint2(_134.xy), uint(_134.z));
}

static inline __attribute__((always_inline))
float3 nao_position(thread const int2& p, thread const int2& size, thread const float& z, constant FrameUniforms& frame)
{
    float2 ndc = (((float2(p) + float2(0.5)) / float2(size)) * 2.0) - float2(1.0);
    return float3((ndc.x / frame.u_proj.x) * z, (ndc.y / frame.u_proj.y) * z, -z);
}

static inline __attribute__((always_inline))
int nao_tile(thread const int2& p)
{
    return ((p.y % 4) * 4) + (p.x % 4);
}

static inline __attribute__((always_inline))
float nao_jitter(thread const int& tile)
{
    return _414[tile];
}

static inline __attribute__((always_inline))
float2 nao_direction(thread const int& tile, thread const int& slice)
{
    return _385[(tile * 4) + slice];
}

static inline __attribute__((always_inline))
float nao_acos(thread const float& x)
{
    return acos(fast::clamp(x, -1.0, 1.0));
}

static inline __attribute__((always_inline))
bool nao_inside(thread const int2& q, thread const int2& size)
{
    bool _140 = all(q >= int2(0));
    bool _147;
    if (_140)
    {
        _147 = all(q < size);
    }
    else
    {
        _147 = _140;
    }
    return _147;
}

kernel void f_gtao(constant FrameUniforms& frame [[buffer(0)]], texture2d_array<float, access::write> dst [[texture(0)]], texture2d_array<float> src0 [[texture(1)]], texture2d_array<float> src1 [[texture(2)]], sampler src0Smplr [[sampler(1)]], sampler src1Smplr [[sampler(2)]], uint3 gl_GlobalInvocationID [[thread_position_in_grid]])
{
    int2 gid = int2(gl_GlobalInvocationID.xy);
    int2 out_size = int3(dst.get_width(), dst.get_height(), dst.get_array_size()).xy;
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
    int2 px = nao_texel(param, param_1, frame);
    int2 param_2 = px;
    int param_3 = 0;
    float z = nao_load(src0, src0Smplr, param_2, param_3, frame).x;
    if (!(z > 0.0))
    {
        int2 param_4 = px;
        int param_5 = 0;
        float4 param_6 = float4(1.0);
        nao_store(param_4, param_5, param_6, frame, dst);
        return;
    }
    int2 param_7 = px;
    int2 param_8 = out_size;
    float param_9 = z;
    float3 p = nao_position(param_7, param_8, param_9, frame);
    int2 param_10 = px;
    int param_11 = 0;
    float3 n = nao_load(src1, src1Smplr, param_10, param_11, frame).xyz;
    float ln = length(n);
    if (ln > 9.9999996826552253889678874634872e-21)
    {
        n /= float3(ln);
    }
    else
    {
        n = float3(0.0, 0.0, 1.0);
    }
    float3 view_v = fast::normalize(-p);
    float radius_px = (frame.u_radius * frame.u_pixels_per_unit) / fast::max(-p.z, 1.0000000031710768509710513471353e-30);
    if (!(radius_px > 1.0))
    {
        int2 param_12 = px;
        int param_13 = 0;
        float4 param_14 = float4(1.0);
        nao_store(param_12, param_13, param_14, frame, dst);
        return;
    }
    int2 param_15 = px;
    int tile = nao_tile(param_15);
    int param_16 = tile;
    float jitter = nao_jitter(param_16);
    float falloff_range = 0.20000000298023223876953125 * frame.u_radius;
    float falloff_mul = (-1.0) / falloff_range;
    float falloff_add = ((frame.u_radius - falloff_range) / falloff_range) + 1.0;
    float min_s = 1.2999999523162841796875 / radius_px;
    float2 centre = float2(px) + float2(0.5);
    float visibility = 0.0;
    for (int slice = 0; slice < 4; slice++)
    {
        int param_17 = tile;
        int param_18 = slice;
        float2 omega = nao_direction(param_17, param_18);
        float3 dir_v = float3(omega, 0.0);
        float3 ortho_v = dir_v - (view_v * dot(dir_v, view_v));
        float3 axis_v = fast::normalize(cross(dir_v, view_v));
        float3 proj_n = n - (axis_v * dot(n, axis_v));
        float proj_len = length(proj_n);
        float sign_n = -1.0;
        if (dot(ortho_v, proj_n) >= 0.0)
        {
            sign_n = 1.0;
        }
        float cos_n = fast::clamp(dot(proj_n, view_v) / fast::max(proj_len, 9.9999996826552253889678874634872e-21), 0.0, 1.0);
        float param_19 = cos_n;
        float ang_n = sign_n * nao_acos(param_19);
        float low0 = cos(ang_n + 1.57079637050628662109375);
        float low1 = cos(ang_n - 1.57079637050628662109375);
        float hc0 = low0;
        float hc1 = low1;
        for (int k = 0; k < 8; k++)
        {
            float s = (float(k) + jitter) / 8.0;
            s = min_s + (((1.0 - min_s) * s) * s);
            float2 off = omega * (s * radius_px);
            int2 q0 = int2(floor(centre + off));
            int2 q1 = int2(floor(centre - off));
            int2 param_20 = q0;
            int2 param_21 = out_size;
            if (nao_inside(param_20, param_21))
            {
                int2 param_22 = q0;
                int param_23 = 0;
                float zq = nao_load(src0, src0Smplr, param_22, param_23, frame).x;
                if (zq > 0.0)
                {
                    int2 param_24 = q0;
                    int2 param_25 = out_size;
                    float param_26 = zq;
                    float3 d = nao_position(param_24, param_25, param_26, frame) - p;
                    float dist = length(d);
                    if (dist > 1.0000000031710768509710513471353e-30)
                    {
                        float w = fast::clamp((dist * falloff_mul) + falloff_add, 0.0, 1.0);
                        hc0 = fast::max(hc0, mix(low0, dot(d / float3(dist), view_v), w));
                    }
                }
            }
            int2 param_27 = q1;
            int2 param_28 = out_size;
            if (nao_inside(param_27, param_28))
            {
                int2 param_29 = q1;
                int param_30 = 0;
                float zq_1 = nao_load(src0, src0Smplr, param_29, param_30, frame).x;
                if (zq_1 > 0.0)
                {
                    int2 param_31 = q1;
                    int2 param_32 = out_size;
                    float param_33 = zq_1;
                    float3 d_1 = nao_position(param_31, param_32, param_33, frame) - p;
                    float dist_1 = length(d_1);
                    if (dist_1 > 1.0000000031710768509710513471353e-30)
                    {
                        float w_1 = fast::clamp((dist_1 * falloff_mul) + falloff_add, 0.0, 1.0);
                        hc1 = fast::max(hc1, mix(low1, dot(d_1 / float3(dist_1), view_v), w_1));
                    }
                }
            }
        }
        float param_34 = hc1;
        float h0 = -nao_acos(param_34);
        float param_35 = hc0;
        float h1 = nao_acos(param_35);
        h0 = ang_n + fast::clamp(h0 - ang_n, -1.57079637050628662109375, 1.57079637050628662109375);
        h1 = ang_n + fast::clamp(h1 - ang_n, -1.57079637050628662109375, 1.57079637050628662109375);
        float sin_n = sin(ang_n);
        float arc0 = ((cos_n + ((2.0 * h0) * sin_n)) - cos((2.0 * h0) - ang_n)) * 0.25;
        float arc1 = ((cos_n + ((2.0 * h1) * sin_n)) - cos((2.0 * h1) - ang_n)) * 0.25;
        visibility += (proj_len * (arc0 + arc1));
    }
    int2 param_36 = px;
    int param_37 = 0;
    float4 param_38 = float4(fast::clamp(visibility / 4.0, 0.0, 1.0));
    nao_store(param_36, param_37, param_38, frame, dst);
}

