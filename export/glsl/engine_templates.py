# ruff: noqa: E501  (engine code: the lines follow C#, C++ and GDScript, not this file's width)
"""Engine wrapper text, as named templates (``string.Template``, ``${field}``), filled by
:mod:`neuralao.export.glsl.engines` only: Unity (C# + one .compute), Unreal (a .usf global shader file +
C++ shader classes with their parameter structs and the RDG passes), Godot 4 (a GDScript
CompositorEffect on RenderingDevice). Each runs a whole frame: the manifest's ``frame.steps``, frame
passes and network passes. Shader code is not here: the wrappers include the generated HLSL and load
the generated SPIR-V."""

from __future__ import annotations

from string import Template

from neuralao.runtime.foundation.errors import NeuralaoError

_E: dict[str, str] = {}

_E["generated"] = (
    "Generated from the manifests of ${model} by `python -m neuralao.export.glsl.engines`; "
    "tests/test_engine_wrappers.py checks it against the manifests and the exported shaders."
)

# ----------------------------------------------------------------------------------------------- Unity
_E["unity_compute"] = """// ${generated}
// One kernel per pass the frame dispatches: each kernel is compiled with its NEURALAO_PASS, which includes
// that pass's HLSL (the export's glsl/<pass>.hlsl, `neuralao glsl MODEL.onnx --target image --hlsl-msl`,
// copied beside this file).
${kernels}

${includes}
"""
_E["unity_kernel"] = "#pragma kernel ${entry} NEURALAO_PASS=${index}"
_E["unity_include"] = """${keyword} NEURALAO_PASS == ${index}
#include "${file}\""""

