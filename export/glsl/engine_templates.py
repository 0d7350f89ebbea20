# ruff: noqa: E501  (engine code: the lines follow C#, C++ and GDScript, not this file's width)
"""Engine wrapper text, as named templates (``string.Template``, ``${field}``), filled by
:mod:`neuralao.export.glsl.engines` only: Unity (C# + one .compute), Unreal (a .usf global shader file +
C++ shader classes with their parameter structs), Godot 4 (a GDScript CompositorEffect on
RenderingDevice). Shader code is not here: the wrappers include the generated HLSL and load the
generated SPIR-V."""

from __future__ import annotations

from string import Template

from neuralao.runtime.foundation.errors import NeuralaoError

_E: dict[str, str] = {}

_E["generated"] = (
    "Generated from the manifest of ${model} by `python -m neuralao.export.glsl.engines`; "
    "tests/test_engine_wrappers.py checks it against the manifest and the generated shaders."
)

# ----------------------------------------------------------------------------------------------- Unity
_E["unity_compute"] = """// ${generated}
// One kernel per network pass: each kernel is compiled with its NEURALAO_PASS, which includes that pass's
// HLSL (<pass>.hlsl of `neuralao glsl MODEL.onnx --target image --hlsl-msl`, beside this file).
${kernels}

${includes}
"""
_E["unity_kernel"] = "#pragma kernel ${entry} NEURALAO_PASS=${index}"
_E["unity_include"] = """${keyword} NEURALAO_PASS == ${index}
#include "${file}\""""

_E["unity_cs"] = """// ${generated}
// Not run here (no Unity): the HLSL it binds, by these names, runs on Vulkan in tests/test_hlsl_target.py.
using System.Collections.Generic;
using UnityEngine;
using UnityEngine.Rendering;

/// <summary>The ${model} network: ${passes} compute passes from the input texture ${input} (fill it
/// first: ${channels} channels, 4 a layer) to the output ${output}.</summary>
public sealed class ${cls} : System.IDisposable
{
    public const int PadMultiple = ${multiple};
    readonly ComputeShader shader;  // ${cls}.compute
    readonly float[] weights;       // weights.bin as floats
    readonly Dictionary<int, GraphicsBuffer> passWeights = new Dictionary<int, GraphicsBuffer>();
    readonly Dictionary<string, RenderTexture> tex = new Dictionary<string, RenderTexture>();

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

    public RenderTexture Input => tex["${input}"];
    public RenderTexture Output => tex["${output}"];

    /// <summary>Allocate every texture for a width x height frame (both at least PadMultiple).</summary>
    public void Resize(int W, int H)
    {
        Release();
        int Wp = CeilDiv(W, PadMultiple) * PadMultiple, Hp = CeilDiv(H, PadMultiple) * PadMultiple;
${textures}
    }

    /// <summary>Every pass in order. flipY: the input and output are bottom-up (row 0 at the bottom).</summary>
    public void Run(${scalar_params}bool flipY)
    {
        int k;
${dispatches}
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
    }
}
"""
_E["unity_weights"] = "        Weights(${index}, ${offset}, ${bytes});"
_E["unity_texture"] = (
    '        tex["${texture}"] = Array2D(${width}, ${height}, ${layers}, RenderTextureFormat.${format});'
)
_E["unity_pass"] = """        // ${entry}: ${ops}
        k = shader.FindKernel("${entry}");
${binds}
        shader.Dispatch(k, CeilDiv(tex["${size_of}"].width, ${gx}), CeilDiv(tex["${size_of}"].height, ${gy}), ${gz});"""
_E["unity_set_texture"] = '        shader.SetTexture(k, "${name}", tex["${texture}"]);'
_E["unity_set_buffer"] = '        shader.SetBuffer(k, "${name}", passWeights[${index}]);'
_E["unity_set_int"] = '        shader.SetInt("${name}", flipY ? 1 : 0);'
_E["unity_set_float"] = '        shader.SetFloat("${name}", ${value});'

# ---------------------------------------------------------------------------------------------- Unreal
_E["unreal_usf"] = """// ${generated}
// One global shader file for every pass: each pass's shader class (${cls}.h) compiles it with its
// NEURALAO_PASS, which includes that pass's HLSL, copied beside this file as <pass>.ush.
#include "/Engine/Public/Platform.ush"

${includes}
"""
_E["unreal_include"] = """${keyword} NEURALAO_PASS == ${index}
#include "${file}\""""

