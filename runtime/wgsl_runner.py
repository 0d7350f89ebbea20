"""Headless executor for the generated WGSL compute passes and the Vulkan passes' SPIR-V: WebGPU
through ``wgpu`` (wgpu-native), on Mesa's lavapipe Vulkan driver here (any WebGPU adapter elsewhere).

The WGSL twin of :func:`neuralao.runtime.glsl_runner.run_compute`, driven only by what an engine reads: the
``.wgsl`` sources, ``weights.bin`` and the manifest (format ``neuralao-wgsl-compute``). The Vulkan
dialect's passes (format ``neuralao-vulkan-compute``) bind the same way (one bind group = descriptor set
0, the same bindings), so the same machinery runs their SPIR-V: ``via="passthrough"`` hands the SPIR-V
words to the Vulkan driver unchanged (wgpu's SPIR-V passthrough: what an engine's
``vkCreateShaderModule`` gets), ``via="naga"`` translates them with naga's SPIR-V front end first (what
a WebGPU implementation that takes SPIR-V does). The HLSL of a GLSL export runs the same way, compiled to
SPIR-V by glslang's HLSL front end and bound by its registers.

    run_wgsl_all(program_or_dir, x, flip_y=False, scalars=None) -> {onnx output name: (1, C, H, W) f32}
    run_wgsl(program_or_dir, x, flip_y=False, scalars=None) -> (1, C_out, H, W) f32   (first graph output)
    run_spirv_all(program_or_dir, x, flip_y=False, scalars=None, via="passthrough") -> as run_wgsl_all
    run_hlsl_all(export_dir, x, flip_y=False, scalars=None) -> as run_wgsl_all  (HLSL -> SPIR-V, passthrough)
    hlsl_bindings(pass_entry, resource) -> (layout, group entries)  an HLSL pass bound by its registers
    time_wgsl(program_or_dir, height, width, repeats=5, scalars=None) -> s/frame
    adapter_info() -> {"device": ..., "backend": ...}

Timings are medians of per-frame wall times; each frame is one command buffer with every pass,
closed by reading one texel of the output back (the queue has finished by then).
"""

from __future__ import annotations

import functools
import json
import logging
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from neuralao.export.glsl import (
    ComputeProgram,
    compile_hlsl,
    compile_spirv,
    load_compute_export,
    load_cross_sources,
)
from neuralao.export.glsl.cross import hlsl_spirv_binding
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.glsl_runner import compute_input, compute_outputs, scalar_values, texture_sizes

log = logging.getLogger(__name__)

# A manifest's texture format -> (WebGPU format, bytes a texel, numpy type of a channel: an unsigned
# integer type is a normalised format, a channel holding value * the type's maximum)
WGPU_FORMATS = {
    "RGBA32F": ("rgba32float", 16, np.float32),
    "R32F": ("r32float", 4, np.float32),
    "RGBA16F": ("rgba16float", 8, np.float16),
    "R16F": ("r16float", 2, np.float16),
    "R16": ("r16unorm", 2, np.uint16),
}
# Storage formats as the GLSL manifests spell them (a WGSL manifest spells WebGPU's already).
_STORAGE_FORMATS = {fmt.lower(): name for fmt, (name, _, _) in WGPU_FORMATS.items()}
WGSL_FORMAT = "neuralao-wgsl-compute"
VULKAN_FORMAT = "neuralao-vulkan-compute"
GLSL_FORMAT = "neuralao-glsl-compute"
_PASSTHROUGH = "spirv-shader-passthrough"
# WGSL f16 arithmetic (enable f16): requested where the adapter has it; else the fp32 types run
_SHADER_F16 = "shader-f16"
# Storage use of the formats core WebGPU leaves out (r16float: the fp16 AO targets of Vulkan SPIR-V and
# HLSL run through passthrough; r16unorm: their hybrid's GTAO), where the adapter has them
_ADAPTER_FORMATS = "texture-adapter-specific-format-features"
# wgpu-native's 16-bit normalised formats (r16unorm), where the adapter has them
_NORM16 = "texture-format16bit-norm"
# Formats wgpu-native has beyond webgpu.h: wgpu's Python API takes them as wgpu-native's enum values
# (named in its wgpu.h), under the feature that allows them.
_NATIVE_FORMATS = {"r16unorm": ("WGPUNativeTextureFormat_R16Unorm", _NORM16)}