_E["unity_cs"] = """// ${generated}
// Not run here (no Unity): the HLSL it binds, by these names and registers, runs the whole frame on
// Vulkan (lavapipe) in tests/test_frame_passes.py.
using System.Collections.Generic;
using UnityEngine;
using UnityEngine.Rendering;

/// <summary>The whole ${model} frame: ${dispatches} steps in the order of the manifest's frame.steps,
/// from the textures the engine writes to the AO texture "${output}".
/// Each frame: Resize(W, H) when the size changes, write the inputs, Run(camera, radius), read AO.
/// The inputs (Texture(id), W x H):
${inputs}
/// </summary>
public sealed class ${cls} : System.IDisposable
{
    public const int PadMultiple = ${multiple};
    public const int InternalHeight = ${internal_height};  // network rows; 0: the network runs at W x H
    readonly ComputeShader shader;  // ${cls}.compute
    readonly float[] weights;       // weights.bin as floats
    readonly Dictionary<int, GraphicsBuffer> passWeights = new Dictionary<int, GraphicsBuffer>();
    readonly Dictionary<string, RenderTexture> tex = new Dictionary<string, RenderTexture>();
    readonly GraphicsBuffer frameUniforms = new GraphicsBuffer(GraphicsBuffer.Target.Constant, ${uniform_floats}, 4);
    bool sameSize;    // the network's input is W x H: the steps marked (w, h) == (W, H) run
    int frameHeight;  // H

    public ${cls}(ComputeShader shader, byte[] weightsBin)
    {
        this.shader = shader;
        weights = new float[weightsBin.Length / 4];
        System.Buffer.BlockCopy(weightsBin, 0, weights, 0, weightsBin.Length);
${weight_buffers}
    }

    /// <summary>A buffer of the pass's own: its range of weights.bin (the HLSL reads from byte 0).</summary>
    void Weights(int pass, int offset, int bytes)
    {
        var b = new GraphicsBuffer(GraphicsBuffer.Target.Raw, bytes / 4, 4);
        b.SetData(weights, offset / 4, 0, bytes / 4);
        passWeights[pass] = b;
    }

    static RenderTexture Array2D(int w, int h, int layers, RenderTextureFormat format)
    {
        var t = new RenderTexture(w, h, 0, format)
        {
            dimension = TextureDimension.Tex2DArray, volumeDepth = layers, enableRandomWrite = true
        };
        t.Create();
        return t;
    }

    static int CeilDiv(int n, int d) => (n + d - 1) / d;

    public RenderTexture Texture(string id) => tex[id];
    public RenderTexture AO => tex["${output}"];

    /// <summary>Allocate every texture of the frame (frame.textures) for a W x H frame: w x h the network's
    /// input (InternalHeight rows, the width rounded half to even), wp x hp those padded.</summary>
    public void Resize(int W, int H)
    {
        Release();
        frameHeight = H;
        int w = InternalHeight > 0 ? Mathf.Max(1, (int)System.Math.Round((double)W * InternalHeight / H)) : W;
        int h = InternalHeight > 0 ? InternalHeight : H;
        int wp = CeilDiv(w, PadMultiple) * PadMultiple, hp = CeilDiv(h, PadMultiple) * PadMultiple;
${textures}
        sameSize = tex["${net_input}"].width == W && tex["${net_input}"].height == H;
    }

    /// <summary>The frame for a camera: its projection, and the row order of the graphics API (row 0 is the
    /// top row on D3D, Vulkan and Metal; the bottom row on OpenGL).</summary>
    public void Run(Camera camera, float radius)
    {
        Matrix4x4 p = camera.projectionMatrix;
        Run(p.m00, p.m11, radius, !SystemInfo.graphicsUVStartsAtTop);
    }

    /// <summary>Every step in order. p00, p11: the projection's scales (f * H / W, f); radius in scene
    /// units; flipY: the textures are stored bottom-up (row 0 = the bottom row).</summary>
    public void Run(float p00, float p11, float radius, bool flipY)
    {
        int flip = flipY ? 1 : 0;
        float pixels_per_unit = 0.5f * frameHeight * p11;
        var u = new float[${uniform_floats}];  // FrameUniforms (cbuffer, b0): ${uniform_bytes} bytes
${uniform_lanes}
        frameUniforms.SetData(u);
        int k;
${steps}
    }

    void Release()
    {
        foreach (var t in tex.Values) t.Release();
        tex.Clear();
    }

    public void Dispose()
    {
        Release();
        foreach (var b in passWeights.Values) b.Release();
        frameUniforms.Release();
    }
}
"""
_E["unity_weights"] = "        Weights(${index}, ${offset}, ${bytes});"
_E["unity_texture"] = (
    '        tex["${texture}"] = Array2D(${width}, ${height}, ${layers}, RenderTextureFormat.${format});'
)
_E["unity_lane_float"] = "        u[${lane}] = (float)(${value});  // ${member}"
_E["unity_lane_int"] = "        u[${lane}] = System.BitConverter.Int32BitsToSingle(${value});  // ${member}"
_E["unity_step"] = """        // step ${step}: ${entry}: ${summary}
        k = shader.FindKernel("${entry}");
${binds}
        shader.Dispatch(k, CeilDiv(tex["${size_of}"].width, ${gx}), CeilDiv(tex["${size_of}"].height, ${gy}), ${gz});"""
_E["unity_when"] = """        if (${condition})  // ${when}
        {
${block}
        }"""
_E["unity_skip"] = "        // step ${step}: ${entry} skipped: ${why}"
_E["unity_set_texture"] = '        shader.SetTexture(k, "${name}", tex["${texture}"]);'
_E["unity_set_buffer"] = '        shader.SetBuffer(k, "${name}", passWeights[${index}]);'
_E["unity_set_int"] = '        shader.SetInt("${name}", flip);'
_E["unity_set_cbuffer"] = '        shader.SetConstantBuffer("${name}", frameUniforms, 0, ${bytes});'

# ---------------------------------------------------------------------------------------------- Unreal
_E["unreal_usf"] = """// ${generated}
// One global shader file for every pass the frame dispatches: each pass's shader class (${cls}.h)
// compiles it with its NEURALAO_PASS, which includes that pass's HLSL (the export's glsl/<pass>.hlsl),
// copied beside this file as <pass>.ush.
#include "/Engine/Public/Platform.ush"

${includes}
"""
_E["unreal_include"] = """${keyword} NEURALAO_PASS == ${index}
#include "${file}\""""