_E["unreal_h"] = """// ${generated}
// Not run here (no Unreal): the HLSL these classes bind, by these names, runs on Vulkan in
// tests/test_hlsl_target.py.
#pragma once

#include "GlobalShader.h"
#include "RenderGraphBuilder.h"
#include "ShaderParameterStruct.h"

namespace ${namespace}
{
constexpr int32 PadMultiple = ${multiple};

${classes}

/** The textures (${input} the input, ${output} the output) and per-pass weight buffers of one frame size. */
struct FResources
{
    TMap<FString, FRDGTextureRef> Textures;
    TMap<int32, FRDGBufferRef> Weights;  // a buffer per pass with params: its range of weights.bin
};

/** Every pass in order (RDG orders the dispatches by their texture reads and writes). */
void AddPasses(FRDGBuilder& GraphBuilder, const FResources& R, ${scalar_params}bool bFlipY);
}  // namespace ${namespace}
"""
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
_E["unreal_param_srv"] = (
    "        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, ${name})  // ${register}"
)
_E["unreal_param_uav"] = (
    "        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, ${name})  // ${register}"
)
_E["unreal_param_buffer"] = (
    "        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, ${name})  // ${register}"
)
_E["unreal_param_scalar"] = "        SHADER_PARAMETER(${type}, ${name})  // $$Globals"

_E["unreal_cpp"] = """// ${generated}
#include "${cls}.h"

#include "RenderGraphUtils.h"

namespace ${namespace}
{
${implements}

void AddPasses(FRDGBuilder& GraphBuilder, const FResources& R, ${scalar_params}bool bFlipY)
{
    FGlobalShaderMap* ShaderMap = GetGlobalShaderMap(GMaxRHIFeatureLevel);
    auto Srv = [&](const TCHAR* T) { return GraphBuilder.CreateSRV(FRDGTextureSRVDesc::Create(R.Textures[T])); };
    auto Uav = [&](const TCHAR* T) { return GraphBuilder.CreateUAV(FRDGTextureUAVDesc(R.Textures[T])); };
    // each weights buffer made with FRDGBufferDesc::CreateByteAddressDesc(bytes): a raw view
    auto Raw = [&](int32 Pass) { return GraphBuilder.CreateSRV(R.Weights[Pass]); };
    auto Size = [&](const TCHAR* T) { return R.Textures[T]->Desc.Extent; };
${dispatches}
}
}  // namespace ${namespace}
"""
_E["unreal_implement"] = (
    'IMPLEMENT_GLOBAL_SHADER(F${entry}, "/Plugin/NeuralAO/${usf}", "${entry}", SF_Compute);'
)
_E["unreal_pass"] = """    {  // ${entry}: ${ops}
        auto* P = GraphBuilder.AllocParameters<F${entry}::FParameters>();
${binds}
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("${entry}"), TShaderMapRef<F${entry}>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("${size_of}")).X, ${gx}), FMath::DivideAndRoundUp(Size(TEXT("${size_of}")).Y, ${gy}), ${gz}));
    }"""
_E["unreal_bind_srv"] = '        P->${name} = Srv(TEXT("${texture}"));'
_E["unreal_bind_uav"] = '        P->${name} = Uav(TEXT("${texture}"));'
_E["unreal_bind_buffer"] = "        P->${name} = Raw(${index});"
_E["unreal_bind_flip"] = "        P->${name} = bFlipY ? 1 : 0;"
_E["unreal_bind_scalar"] = "        P->${name} = ${value};"