@functools.cache
def _device():
    """The process-wide WebGPU device (imported lazily: ``wgpu`` is needed only for WGSL runs)."""
    try:
        import wgpu
    except ImportError:  # pragma: no cover - pinned in pyproject
        raise NeuralaoError("running WGSL needs the wgpu package (pip install wgpu)") from None
    adapter = wgpu.gpu.request_adapter_sync(power_preference="high-performance")
    if adapter is None:
        raise NeuralaoError("no WebGPU adapter (install a Vulkan driver, e.g. Debian's mesa-vulkan-drivers)")
    # SPIR-V passthrough (Vulkan adapters) is only used by run_spirv_all(via="passthrough")
    features = [f for f in (_PASSTHROUGH, _SHADER_F16, _ADAPTER_FORMATS, _NORM16) if f in adapter.features]
    return wgpu, adapter, adapter.request_device_sync(required_features=features, required_limits={})


def gpu_format(name: str) -> str | int:
    """WebGPU format ``name`` as wgpu's API takes it: the name, or wgpu-native's enum value of a format
    webgpu.h leaves out (:data:`_NATIVE_FORMATS`); NeuralaoError where the device lacks its feature."""
    if name not in _NATIVE_FORMATS:
        return name
    enum, feature = _NATIVE_FORMATS[name]
    if feature not in _device()[2].features:
        raise NeuralaoError(f"this WebGPU adapter has no {feature}: it cannot allocate {name} textures")
    from wgpu.backends.wgpu_native._ffi import lib

    return getattr(lib, enum)


def to_texels(data: np.ndarray, dtype: type) -> bytes:
    """float32 ``data`` as texels whose channels are ``dtype`` (an unsigned integer type: normalised,
    clamped to [0, 1] and rounded to the nearest step, as a GPU stores it)."""
    if np.issubdtype(dtype, np.unsignedinteger):
        top = np.iinfo(dtype).max
        data = np.rint(np.clip(np.asarray(data, np.float64), 0.0, 1.0) * top)
    return np.ascontiguousarray(data, dtype).tobytes()


def from_texels(raw, dtype: type) -> np.ndarray:
    """Texel bytes whose channels are ``dtype`` as float32 (normalised integers divided by their maximum)."""
    data = np.frombuffer(raw, dtype)
    if np.issubdtype(dtype, np.unsignedinteger):
        return (data / np.float64(np.iinfo(dtype).max)).astype(np.float32)
    return data.astype(np.float32)


def adapter_info() -> dict[str, str]:
    """The adapter WGSL runs on: {"device": ..., "backend": ..., "description": ...}."""
    _, adapter, _ = _device()
    info = adapter.info
    return {"device": info["device"], "backend": info["backend_type"], "description": info["description"]}


def _program(program_or_dir: ComputeProgram | str | Path, fmt: str = WGSL_FORMAT) -> ComputeProgram:
    prog = (
        program_or_dir if isinstance(program_or_dir, ComputeProgram) else load_compute_export(program_or_dir)
    )
    if prog.manifest.get("format") != fmt:
        how = {
            WGSL_FORMAT: "dialect='wgsl' / --target wgsl",
            VULKAN_FORMAT: "dialect='vulkan' / --dialect vulkan",
            GLSL_FORMAT: "--target image --hlsl-msl",
        }[fmt]
        raise NeuralaoError(f"not a {fmt} program (generate it with {how})")
    return prog