_E["unreal_h"] = """// ${generated}
// Not run here (no Unreal): the HLSL these classes bind, by these names and registers, runs the whole
// frame on Vulkan (lavapipe) in tests/test_frame_passes.py.
#pragma once

#include "GlobalShader.h"
#include "RenderGraphBuilder.h"
#include "ShaderParameterStruct.h"

namespace ${namespace}
{
constexpr int32 PadMultiple = ${multiple};
constexpr int32 InternalHeight = ${internal_height};  // network rows; 0: the network runs at W x H

/** The frame passes' cbuffer ${block} (b0), members at the HLSL's offsets (${uniform_bytes} bytes). */
BEGIN_GLOBAL_SHADER_PARAMETER_STRUCT(F${block}, )
${members}
END_GLOBAL_SHADER_PARAMETER_STRUCT()

${classes}

/** The frame's textures (CreateTextures) and the per-pass weight buffers (each made with
 * FRDGBufferDesc::CreateByteAddressDesc(bytes), filled with the pass's range of weights.bin). */
struct FResources
{
    TMap<FString, FRDGTextureRef> Textures;
    TMap<int32, FRDGBufferRef> Weights;
};

/** Every texture of the frame (frame.textures) for a Frame.X x Frame.Y frame. Before AddPasses, write the
 * inputs:
${inputs}
 */
TMap<FString, FRDGTextureRef> CreateTextures(FRDGBuilder& GraphBuilder, FIntPoint Frame);

/** Every step of the frame in order (RDG orders the dispatches by their texture reads and writes);
 * Projection: the view's projection matrix. Returns the AO texture "${output}". */
FRDGTextureRef AddPasses(FRDGBuilder& GraphBuilder, const FResources& R, FIntPoint Frame, const FMatrix& Projection, float Radius);
}  // namespace ${namespace}
"""
_E["unreal_member"] = "    SHADER_PARAMETER(${type}, ${name})  // offset ${offset}"
_E["unreal_class"] = """class F${entry} : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(F${entry});
    SHADER_USE_PARAMETER_STRUCT(F${entry}, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
${parameters}
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), ${index});
    }
};"""
_E["unreal_param_srv"] = "        SHADER_PARAMETER_RDG_TEXTURE_SRV(${type}, ${name})  // ${register}"
_E["unreal_param_uav"] = "        SHADER_PARAMETER_RDG_TEXTURE_UAV(${type}, ${name})  // ${register}"
_E["unreal_param_buffer"] = "        SHADER_PARAMETER_RDG_BUFFER_SRV(${type}, ${name})  // ${register}"
_E["unreal_param_block"] = "        SHADER_PARAMETER_RDG_UNIFORM_BUFFER(F${type}, ${name})  // ${register}"
_E["unreal_param_scalar"] = "        SHADER_PARAMETER(${type}, ${name})  // $$Globals"

