"""GLSL generated from the ONNX graph: the baked-MLP fragment shader and the U-Net compute passes.

Structure (tinygrad's ``onnx.py`` / ``cstyle.py`` and hls4ml's templates + writer):

* **Op tables.** :class:`VectorOps` (per-pixel dense networks, fragment target) and
  :class:`ImageOps` (NCHW image networks, compute target) map an ONNX op type to a handler method
  named exactly after the op, whose positional parameters are the op's inputs and whose
  keyword-only parameters are the ONNX attributes with the ONNX defaults. Handlers lower the graph to
  a small IR (dense layers / compute passes) and fuse on the way (bias, batch norm, activations,
  concat into the consuming conv). An op not in the table, an attribute the handler does not take,
  or an attribute value it cannot honour raises :class:`NeuralaoError` naming the op and the node.
* **Dialects.** :class:`Dialect` is desktop GLSL 4.3 (explicit ``binding`` qualifiers);
  :class:`GLSL330` and :class:`ES300` override only what differs (version line, precision
  statements, no binding qualifiers: the host binds blocks and samplers, the manifest says where).
  :class:`WGSL` (compute target, WebGPU) overrides the template table it fills from and the binding
  slots: the same op table, passes, writer and manifest write WGSL (``generate_compute(dialect="wgsl")``).
  :class:`Vulkan` (compute target, ``dialect="vulkan"``) is the GLSL table with Vulkan's resource
  declarations (``#version 450``, descriptor set 0, a binding per resource, sampled images without a
  sampler, a std140 uniform block for a pass's scalar); the writer adds each pass's SPIR-V.
  In :mod:`.templates` the WGSL table likewise overrides only what differs: the shared templates are
  written once with dialect words (types, declarations, texel fetches), which each dialect spells.
  HLSL and MSL are not written here: :mod:`.cross` makes them from the GLSL through SPIR-V.
* **Writer.** Only the ``_write_*`` functions of :mod:`.vector` and :mod:`.image` produce shader
  text, and only by filling the named templates of :mod:`neuralao.export.glsl.templates`. Identifiers are
  generated (``t3``, ``w0_1``, ``src0``); ONNX node and tensor names go to the manifest, never into
  shader source.

Layout (each module imports only those above it):

    templates.py    every GLSL and WGSL string, as named templates, :func:`fill` / :func:`fill_wgsl`
    graph.py        OnnxGraph / read_graph, the OpTable base (dispatch), glsl_float and small helpers
    dialects.py     Dialect, GLSL330, ES300, WGSL, Vulkan, DIALECTS, COMPUTE_DIALECTS, FRAGMENT_FILES
    activations.py  Act (epilogue activations, both targets)
    views.py        image tensors through Reshape / Transpose as index digits (atoms), no shader text
    memory.py       texture lifetimes, the aliasing plan and peak texture memory of a compute
                    manifest (its "memory" entry), storage formats by precision; no shader text
    vector.py       fragment target: VectorOps, uniform-block packing, writer, manifest, MLPShader
    image.py        compute target: ImageOps, conv weight packing, writer, manifest, ComputeProgram
    validate.py     glslangValidator
    cross.py        SPIR-V of the Vulkan passes; HLSL / MSL from the GLSL passes (SPIR-V -> SPIRV-Cross),
                    their entry points, resource names and registers
    files.py        export folders: write_* / load_* for both targets, hashes checked
    engine_templates.py  Unity / Unreal / Godot wrapper text, as named templates
    engines.py      engine wrappers of a program from its GLSL and Vulkan manifests (docs/engines/)

Public API (stable; ``export/mlp.py`` and ``export/unet.py`` call it):

    generate_mlp_fragment(model, dialect="glsl330", fold_repeated_input=True) -> MLPShader
    write_mlp_export(shader, out_dir, validate=True) -> Path      (manifest.json path)
    load_mlp_export(export_dir, dialect="glsl330") -> MLPShader
    generate_compute(model, precision="fp32", kind="unet", local_size=None, conv_block=None,
                     dialect="glsl430"|"wgsl"|"vulkan", preset="gpu"|"cpu", fuse=None) -> ComputeProgram
        (PRESETS: gpu = 1 texel x 1 layer per invocation, 8x8 groups, cheap passes fused; cpu = llvmpipe's
        8x4x2 blocks, no fusion; fp16 = RGBA16F storage but for the input and what is computed from it
        pixel by pixel, fp16 conv products summed in fp32 where the compiler has a half type)
    write_compute_export(program, out_dir, validate=True, cross=False) -> Path
        (cross: + HLSL, MSL, each pass's names and registers in its "hlsl" / "msl" entry; a Vulkan
        program: + <pass>.spv)
    load_compute_export(export_dir) -> ComputeProgram
    load_cross_sources(export_dir, language="hlsl"|"msl") -> {pass name: text}
    memory_plan(manifest, width, height, precision="fp32") -> MemoryPlan
        texture bytes of a compute manifest's frame at width x height pixels: per texture, per
        aliasing slot, in all (separate, aliased, live); the manifest's "memory" entry is its output
    memory_schedule(manifest) -> MemorySchedule   steps, lifetimes, aliasing slots (no sizes)
    validate_glsl(source, stage) -> None                         (glslangValidator)
    compile_spirv(source) -> bytes                               (Vulkan GLSL -> SPIR-V, glslangValidator -V)
    compile_hlsl(source, entry) -> bytes                  (HLSL -> Vulkan SPIR-V, glslang's HLSL front end)

The runners are :mod:`neuralao.runtime.glsl_runner` (GL) and :mod:`neuralao.runtime.wgsl_runner` (WebGPU:
WGSL, the Vulkan passes' SPIR-V, and the HLSL compiled back to SPIR-V).
"""