def _spirv_passthrough(dev, words: bytes):
    """A shader module of SPIR-V ``words`` handed to the Vulkan driver as they are (wgpu-native's
    ``wgpuDeviceCreateShaderModuleSpirV``; wgpu's Python API exposes SPIR-V only through naga)."""
    from wgpu.backends.wgpu_native import _api
    from wgpu.backends.wgpu_native._ffi import ffi

    if _PASSTHROUGH not in dev.features:
        raise NeuralaoError(f"this adapter has no {_PASSTHROUGH} (a Vulkan adapter has): use via='naga'")
    # code and label are locals, so the memory they point to lives until wgpu has copied it
    code = ffi.new("uint32_t[]", len(words) // 4)
    ffi.memmove(code, words, len(words))
    label = _api.to_c_string_view("neuralao pass")
    desc = ffi.new("WGPUShaderModuleDescriptorSpirV *")
    desc.label, desc.sourceSize, desc.source = label, len(words) // 4, code
    module = _api.libf.wgpuDeviceCreateShaderModuleSpirV(dev._internal, desc)
    return _api.GPUShaderModule("neuralao pass", module, dev)


_PIPELINES: dict[tuple, tuple] = {}


def _pipeline(code: str | bytes, layout_key: str, via: str = "naga", entry: str = "main") -> tuple:
    """(bind group layout, compute pipeline) of a pass (``code``: WGSL source or SPIR-V bytes; layout_key:
    its layout entries as JSON; ``via``: how SPIR-V reaches the driver; ``entry``: the entry point),
    cached for the process: compiling is the slow part on lavapipe."""
    key = (code, layout_key, via, entry)
    if key not in _PIPELINES:
        wgpu, _, dev = _device()
        bgl = dev.create_bind_group_layout(entries=json.loads(layout_key))
        module = (
            _spirv_passthrough(dev, code)
            if isinstance(code, bytes) and via == "passthrough"
            else dev.create_shader_module(code=code)
        )
        pipeline = dev.create_compute_pipeline(
            layout=dev.create_pipeline_layout(bind_group_layouts=[bgl]),
            compute={"module": module, "entry_point": entry},
        )
        _PIPELINES[key] = (bgl, pipeline)
    return _PIPELINES[key]


class _WgslRun:
    """Textures for one input size, one pipeline and bind group per pass, the weights buffer."""

    def __init__(
        self,
        prog: ComputeProgram,
        height: int,
        width: int,
        scalars: dict[str, float],
        flip_y: bool,
        via: str = "naga",
    ):
        wgpu, _, dev = _device()
        self.wgpu, self.dev, self.m = wgpu, dev, prog.manifest
        tu = wgpu.TextureUsage
        self.textures = {}
        for ident, (tw, th, layers, _) in texture_sizes(self.m, height, width).items():
            fmt, texel, _ = WGPU_FORMATS[self.m["textures"][ident]["format"]]
            tex = dev.create_texture(
                size=(tw, th, layers),
                format=gpu_format(fmt),
                dimension="2d",
                usage=tu.TEXTURE_BINDING | tu.STORAGE_BINDING | tu.COPY_DST | tu.COPY_SRC,
            )
            self.textures[ident] = (tex, tex.create_view(dimension="2d-array"), tw, th, layers, texel)
        bu = wgpu.BufferUsage
        weights = prog.weights or b"\0" * 16
        self.weights = dev.create_buffer_with_data(data=weights, usage=bu.STORAGE)
        self.via = via
        self.passes = []
        for p in self.m["passes"]:
            self.passes.append(self._pass(_code(prog, p["shader"]), p, scalars, flip_y))

    def _uniform(self, value: float | int, dtype: str):
        data = np.zeros(4, dtype)
        data[0] = value
        return self.dev.create_buffer_with_data(data=data.tobytes(), usage=self.wgpu.BufferUsage.UNIFORM)

    def _pass(self, code: str | bytes, p: dict, scalars: dict[str, float], flip_y: bool):
        wgpu, dev = self.wgpu, self.dev
        stage = wgpu.ShaderStage.COMPUTE
        layout, group = [], []
        for inp in p["inputs"]:
            layout.append(
                {
                    "binding": inp["binding"],
                    "visibility": stage,
                    "texture": {"sample_type": "unfilterable-float", "view_dimension": "2d-array"},
                }
            )
            group.append({"binding": inp["binding"], "resource": self.textures[inp["texture"]][1]})
        out = p["output"]
        layout.append(
            {
                "binding": out["binding"],
                "visibility": stage,
                "storage_texture": {
                    "access": "write-only",
                    "format": gpu_format(_STORAGE_FORMATS.get(out["format"], out["format"])),
                    "view_dimension": "2d-array",
                },
            }
        )
        group.append({"binding": out["binding"], "resource": self.textures[out["texture"]][1]})
        if "params" in p:
            prm = p["params"]
            layout.append(
                {"binding": prm["binding"], "visibility": stage, "buffer": {"type": "read-only-storage"}}
            )
            group.append(
                {
                    "binding": prm["binding"],
                    "resource": {"buffer": self.weights, "offset": prm["offset"], "size": prm["bytes"]},
                }
            )
        for name, u in p.get("uniforms", {}).items():
            buf = (
                self._uniform(int(flip_y), "<i4")
                if name == "u_flip_y"
                else self._uniform(scalars[u["onnx_input"]], "<f4")
            )
            layout.append({"binding": u["binding"], "visibility": stage, "buffer": {"type": "uniform"}})
            group.append({"binding": u["binding"], "resource": {"buffer": buf, "offset": 0, "size": 16}})
        bgl, pipeline = _pipeline(code, json.dumps(layout), self.via)
        _, _, tw, th, layers, _ = self.textures[out["texture"]]
        lx, ly, _ = p["local_size"]
        bx, by, bl = p.get("block", [1, 1, 1])
        groups = (-(-tw // (lx * bx)), -(-th // (ly * by)), layers // bl)
        return pipeline, dev.create_bind_group(layout=bgl, entries=group), groups

    def upload(self, x: np.ndarray) -> None:
        tex, _, w, h, layers, texel = self.textures[self.m["input"]["texture"]]
        data = np.zeros((layers * 4, h, w), np.float32)
        data[: x.shape[1]] = x[0]
        data = np.ascontiguousarray(data.reshape(layers, 4, h, w).transpose(0, 2, 3, 1))
        self.dev.queue.write_texture(
            {"texture": tex}, data.tobytes(), {"bytes_per_row": w * 16, "rows_per_image": h}, (w, h, layers)
        )

    def dispatch(self) -> None:
        enc = self.dev.create_command_encoder()
        cp = enc.begin_compute_pass()
        for pipeline, group, groups in self.passes:  # one pass encoder: WebGPU orders the dispatches
            cp.set_pipeline(pipeline)
            cp.set_bind_group(0, group)
            cp.dispatch_workgroups(*groups)
        cp.end()
        self.dev.queue.submit([enc.finish()])

    def read(self, ident: str, channels: int, size: tuple[int, int] | None = None) -> np.ndarray:
        tex, _, w, h, layers, _ = self.textures[ident]
        w, h = size or (w, h)
        raw = self.dev.queue.read_texture(
            {"texture": tex}, {"bytes_per_row": w * 16, "rows_per_image": h}, (w, h, layers)
        )
        buf = np.frombuffer(raw, np.float32).reshape(layers, h, w, 4)
        return np.ascontiguousarray(buf.transpose(0, 3, 1, 2).reshape(layers * 4, h, w)[None, :channels])


def hlsl_bindings(p: dict, resource: Callable[[dict], object]) -> tuple[list, list]:
    """(bind group layout entries, bind group entries) of a pass's HLSL compiled by
    :func:`neuralao.export.glsl.compile_hlsl`, from its manifest ``hlsl.resources``: each at the binding its
    register gets; ``resource(r)`` is what is bound for resource ``r`` (a texture view, or a buffer binding
    {"buffer", "offset", "size"})."""
    wgpu = _device()[0]
    layout, group = [], []
    for r in p["hlsl"]["resources"]:
        entry = {"binding": hlsl_spirv_binding(r["register"]), "visibility": wgpu.ShaderStage.COMPUTE}
        if r["type"].startswith("Texture2DArray"):
            entry["texture"] = {"sample_type": "unfilterable-float", "view_dimension": "2d-array"}
        elif r["type"].startswith("RWTexture2DArray"):
            fmt = gpu_format(_STORAGE_FORMATS[p["output"]["format"]])
            entry["storage_texture"] = {"access": "write-only", "format": fmt, "view_dimension": "2d-array"}
        elif r["type"] == "ByteAddressBuffer":
            entry["buffer"] = {"type": "read-only-storage"}
        else:  # a $Globals member (a network pass's uniform) or a frame pass's FrameUniforms cbuffer
            entry["buffer"] = {"type": "uniform"}
        layout.append(entry)
        group.append({"binding": entry["binding"], "resource": resource(r)})
    return layout, group


class _HlslRun(_WgslRun):
    """The HLSL passes of a GLSL export written with HLSL / MSL, each compiled back to SPIR-V by glslang's
    HLSL front end and passed to the Vulkan driver as it is. Bound as Unity or Unreal would from the
    manifest's ``hlsl.resources``: each at the binding its register gets, each pass's params a buffer of
    its own (its range of weights.bin), the uniform a 16-byte $Globals."""

    def __init__(self, prog: ComputeProgram, hlsl: dict[str, str], height, width, scalars, flip_y):
        self.hlsl, self.weights_bytes = hlsl, prog.weights
        super().__init__(prog, height, width, scalars, flip_y, via="passthrough")

    def _pass(self, code: str | bytes, p: dict, scalars: dict[str, float], flip_y: bool):
        dev = self.dev
        spirv = hlsl_spirv(self.hlsl[p["name"]], p["hlsl"]["entry"])

        def resource(r: dict):
            if "texture" in r:
                return self.textures[r["texture"]][1]
            if "weights" in r:
                return weights_range(self.weights_bytes, r["weights"])
            # a $Globals member at offset 0: the pass's one uniform
            name = r["name"]
            value = int(flip_y) if name == "u_flip_y" else scalars[p["uniforms"][name]["onnx_input"]]
            return {"buffer": self._uniform(value, "<i4" if r["type"] == "int" else "<f4"), "size": 16}

        layout, group = hlsl_bindings(p, resource)
        bgl, pipeline = _pipeline(spirv, json.dumps(layout), "passthrough", p["hlsl"]["entry"])
        _, _, tw, th, layers, _ = self.textures[p["output"]["texture"]]
        lx, ly, _ = p["hlsl"]["numthreads"]
        bx, by, bl = p.get("block", [1, 1, 1])
        groups = (-(-tw // (lx * bx)), -(-th // (ly * by)), layers // bl)
        return pipeline, dev.create_bind_group(layout=bgl, entries=group), groups


def weights_range(weights: bytes, w: dict) -> dict:
    """A buffer binding of a pass's own params buffer: its range of weights.bin (``w``: the resource's
    "weights" {"offset", "bytes"}), as Unity and Unreal bind it."""
    wgpu, _, dev = _device()
    data = weights[w["offset"] : w["offset"] + w["bytes"]]
    buf = dev.create_buffer_with_data(data=data, usage=wgpu.BufferUsage.STORAGE)
    return {"buffer": buf, "offset": 0, "size": w["bytes"]}


@functools.cache
def hlsl_spirv(source: str, entry: str) -> bytes:
    """:func:`neuralao.export.glsl.compile_hlsl`, cached for the process (glslang is the slow part)."""
    return compile_hlsl(source, entry)


def _code(prog: ComputeProgram, shader: str) -> str | bytes:
    """What a pass's module is made from: WGSL source, or a Vulkan pass's SPIR-V (read from the export,
    or compiled from the source when the program was generated in this process)."""
    if prog.manifest["format"] != VULKAN_FORMAT:
        code = prog.sources[shader]
        arithmetic = prog.manifest.get("arithmetic", {})
        if arithmetic.get("precision") == "fp16" and _SHADER_F16 not in _device()[2].features:
            # no f16 on this device: the same passes with the fp32 accumulation types the manifest gives
            code = code.replace(arithmetic["declarations"], arithmetic["fp32_declarations"])
        return code
    if shader not in prog.spirv:
        prog.spirv[shader] = compile_spirv(prog.sources[shader])
    return prog.spirv[shader]


def run_wgsl_all(
    program_or_dir: ComputeProgram | str | Path,
    x: np.ndarray,
    flip_y: bool = False,
    scalars: dict[str, float] | None = None,
) -> dict:
    """Run every WGSL pass on x : (1, C, H, W) float32; {onnx output name: (1, C_out, H, W) float32}."""
    prog = _program(program_or_dir)
    x = compute_input(prog.manifest, x)
    run = _WgslRun(prog, x.shape[2], x.shape[3], scalar_values(prog.manifest, scalars), flip_y)
    run.upload(x)
    run.dispatch()
    return compute_outputs(prog.manifest, run.read)


def run_wgsl(
    program_or_dir: ComputeProgram | str | Path,
    x: np.ndarray,
    flip_y: bool = False,
    scalars: dict[str, float] | None = None,
) -> np.ndarray:
    """The first graph output of :func:`run_wgsl_all`: (1, C_out, H, W) float32 (the U-Net's ao)."""
    prog = _program(program_or_dir)
    return run_wgsl_all(prog, x, flip_y, scalars)[prog.manifest["outputs"][0]["onnx_name"]]


def run_spirv_all(
    program_or_dir: ComputeProgram | str | Path,
    x: np.ndarray,
    flip_y: bool = False,
    scalars: dict[str, float] | None = None,
    via: str = "passthrough",
) -> dict:
    """Run every pass of a Vulkan program (``generate_compute(dialect="vulkan")`` or its export folder) as
    SPIR-V on x : (1, C, H, W) float32; {onnx output name: (1, C_out, H, W) float32}. ``via``:
    "passthrough" (the SPIR-V words to the Vulkan driver as they are) or "naga" (translated by naga's
    SPIR-V front end first)."""
    if via not in ("passthrough", "naga"):
        raise NeuralaoError(f"via must be 'passthrough' or 'naga', got {via!r}")
    prog = _program(program_or_dir, VULKAN_FORMAT)
    x = compute_input(prog.manifest, x)
    run = _WgslRun(prog, x.shape[2], x.shape[3], scalar_values(prog.manifest, scalars), flip_y, via)
    run.upload(x)
    run.dispatch()
    return compute_outputs(prog.manifest, run.read)


def run_hlsl_all(
    export_dir: str | Path,
    x: np.ndarray,
    flip_y: bool = False,
    scalars: dict[str, float] | None = None,
) -> dict:
    """Run the HLSL of every pass of a GLSL export written with HLSL / MSL (``neuralao glsl ...
    --hlsl-msl``) on x : (1, C, H, W) float32, each pass compiled to SPIR-V by glslang's HLSL front end
    (:func:`neuralao.export.glsl.compile_hlsl`) and run on the Vulkan adapter through wgpu's SPIR-V
    passthrough; {onnx output name: (1, C_out, H, W) float32}."""
    prog = _program(export_dir, GLSL_FORMAT)
    x = compute_input(prog.manifest, x)
    hlsl = load_cross_sources(export_dir, "hlsl")
    run = _HlslRun(prog, hlsl, x.shape[2], x.shape[3], scalar_values(prog.manifest, scalars), flip_y)
    run.upload(x)
    run.dispatch()
    return compute_outputs(prog.manifest, run.read)


def time_wgsl(
    program_or_dir: ComputeProgram | str | Path,
    height: int,
    width: int,
    repeats: int = 5,
    warmup: int = 1,
    scalars: dict[str, float] | None = None,
) -> float:
    """Median seconds for all passes at width x height (random input; scalar inputs 1.0 unless given)."""
    prog = _program(program_or_dir)
    values = {u["onnx_input"]: 1.0 for u in prog.manifest.get("uniforms", [])} | dict(scalars or {})
    run = _WgslRun(prog, height, width, scalar_values(prog.manifest, values), False)
    c = prog.manifest["input"]["channels"]
    run.upload(np.random.default_rng(0).normal(size=(1, c, height, width)).astype(np.float32))
    out = prog.manifest["outputs"][0]

    def frame() -> None:
        run.dispatch()
        run.read(out["texture"], 1, size=(1, 1))  # waits for the queue

    for _ in range(warmup):
        frame()
    times = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        frame()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))