# ----------------------------------------------------------------------------------------------- Godot
_E["godot_gd"] = """# ${generated}
# Not run here (no Godot): the SPIR-V it loads, bound at these bindings, runs on Vulkan in
# tests/test_vulkan_target.py (the Vulkan export: `neuralao glsl MODEL.onnx --target image --dialect vulkan`).
@tool
extends CompositorEffect
class_name ${cls}

## Folder of the Vulkan export: <pass>.spv and weights.bin.
@export_dir var export_dir := "res://neuralao/${model}/vulkan"
${scalar_exports}## The input and output are bottom-up (row 0 at the bottom).
@export var flip_y := false
## Filled by your input pass before this effect runs (${channels} channels, 4 a layer).
var input_texture: RID
var output_texture: RID

const PAD_MULTIPLE := ${multiple}
# name, SPIR-V file, [size_of texture, x, y, z groups divisors / count], bindings: [binding, kind, what]
# (kind: texture = sampled image without sampler, image = storage image, weights = the pass's range of
# weights.bin [offset, bytes], uniform = a 16-byte std140 block holding one value)
const PASSES := [
${passes}
]
# texture: [width of, num, den, offset, height of, num, den, offset, layers, format]
const TEXTURES := {
${textures}
}

var rd: RenderingDevice
var pipelines := {}
var weight_buffers := {}
var textures := {}
var size := Vector2i.ZERO

func _init() -> void:
    effect_callback_type = EFFECT_CALLBACK_TYPE_POST_TRANSPARENT
    rd = RenderingServer.get_rendering_device()

func _render_callback(_callback_type: int, render_data: RenderData) -> void:
    var frame: Vector2i = render_data.get_render_scene_buffers().get_internal_size()
    if frame != size:
        _resize(frame)
    if input_texture.is_valid():
        run()

func _pipeline(p: Array) -> RID:
    if not pipelines.has(p[0]):
        var spirv := RDShaderSPIRV.new()
        spirv.set_stage_bytecode(RenderingDevice.SHADER_STAGE_COMPUTE, FileAccess.get_file_as_bytes(export_dir.path_join(p[1])))
        var shader := rd.shader_create_from_spirv(spirv)
        pipelines[p[0]] = [shader, rd.compute_pipeline_create(shader)]
    return pipelines[p[0]][1]

func _dim(of: String, num: int, den: int, offset: int, w: int, h: int) -> int:
    var base := {"W": w, "H": h, "Wp": ceili(w / float(PAD_MULTIPLE)) * PAD_MULTIPLE, "Hp": ceili(h / float(PAD_MULTIPLE)) * PAD_MULTIPLE}
    return base[of] * num / den + offset

func _resize(frame: Vector2i) -> void:
    for t in textures.values():
        rd.free_rid(t)
    textures.clear()
    size = frame
    for id in TEXTURES:
        var d: Array = TEXTURES[id]
        var fmt := RDTextureFormat.new()
        fmt.texture_type = RenderingDevice.TEXTURE_TYPE_2D_ARRAY
        fmt.width = _dim(d[0], d[1], d[2], d[3], frame.x, frame.y)
        fmt.height = _dim(d[4], d[5], d[6], d[7], frame.x, frame.y)
        fmt.array_layers = d[8]
        fmt.format = d[9]
        fmt.usage_bits = (RenderingDevice.TEXTURE_USAGE_SAMPLING_BIT | RenderingDevice.TEXTURE_USAGE_STORAGE_BIT
            | RenderingDevice.TEXTURE_USAGE_CAN_UPDATE_BIT | RenderingDevice.TEXTURE_USAGE_CAN_COPY_FROM_BIT)
        textures[id] = rd.texture_create(fmt, RDTextureView.new())
    input_texture = textures["${input}"]
    output_texture = textures["${output}"]

func _weights(offset: int, bytes: int) -> RID:
    if not weight_buffers.has(offset):
        var all := FileAccess.get_file_as_bytes(export_dir.path_join("weights.bin"))
        weight_buffers[offset] = rd.storage_buffer_create(bytes, all.slice(offset, offset + bytes))
    return weight_buffers[offset]

func _value(what: String) -> PackedByteArray:
    var block := PackedByteArray()
    block.resize(16)
    if what == "u_flip_y":
        block.encode_s32(0, 1 if flip_y else 0)
    else:
        block.encode_float(0, get(what))
    return block

func run() -> void:
    var frees := []
    var list := rd.compute_list_begin()
    for p in PASSES:
        var uniforms := []
        for b in p[3]:
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
            else:
                u.uniform_type = RenderingDevice.UNIFORM_TYPE_UNIFORM_BUFFER
                var buf := rd.uniform_buffer_create(16, _value(b[2]))
                frees.append(buf)
                u.add_id(buf)
            uniforms.append(u)
        var pipeline := _pipeline(p)
        var set := rd.uniform_set_create(uniforms, pipelines[p[0]][0], 0)
        frees.append(set)
        var g: Array = p[2]
        var t: RID = textures[g[0]]
        var tf := rd.texture_get_format(t)
        rd.compute_list_bind_compute_pipeline(list, pipeline)
        rd.compute_list_bind_uniform_set(list, set, 0)
        rd.compute_list_dispatch(list, ceili(tf.width / float(g[1])), ceili(tf.height / float(g[2])), g[3])
        rd.compute_list_add_barrier(list)
    rd.compute_list_end()
    for r in frees:
        rd.free_rid(r)
"""
_E["godot_scalar_export"] = "## Graph input '${onnx}' (${meaning}).\n@export var ${name} := 0.1\n"
_E["godot_pass"] = '    ["${entry}", "${spirv}", ["${size_of}", ${gx}, ${gy}, ${gz}], [${bindings}]],'
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
