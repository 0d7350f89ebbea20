# Generated from the manifests of unet-gtao by `python -m neuralao.export.glsl.engines`; tests/test_engine_wrappers.py checks it against the manifests and the exported shaders.
# Not run here (no Godot): the SPIR-V it loads, bound at these bindings, runs the whole frame on Vulkan
# (lavapipe) in tests/test_frame_passes.py (the export's vulkan/ folder:
# `neuralao glsl MODEL.onnx --target image --dialect vulkan`).
@tool
extends CompositorEffect
class_name NeuralAOUnetGtao

## Folder of the Vulkan export: <pass>.spv and weights.bin.
@export_dir var export_dir := "res://neuralao/unet-gtao/vulkan"
## The AO radius in scene units.
@export var radius := 1.0
## Your passes write these each frame before this effect runs (texture(id), W x H):
##  depth: write each frame: linear depth -z_cam in scene units (lane 0), 0 on background; the passes reconstruct camera-space positions from it, the pixel and u_proj
##  normal: write each frame: camera-space unit normal (xyz), OpenGL axes, facing the viewer
## The AO, W x H, for your composite.
var ao_texture: RID

const PAD_MULTIPLE := 8
const INTERNAL_HEIGHT := 256  # network rows; 0: the network runs at W x H
const FLIP_Y := 0  # RenderingDevice (Vulkan, D3D12, Metal): row 0 is the top row
# FrameUniforms (std140, 32 bytes): [member, offset, lanes: value names]
const FRAME_UNIFORMS := [
    ["u_proj", 0, ["p00", "p11"]],
    ["u_radius", 8, ["radius"]],
    ["u_pixels_per_unit", 12, ["pixels_per_unit"]],
    ["u_flip_y", 16, ["flip"]],
]
# texture: [width: symbol, num, den, offset, height: symbol, num, den, offset, layers, format]
# (symbols: W x H the frame, w x h the network's input, wp x hp those padded; "" a fixed size)
const TEXTURES := {
    "ao": ["W", 1, 1, 0, "H", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32_SFLOAT],
    "depth": ["W", 1, 1, 0, "H", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32_SFLOAT],
    "gtao": ["W", 1, 1, 0, "H", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32_SFLOAT],
    "gtao_raw": ["W", 1, 1, 0, "H", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32_SFLOAT],
    "low_gbuffer": ["w", 1, 1, 0, "h", 1, 1, 0, 3, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "normal": ["W", 1, 1, 0, "H", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t0": ["w", 1, 1, 0, "h", 1, 1, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t12": ["wp", 1, 1, 0, "hp", 1, 1, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t14": ["wp", 1, 1, 0, "hp", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t16": ["wp", 1, 2, 0, "hp", 1, 2, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t18": ["wp", 1, 4, 0, "hp", 1, 4, 0, 4, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t2": ["", 0, 1, 1, "", 0, 1, 1, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t20": ["wp", 1, 8, 0, "hp", 1, 8, 0, 8, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t22": ["wp", 1, 4, 0, "hp", 1, 4, 0, 4, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t23": ["wp", 1, 4, 0, "hp", 1, 4, 0, 4, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t25": ["wp", 1, 2, 0, "hp", 1, 2, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t26": ["wp", 1, 2, 0, "hp", 1, 2, 0, 2, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t28": ["wp", 1, 1, 0, "hp", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t29": ["wp", 1, 1, 0, "hp", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t32": ["w", 1, 1, 0, "h", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
    "t9": ["wp", 1, 1, 0, "hp", 1, 1, 0, 1, RenderingDevice.DATA_FORMAT_R32G32B32A32_SFLOAT],
}
# pass: [SPIR-V file, [size_of texture, texels x a group, texels y a group, groups z], bindings]
# bindings: [binding, kind, what]: texture = sampled image without sampler, image = storage image,
# weights = the pass's range of weights.bin [offset, bytes], uniform = a 16-byte std140 block holding
# the named value, frame = the FrameUniforms buffer
const PASSES := {
    "f_gtao": ["f_gtao.spv", ["gtao_raw", 8, 8, 1], [[0, "texture", "depth"], [1, "texture", "normal"], [2, "image", "gtao_raw"], [3, "frame", "FrameUniforms"]]],
    "f_gtao_blur": ["f_gtao_blur.spv", ["gtao", 8, 8, 1], [[0, "texture", "depth"], [1, "texture", "gtao_raw"], [2, "image", "gtao"], [3, "frame", "FrameUniforms"]]],
    "f_downsample": ["f_downsample.spv", ["low_gbuffer", 8, 8, 1], [[0, "texture", "depth"], [1, "texture", "normal"], [2, "texture", "gtao"], [3, "texture", "gtao_raw"], [4, "image", "low_gbuffer"], [5, "frame", "FrameUniforms"]]],
    "f_network_input": ["f_network_input.spv", ["t0", 8, 8, 1], [[0, "texture", "low_gbuffer"], [1, "image", "t0"], [2, "frame", "FrameUniforms"]]],
    "f_network_radius": ["f_network_radius.spv", ["t2", 1, 1, 1], [[0, "image", "t2"], [1, "frame", "FrameUniforms"]]],
    "p01_pointwise": ["p01_pointwise.spv", ["t9", 8, 8, 1], [[0, "texture", "t0"], [1, "texture", "t2"], [2, "image", "t9"], [3, "weights", [0, 288]], [4, "uniform", "u_flip_y"]]],
    "p02_pointwise": ["p02_pointwise.spv", ["t12", 8, 8, 2], [[0, "texture", "t0"], [1, "texture", "t2"], [2, "image", "t12"], [3, "weights", [512, 448]], [4, "uniform", "u_flip_y"]]],
    "p03_conv": ["p03_conv.spv", ["t14", 8, 8, 1], [[0, "texture", "t12"], [1, "texture", "t9"], [2, "image", "t14"], [3, "weights", [1024, 1744]]]],
    "p04_conv": ["p04_conv.spv", ["t16", 8, 8, 2], [[0, "texture", "t14"], [1, "image", "t16"], [2, "weights", [2816, 1184]]]],
    "p05_conv": ["p05_conv.spv", ["t18", 8, 8, 4], [[0, "texture", "t16"], [1, "image", "t18"], [2, "weights", [4096, 4672]]]],
    "p06_conv": ["p06_conv.spv", ["t20", 8, 8, 8], [[0, "texture", "t18"], [1, "image", "t20"], [2, "weights", [8960, 18560]]]],
    "p07_conv": ["p07_conv.spv", ["t22", 8, 8, 4], [[0, "texture", "t20"], [1, "image", "t22"], [2, "weights", [27648, 18496]]]],
    "p08_conv": ["p08_conv.spv", ["t23", 8, 8, 4], [[0, "texture", "t22"], [1, "texture", "t18"], [2, "image", "t23"], [3, "weights", [46336, 18496]]]],
    "p09_conv": ["p09_conv.spv", ["t25", 8, 8, 2], [[0, "texture", "t23"], [1, "image", "t25"], [2, "weights", [65024, 4640]]]],
    "p10_conv": ["p10_conv.spv", ["t26", 8, 8, 2], [[0, "texture", "t25"], [1, "texture", "t16"], [2, "image", "t26"], [3, "weights", [69888, 4640]]]],
    "p11_conv": ["p11_conv.spv", ["t28", 8, 8, 1], [[0, "texture", "t26"], [1, "image", "t28"], [2, "weights", [74752, 1168]]]],
    "p12_conv": ["p12_conv.spv", ["t29", 8, 8, 1], [[0, "texture", "t28"], [1, "texture", "t14"], [2, "image", "t29"], [3, "weights", [76032, 1168]]]],
    "p13_pointwise": ["p13_pointwise.spv", ["t32", 8, 8, 1], [[0, "texture", "t12"], [1, "texture", "t9"], [2, "texture", "t29"], [3, "image", "t32"], [4, "weights", [77312, 288]], [5, "uniform", "u_flip_y"]]],
    "f_upsample": ["f_upsample.spv", ["ao", 8, 8, 1], [[0, "texture", "depth"], [1, "texture", "normal"], [2, "texture", "t32"], [3, "texture", "low_gbuffer"], [4, "texture", "gtao"], [5, "image", "ao"], [6, "frame", "FrameUniforms"]]],
    "f_composite": ["f_composite.spv", ["ao", 8, 8, 1], [[0, "texture", "depth"], [1, "texture", "t32"], [2, "image", "ao"], [3, "frame", "FrameUniforms"]]],
}
# the frame in order (frame.steps): [pass, when] (when: "" always, or the condition on the network's size)
const STEPS := [
    ["f_gtao", ""],
    ["f_gtao_blur", ""],
    ["f_downsample", ""],
    ["f_network_input", ""],
    ["f_network_radius", ""],
    ["p01_pointwise", ""],
    ["p02_pointwise", ""],
    ["p03_conv", ""],
    ["p04_conv", ""],
    ["p05_conv", ""],
    ["p06_conv", ""],
    ["p07_conv", ""],
    ["p08_conv", ""],
    ["p09_conv", ""],
    ["p10_conv", ""],
    ["p11_conv", ""],
    ["p12_conv", ""],
    ["p13_pointwise", ""],
    ["f_upsample", "(w, h) != (W, H)"],
    ["f_composite", "(w, h) == (W, H)"],
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
    var low := rd.texture_get_format(textures["t0"])
    same_size = low.width == frame.x and low.height == frame.y
    ao_texture = textures["ao"]

func _weights(offset: int, bytes: int) -> RID:
    if not weight_buffers.has(offset):
        var all := FileAccess.get_file_as_bytes(export_dir.path_join("weights.bin"))
        weight_buffers[offset] = rd.storage_buffer_create(bytes, all.slice(offset, offset + bytes))
    return weight_buffers[offset]

func _frame_uniforms(p00: float, p11: float) -> PackedByteArray:
    var values := {"p00": p00, "p11": p11, "radius": radius, "pixels_per_unit": 0.5 * size.y * p11, "flip": FLIP_Y}
    var block := PackedByteArray()
    block.resize(32)
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
    var frame_block := rd.uniform_buffer_create(32, _frame_uniforms(p00, p11))
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