_E["unreal_cpp"] = """// ${generated}
#include "${cls}.h"

#include "RenderGraphUtils.h"

namespace ${namespace}
{
IMPLEMENT_GLOBAL_SHADER_PARAMETER_STRUCT(F${block}, "${block}");
${implements}

TMap<FString, FRDGTextureRef> CreateTextures(FRDGBuilder& GraphBuilder, FIntPoint Frame)
{
    const int32 W = Frame.X, H = Frame.Y;
    const int32 w = InternalHeight > 0 ? FMath::Max(1, (int32)FMath::RoundHalfToEven((double)W * InternalHeight / H)) : W;
    const int32 h = InternalHeight > 0 ? InternalHeight : H;
    const int32 wp = FMath::DivideAndRoundUp(w, PadMultiple) * PadMultiple, hp = FMath::DivideAndRoundUp(h, PadMultiple) * PadMultiple;
    TMap<FString, FRDGTextureRef> T;
    auto Make = [&](const TCHAR* Id, int32 X, int32 Y, int32 Layers, EPixelFormat Format) {
        T.Add(Id, GraphBuilder.CreateTexture(FRDGTextureDesc::Create2DArray(FIntPoint(X, Y), Format, FClearValueBinding::None,
            TexCreate_ShaderResource | TexCreate_UAV, Layers), Id));
    };
${textures}
    return T;
}

FRDGTextureRef AddPasses(FRDGBuilder& GraphBuilder, const FResources& R, FIntPoint Frame, const FMatrix& Projection, float Radius)
{
    FGlobalShaderMap* ShaderMap = GetGlobalShaderMap(GMaxRHIFeatureLevel);
    auto Srv = [&](const TCHAR* T) { return GraphBuilder.CreateSRV(FRDGTextureSRVDesc::Create(R.Textures[T])); };
    auto Uav = [&](const TCHAR* T) { return GraphBuilder.CreateUAV(FRDGTextureUAVDesc(R.Textures[T])); };
    auto Raw = [&](int32 Pass) { return GraphBuilder.CreateSRV(R.Weights[Pass]); };
    auto Size = [&](const TCHAR* T) { return R.Textures[T]->Desc.Extent; };
    const float p00 = Projection.M[0][0], p11 = Projection.M[1][1];
    const float radius = Radius;
    const float pixels_per_unit = 0.5f * Frame.Y * p11;
    const int32 flip = 0;  // row 0 is the top row on every RHI Unreal renders with (D3D, Vulkan, Metal)
    const bool bSameSize = Size(TEXT("${net_input}")) == Frame;  // the steps marked (w, h) == (W, H) run
    auto* U = GraphBuilder.AllocParameters<F${block}>();
${uniform_lanes}
    TRDGUniformBufferRef<F${block}> FrameUniformBuffer = GraphBuilder.CreateUniformBuffer(U);
${steps}
    return R.Textures[TEXT("${output}")];
}
}  // namespace ${namespace}
"""
_E["unreal_lane"] = "    U->${member} = ${value};"
_E["unreal_implement"] = (
    'IMPLEMENT_GLOBAL_SHADER(F${entry}, "/Plugin/NeuralAO/${usf}", "${entry}", SF_Compute);'
)
_E["unreal_texture"] = '    Make(TEXT("${texture}"), ${width}, ${height}, ${layers}, ${format});'
_E["unreal_step"] = """    {  // step ${step}: ${entry}: ${summary}
        auto* P = GraphBuilder.AllocParameters<F${entry}::FParameters>();
${binds}
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("${entry}"), TShaderMapRef<F${entry}>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("${size_of}")).X, ${gx}), FMath::DivideAndRoundUp(Size(TEXT("${size_of}")).Y, ${gy}), ${gz}));
    }"""
_E["unreal_when"] = """    if (${condition})  // ${when}
${block}"""
_E["unreal_skip"] = "    // step ${step}: ${entry} skipped: ${why}"
_E["unreal_bind_srv"] = '        P->${name} = Srv(TEXT("${texture}"));'
_E["unreal_bind_uav"] = '        P->${name} = Uav(TEXT("${texture}"));'
_E["unreal_bind_buffer"] = "        P->${name} = Raw(${index});"
_E["unreal_bind_flip"] = "        P->${name} = flip;"
_E["unreal_bind_block"] = "        P->${name} = FrameUniformBuffer;"

