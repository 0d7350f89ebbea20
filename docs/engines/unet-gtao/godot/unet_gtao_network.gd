# Generated from the manifest of unet-gtao by `python -m neuralao.export.glsl.engines`; tests/test_engine_wrappers.py checks it against the manifest and the generated shaders.
# Not run here (no Godot): the SPIR-V it loads, bound at these bindings, runs on Vulkan in
# tests/test_vulkan_target.py (the Vulkan export: `neuralao glsl MODEL.onnx --target image --dialect vulkan`).
@tool
extends CompositorEffect
class_name NeuralAOUnetGtao

## Folder of the Vulkan export: <pass>.spv and weights.bin.
@export_dir var export_dir := "res://neuralao/unet-gtao/vulkan"
## Graph input 'radius' (radius).
@export var u_radius := 0.1
## The input and output are bottom-up (row 0 at the bottom).
@export var flip_y := false
## Filled by your input pass before this effect runs (5 channels, 4 a layer).
var input_texture: RID
var output_texture: RID

const PAD_MULTIPLE := 8
# name, SPIR-V file, [size_of texture, x, y, z groups divisors / count], bindings: [binding, kind, what]
# (kind: texture = sampled image without sampler, image = storage image, weights = the pass's range of
# weights.bin [offset, bytes], uniform = a 16-byte std140 block holding one value)
const PASSES := [
    ["p00_pad", "p00_pad.spv", ["t1", 8, 8, 2], [[0, "texture", "t0"], [1, "image", "t1"], [3, "uniform", "u_flip_y"]]],
    ["p01_uniform", "p01_uniform.spv", ["t2", 8, 8, 1], [[0, "image", "t2"], [2, "uniform", "u_radius"]]],
    ["p02_conv", "p02_conv.spv", ["t4", 8, 8, 1], [[0, "texture", "t1"], [1, "texture", "t2"], [2, "image", "t4"], [3, "weights", [0, 144]]]],
    ["p03_conv", "p03_conv.spv", ["t5", 8, 8, 1], [[0, "texture", "t1"], [1, "texture", "t4"], [2, "image", "t5"], [3, "weights", [256, 208]]]],
    ["p04_conv", "p04_conv.spv", ["t6", 8, 8, 1], [[0, "texture", "t1"], [1, "texture", "t4"], [2, "image", "t6"], [3, "weights", [512, 1744]]]],
    ["p05_pool_avg", "p05_pool_avg.spv", ["t7", 8, 8, 1], [[0, "texture", "t6"], [1, "image", "t7"]]],
    ["p06_conv", "p06_conv.spv", ["t8", 8, 8, 2], [[0, "texture", "t7"], [1, "image", "t8"], [2, "weights", [2304, 1184]]]],
    ["p07_pool_avg", "p07_pool_avg.spv", ["t9", 8, 8, 2], [[0, "texture", "t8"], [1, "image", "t9"]]],
    ["p08_conv", "p08_conv.spv", ["t10", 8, 8, 4], [[0, "texture", "t9"], [1, "image", "t10"], [2, "weights", [3584, 4672]]]],
    ["p09_pool_avg", "p09_pool_avg.spv", ["t11", 8, 8, 4], [[0, "texture", "t10"], [1, "image", "t11"]]],
    ["p10_conv", "p10_conv.spv", ["t12", 8, 8, 8], [[0, "texture", "t11"], [1, "image", "t12"], [2, "weights", [8448, 18560]]]],
    ["p11_resize_linear", "p11_resize_linear.spv", ["t13", 8, 8, 8], [[0, "texture", "t12"], [1, "image", "t13"]]],
    ["p12_conv", "p12_conv.spv", ["t14", 8, 8, 4], [[0, "texture", "t13"], [1, "image", "t14"], [2, "weights", [27136, 18496]]]],
    ["p13_conv", "p13_conv.spv", ["t15", 8, 8, 4], [[0, "texture", "t14"], [1, "texture", "t10"], [2, "image", "t15"], [3, "weights", [45824, 18496]]]],
    ["p14_resize_linear", "p14_resize_linear.spv", ["t16", 8, 8, 4], [[0, "texture", "t15"], [1, "image", "t16"]]],
    ["p15_conv", "p15_conv.spv", ["t17", 8, 8, 2], [[0, "texture", "t16"], [1, "image", "t17"], [2, "weights", [64512, 4640]]]],
    ["p16_conv", "p16_conv.spv", ["t18", 8, 8, 2], [[0, "texture", "t17"], [1, "texture", "t8"], [2, "image", "t18"], [3, "weights", [69376, 4640]]]],
    ["p17_resize_linear", "p17_resize_linear.spv", ["t19", 8, 8, 2], [[0, "texture", "t18"], [1, "image", "t19"]]],
    ["p18_conv", "p18_conv.spv", ["t20", 8, 8, 1], [[0, "texture", "t19"], [1, "image", "t20"], [2, "weights", [74240, 1168]]]],
    ["p19_conv", "p19_conv.spv", ["t21", 8, 8, 1], [[0, "texture", "t20"], [1, "texture", "t6"], [2, "image", "t21"], [3, "weights", [75520, 1168]]]],
    ["p20_conv", "p20_conv.spv", ["t24", 8, 8, 1], [[0, "texture", "t21"], [1, "texture", "t5"], [2, "image", "t24"], [3, "weights", [76800, 80]], [4, "uniform", "u_flip_y"]]],
]
# texture: [width of, num, den, offset, height of, num, den, offset, layers, format]
const TEXTURES := {
    "t0": ["W", 1, 1, 0, "H", 1, 1, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t1": ["Wp", 1, 1, 0, "Hp", 1, 1, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t2": ["Wp", 0, 1, 1, "Hp", 0, 1, 1, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t4": ["Wp", 1, 1, 0, "Hp", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t5": ["Wp", 1, 1, 0, "Hp", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t6": ["Wp", 1, 1, 0, "Hp", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t7": ["Wp", 1, 2, 0, "Hp", 1, 2, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t8": ["Wp", 1, 2, 0, "Hp", 1, 2, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t9": ["Wp", 1, 4, 0, "Hp", 1, 4, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t10": ["Wp", 1, 4, 0, "Hp", 1, 4, 0, 4, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t11": ["Wp", 1, 8, 0, "Hp", 1, 8, 0, 4, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t12": ["Wp", 1, 8, 0, "Hp", 1, 8, 0, 8, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t13": ["Wp", 1, 4, 0, "Hp", 1, 4, 0, 8, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t14": ["Wp", 1, 4, 0, "Hp", 1, 4, 0, 4, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t15": ["Wp", 1, 4, 0, "Hp", 1, 4, 0, 4, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t16": ["Wp", 1, 2, 0, "Hp", 1, 2, 0, 4, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t17": ["Wp", 1, 2, 0, "Hp", 1, 2, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t18": ["Wp", 1, 2, 0, "Hp", 1, 2, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t19": ["Wp", 1, 1, 0, "Hp", 1, 1, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t20": ["Wp", 1, 1, 0, "Hp", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t21": ["Wp", 1, 1, 0, "Hp", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t24": ["W", 1, 1, 0, "H", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
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
    input_texture = textures["t0"]
    output_texture = textures["t24"]

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