from neuralao.export.glsl.activations import Act
from neuralao.export.glsl.cross import (
    compile_hlsl,
    compile_spirv,
    cross_compile,
    hlsl_interface,
    msl_interface,
    spirv_cross_available,
    validate_hlsl,
)
from neuralao.export.glsl.dialects import (
    COMPUTE_DIALECTS,
    DIALECTS,
    ES300,
    FRAGMENT_FILES,
    GLSL330,
    WGSL,
    Dialect,
    Vulkan,
    get_dialect,
)
from neuralao.export.glsl.files import (
    load_compute_export,
    load_cross_sources,
    load_mlp_export,
    write_compute_export,
    write_mlp_export,
)
from neuralao.export.glsl.graph import FORMAT_VERSION, OnnxGraph, OpTable, glsl_float, read_graph
from neuralao.export.glsl.image import (
    CONV_KINDS,
    FOLDED_OPS,
    MAX_ARRAY_LAYERS,
    MAX_FILTER_TAPS,
    MAX_FOLDED_ELEMENTS,
    MAX_KERNEL,
    MAX_PARAM_BYTES,
    MAX_TEXTURE_SIZE,
    PARAM_ALIGN,
    ComputeProgram,
    ConcatValue,
    Dim,
    Epilogue,
    ImageOps,
    Pass,
    Texture,
    View,
    generate_compute,
)
from neuralao.export.glsl.memory import (
    MemoryPlan,
    MemorySchedule,
    memory_plan,
    memory_schedule,
    plan_slots,
)
from neuralao.export.glsl.validate import glslang_available, validate_glsl
from neuralao.export.glsl.vector import (
    MAX_FRAGMENT_UNIFORM_BLOCKS,
    MAX_STRAIGHT_TILES,
    MAX_UNIFORM_BLOCK_BYTES,
    MAX_VECTOR_WIDTH,
    ConcatOp,
    DenseOp,
    InputBinding,
    MapOp,
    MLPShader,
    UniformBlock,
    VectorOps,
    VecValue,
    generate_mlp_fragment,
    generate_vector_fragment,
)

__all__ = [
    "COMPUTE_DIALECTS",
    "CONV_KINDS",
    "DIALECTS",
    "ES300",
    "FOLDED_OPS",
    "FORMAT_VERSION",
    "FRAGMENT_FILES",
    "GLSL330",
    "MAX_ARRAY_LAYERS",
    "MAX_FILTER_TAPS",
    "MAX_FOLDED_ELEMENTS",
    "MAX_FRAGMENT_UNIFORM_BLOCKS",
    "MAX_KERNEL",
    "MAX_PARAM_BYTES",
    "MAX_STRAIGHT_TILES",
    "MAX_TEXTURE_SIZE",
    "MAX_UNIFORM_BLOCK_BYTES",
    "MAX_VECTOR_WIDTH",
    "PARAM_ALIGN",
    "Act",
    "ComputeProgram",
    "ConcatOp",
    "ConcatValue",
    "DenseOp",
    "Dialect",
    "Dim",
    "Epilogue",
    "ImageOps",
    "InputBinding",
    "MLPShader",
    "MapOp",
    "MemoryPlan",
    "MemorySchedule",
    "OnnxGraph",
    "OpTable",
    "Pass",
    "Texture",
    "UniformBlock",
    "VecValue",
    "VectorOps",
    "View",
    "Vulkan",
    "WGSL",
    "compile_hlsl",
    "compile_spirv",
    "cross_compile",
    "generate_compute",
    "generate_mlp_fragment",
    "generate_vector_fragment",
    "get_dialect",
    "glsl_float",
    "glslang_available",
    "hlsl_interface",
    "load_compute_export",
    "load_cross_sources",
    "load_mlp_export",
    "memory_plan",
    "memory_schedule",
    "msl_interface",
    "plan_slots",
    "read_graph",
    "spirv_cross_available",
    "validate_glsl",
    "validate_hlsl",
    "write_compute_export",
    "write_mlp_export",
]