# ----------------------------------------------------------------------------------------------- Godot
_E["godot_gd"] = """# ${generated}
# Not run here (no Godot): the SPIR-V it loads, bound at these bindings, runs the whole frame on Vulkan
# (lavapipe) in tests/test_frame_passes.py (the export's vulkan/ folder:
# `neuralao glsl MODEL.onnx --target image --dialect vulkan`).
@tool
extends CompositorEffect
class_name ${cls}

## Folder of the Vulkan export: <pass>.spv and weights.bin.
@export_dir var export_dir := "res://neuralao/${model}/vulkan"
## The AO radius in scene units.
@export var radius := 1.0
## Your passes write these each frame before this effect runs (texture(id), W x H):
${inputs}
## The AO, W x H, for your composite.
var ao_texture: RID

const PAD_MULTIPLE := ${multiple}
const INTERNAL_HEIGHT := ${internal_height}  # network rows; 0: the network runs at W x H
const FLIP_Y := 0  # RenderingDevice (Vulkan, D3D12, Metal): row 0 is the top row
# FrameUniforms (std140, ${uniform_bytes} bytes): [member, offset, lanes: value names]
const FRAME_UNIFORMS := [
${uniform_members}
]
# texture: [width: symbol, num, den, offset, height: symbol, num, den, offset, layers, format]
# (symbols: W x H the frame, w x h the network's input, wp x hp those padded; "" a fixed size)
const TEXTURES := {
${textures}
}
# pass: [SPIR-V file, [size_of texture, texels x a group, texels y a group, groups z], bindings]
# bindings: [binding, kind, what]: texture = sampled image without sampler, image = storage image,
# weights = the pass's range of weights.bin [offset, bytes], uniform = a 16-byte std140 block holding
# the named value, frame = the FrameUniforms buffer
const PASSES := {
${passes}
}
# the frame in order (frame.steps): [pass, when] (when: "" always, or the condition on the network's size)
const STEPS := [
${steps}
]

var rd: RenderingDevice
var pipelines := {}
var weight_buffers := {}
var textures := {}
var size := Vector2i.ZERO
var same_size := false

func _init() -> void:
    effect_callback_type = EFFECT_CALLBACK_TYPE_POST_TRANSPARENT
    rd = RenderingServer.get_rendering_device()

func texture(id: String) -> RID:
    return textures[id]

func _render_callback(_callback_type: int, render_data: RenderData) -> void:
    var frame: Vector2i = render_data.get_render_scene_buffers().get_internal_size()
    if frame != size:
        _resize(frame)
    var proj: Projection = render_data.get_render_scene_data().get_cam_projection()
    run(absf(proj.x.x), absf(proj.y.y))

func _pipeline(name: String) -> RID:
    if not pipelines.has(name):
        var spirv := RDShaderSPIRV.new()
        spirv.set_stage_bytecode(RenderingDevice.SHADER_STAGE_COMPUTE, FileAccess.get_file_as_bytes(export_dir.path_join(PASSES[name][0])))
        var shader := rd.shader_create_from_spirv(spirv)
        pipelines[name] = [shader, rd.compute_pipeline_create(shader)]
    return pipelines[name][1]

func _dim(of: String, num: int, den: int, offset: int, sizes: Dictionary) -> int:
    return (sizes[of] * num / den if of != "" else 0) + offset

func _round_half_even(x: float) -> int:
    var f := floori(x)
    var d := x - f
    return f + 1 if d > 0.5 or (d == 0.5 and f % 2 == 1) else f

func _resize(frame: Vector2i) -> void:
    for t in textures.values():
        rd.free_rid(t)
    textures.clear()
    size = frame
    var w := maxi(1, _round_half_even(frame.x * INTERNAL_HEIGHT / float(frame.y))) if INTERNAL_HEIGHT > 0 else frame.x
    var h := INTERNAL_HEIGHT if INTERNAL_HEIGHT > 0 else frame.y
    var sizes := {"W": frame.x, "H": frame.y, "w": w, "h": h,
        "wp": ceili(w / float(PAD_MULTIPLE)) * PAD_MULTIPLE, "hp": ceili(h / float(PAD_MULTIPLE)) * PAD_MULTIPLE}
    for id in TEXTURES:
        var d: Array = TEXTURES[id]
        var fmt := RDTextureFormat.new()
        fmt.texture_type = RenderingDevice.TEXTURE_TYPE_2D_ARRAY
        fmt.width = _dim(d[0], d[1], d[2], d[3], sizes)
        fmt.height = _dim(d[4], d[5], d[6], d[7], sizes)
        fmt.array_layers = d[8]
        fmt.format = d[9]
        fmt.usage_bits = (RenderingDevice.TEXTURE_USAGE_SAMPLING_BIT | RenderingDevice.TEXTURE_USAGE_STORAGE_BIT
            | RenderingDevice.TEXTURE_USAGE_CAN_UPDATE_BIT | RenderingDevice.TEXTURE_USAGE_CAN_COPY_FROM_BIT)
        textures[id] = rd.texture_create(fmt, RDTextureView.new())
    var low := rd.texture_get_format(textures["${net_input}"])
    same_size = low.width == frame.x and low.height == frame.y
    ao_texture = textures["${output}"]

func _weights(offset: int, bytes: int) -> RID:
    if not weight_buffers.has(offset):
        var all := FileAccess.get_file_as_bytes(export_dir.path_join("weights.bin"))
        weight_buffers[offset] = rd.storage_buffer_create(bytes, all.slice(offset, offset + bytes))
    return weight_buffers[offset]

func _frame_uniforms(p00: float, p11: float) -> PackedByteArray:
    var values := {"p00": p00, "p11": p11, "radius": radius, "pixels_per_unit": 0.5 * size.y * p11, "flip": FLIP_Y}
    var block := PackedByteArray()
    block.resize(${uniform_bytes})
    for m in FRAME_UNIFORMS:
        for i in m[2].size():
            var value = values[m[2][i]]
            if typeof(value) == TYPE_INT:
                block.encode_s32(m[1] + 4 * i, value)
            else:
                block.encode_float(m[1] + 4 * i, value)
    return block

func _pass_uniform(what: String) -> PackedByteArray:
    var block := PackedByteArray()
    block.resize(16)
    if what != "u_flip_y":
        push_error("the frame sets no uniform " + what)
    block.encode_s32(0, FLIP_Y)
    return block

func run(p00: float, p11: float) -> void:
    var frame_block := rd.uniform_buffer_create(${uniform_bytes}, _frame_uniforms(p00, p11))
    var frees := [frame_block]
    var list := rd.compute_list_begin()
    for step in STEPS:
        if step[1] == "(w, h) == (W, H)" and not same_size or step[1] == "(w, h) != (W, H)" and same_size:
            continue
        var p: Array = PASSES[step[0]]
        var uniforms := []
        for b in p[2]:
            var u := RDUniform.new()
            u.binding = b[0]
            if b[1] == "texture":
                u.uniform_type = RenderingDevice.UNIFORM_TYPE_TEXTURE
                u.add_id(textures[b[2]])
            elif b[1] == "image":
                u.uniform_type = RenderingDevice.UNIFORM_TYPE_IMAGE
                u.add_id(textures[b[2]])
            elif b[1] == "weights":
                u.uniform_type = RenderingDevice.UNIFORM_TYPE_STORAGE_BUFFER
                u.add_id(_weights(b[2][0], b[2][1]))
            elif b[1] == "frame":
                u.uniform_type = RenderingDevice.UNIFORM_TYPE_UNIFORM_BUFFER
                u.add_id(frame_block)
            else:
                u.uniform_type = RenderingDevice.UNIFORM_TYPE_UNIFORM_BUFFER
                var buf := rd.uniform_buffer_create(16, _pass_uniform(b[2]))
                frees.append(buf)
                u.add_id(buf)
            uniforms.append(u)
        var pipeline := _pipeline(step[0])
        var set := rd.uniform_set_create(uniforms, pipelines[step[0]][0], 0)
        frees.append(set)
        var g: Array = p[1]
        var tf := rd.texture_get_format(textures[g[0]])
        rd.compute_list_bind_compute_pipeline(list, pipeline)
        rd.compute_list_bind_uniform_set(list, set, 0)
        rd.compute_list_dispatch(list, ceili(tf.width / float(g[1])), ceili(tf.height / float(g[2])), g[3])
        rd.compute_list_add_barrier(list)
    rd.compute_list_end()
    for r in frees:
        rd.free_rid(r)
"""
_E["godot_input"] = "## ${texture}: ${meaning}\n"
_E["godot_uniform"] = '    ["${member}", ${offset}, [${lanes}]],'
_E["godot_pass"] = '    "${entry}": ["${spirv}", ["${size_of}", ${gx}, ${gy}, ${gz}], [${bindings}]],'
_E["godot_step"] = '    ["${entry}", "${when}"],'
_E["godot_texture"] = (
    '    "${texture}": ["${wof}", ${wnum}, ${wden}, ${woff}, "${hof}", ${hnum}, ${hden}, ${hoff}, ${layers}, RenderingDevice.${format}],'
)


def fill_engine(name: str, /, **fields: object) -> str:
    """Fill engine template ``name``; every field must be given and used (NeuralaoError otherwise)."""
    template = Template(_E[name])
    wanted = {m.group("named") or m.group("braced") for m in template.pattern.finditer(template.template)} - {
        None
    }
    if set(fields) != wanted:
        raise NeuralaoError(f"engine template {name}: fields {sorted(fields)} != {sorted(wanted)}")
    return template.substitute(**fields)
