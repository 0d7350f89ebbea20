"""Run a U-Net export's whole frame on the GPU from its generated passes alone: the frame passes
(:mod:`neuralao.export.glsl.frame`: GTAO and its blur, point sampling, the mean-depth reduction, the
network's input and radius, upsampling with the hybrid's correction and combine, each reading the engine's
depth and normal directly) and the
network's passes, in the order of the manifest's ``frame.steps``, as an engine follows it.

    frame_settings() -> FrameSettings                the runtime references' settings (GTAO, upsampling)
    model_frame_settings(proto) -> FrameSettings     the same for one U-Net (GTAO blurred or not)
    frame_program(model_onnx, dialect) -> ComputeProgram     the network's passes + the frame's
    FrameRunner(program, width, height, flip_y=False, via=None, hlsl=None)  textures and pipelines of one
                                                     frame size
        .run(frame, radius) -> ao (H, W) float32      (1 on background, top row first)
        .read(texture) -> (H, W, 4 * layers) float32  any texture of the frame, top row first
    run_frame(program, frame, radius, flip_y=False, via=None, hlsl=None) -> ao (H, W) float32

Backends by the program's dialect: GLSL 4.30 on the headless GL context (:mod:`neuralao.runtime.gl`),
WGSL through wgpu, Vulkan SPIR-V through wgpu's SPIR-V passthrough (``via="passthrough"``) or naga
(``via="naga"``). A GLSL 4.30 program with ``via="hlsl"``: every step from its HLSL, compiled to SPIR-V
by glslang's HLSL front end and run through wgpu's passthrough, bound by the manifest's registers
(``hlsl``: {pass name: HLSL text}, e.g. an export's files by
:func:`neuralao.export.glsl.load_cross_sources`; passes not in it are cross-compiled from the program's
GLSL as the export writer does). ``flip_y``: the textures are stored bottom-up (GL's convention; the
frame uniform and the pad / crop passes' ``u_flip_y`` = 1) rather than top row first; the AO read back is
top row first either way.
"""

from __future__ import annotations

import functools
import json
import math
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import onnx

from neuralao.export.glsl import ComputeProgram, compile_spirv, generate_compute
from neuralao.export.glsl.frame import (
    UNIFORM_BLOCK_BYTES,
    FrameSettings,
    active_steps,
    frame_sizes,
    generate_frame,
)
from neuralao.runtime.baselines import GTAOSettings, gtao_pass_description, projection_scale
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.internal_resolution import UpsampleSettings
from neuralao.runtime.onnx_io import get_metadata
from neuralao.runtime.unet_input import THICKNESS_CAP, hybrid_gtao_blur
from neuralao.runtime.wgsl_runner import WGPU_FORMATS, from_texels, gpu_format, to_texels

# A manifest's texture format -> GL internal format (R16: 16-bit unsigned normalised, read back as floats)
_GL_FORMATS = {
    "RGBA32F": "GL_RGBA32F",
    "R32F": "GL_R32F",
    "RGBA16F": "GL_RGBA16F",
    "R16F": "GL_R16F",
    "R16": "GL_R16",
}
_GL_ONE_LANE = ("R32F", "R16F", "R16")  # uploaded from one float a texel
_CHANNEL_TYPES = {name: dtype for name, _, dtype in WGPU_FORMATS.values()}


def frame_settings(
    gtao: GTAOSettings | None = None, upsample: UpsampleSettings | None = None
) -> FrameSettings:
    """The :class:`FrameSettings` of the runtime references: ``GTAOSettings`` (defaults: what the shipped
    hybrid was trained on) with its noise tile, and ``UpsampleSettings``."""
    g = gtao if gtao is not None else GTAOSettings()
    if g.thickness_blend or g.thin_occluder_compensation:
        raise NeuralaoError("the frame passes run plain GTAO: no thickness heuristic (both must be 0)")
    u = upsample if upsample is not None else UpsampleSettings()
    desc = gtao_pass_description(g)
    return FrameSettings(
        slices=g.slices,
        steps=g.steps,
        falloff=g.falloff,
        noise_size=g.noise_size,
        blur=g.blur,
        noise=tuple(desc["noise"]["texels"]),
        spatial_sigma=u.spatial_sigma,
        plane_sigma=u.plane_sigma,
        normal_power=u.normal_power,
        floor=u.floor,
        thickness_cap=THICKNESS_CAP,
    )


def model_frame_settings(proto: onnx.ModelProto) -> FrameSettings:
    """:func:`frame_settings` for one U-Net: GTAO with or without its blur, as the model was trained
    (its metadata's ``gtao_blur``)."""
    return frame_settings(GTAOSettings(blur=hybrid_gtao_blur(get_metadata(proto), "the ONNX model")))


def frame_program(model: str | Path | onnx.ModelProto, dialect: str = "glsl430", **kw) -> ComputeProgram:
    """A U-Net's compute program in ``dialect`` with its frame passes (:func:`model_frame_settings`)."""
    proto = model if isinstance(model, onnx.ModelProto) else onnx.load(str(model))
    return generate_frame(generate_compute(proto, dialect=dialect, **kw), model_frame_settings(proto))


def uniform_bytes(yfov: float, radius: float, width: int, height: int, flip_y: bool) -> bytes:
    """The FrameUniforms block (std140, UNIFORM_BLOCK_BYTES bytes): u_proj, u_radius, u_pixels_per_unit,
    u_flip_y."""
    if not (math.isfinite(radius) and radius > 0):
        raise NeuralaoError(f"AO radius must be a positive finite distance, got {radius}")
    p00, p11 = projection_scale(yfov, width, height)
    data = bytearray(UNIFORM_BLOCK_BYTES)
    data[:16] = np.array([p00, p11, radius, 0.5 * height * p11], "<f4").tobytes()
    data[16:20] = np.array([int(flip_y)], "<i4").tobytes()
    return bytes(data)


def _inputs(frame: FrameLike, flip_y: bool, back: bool = False) -> dict[str, np.ndarray]:
    """The engine's input textures in texture row order: depth (H, W, 1) and normal (H, W, 4), and with
    ``back`` (input version 4) depth_back (H, W, 1)."""
    mask = np.asarray(frame["mask"], bool)
    out = {"depth": np.where(mask, np.asarray(frame["depth"], np.float32), np.float32(0.0))[..., None]}
    normal = np.zeros((*mask.shape, 4), np.float32)
    normal[..., :3] = np.where(mask[..., None], np.nan_to_num(np.asarray(frame["normal_cam"], np.float32)), 0)
    out["normal"] = normal
    if back:
        if "depth_back" not in frame:
            raise NeuralaoError(
                "this model reads the G-buffer's back layer (depth_back); render the frames with it "
                "(`neuralao render --back-layer`)"
            )
        out["depth_back"] = np.where(mask, np.asarray(frame["depth_back"], np.float32), np.float32(0.0))[
            ..., None
        ]
    return {k: np.ascontiguousarray(v[::-1] if flip_y else v) for k, v in out.items()}


class FrameRunner:
    """One frame size of a program with frame passes: every texture of the frame allocated, every pass
    compiled. ``run(frame, radius)`` uploads the engine's depth and normal (and back layer), runs the steps
    in order and returns the AO (H, W) float32, top row first."""

    def __init__(
        self,
        program: ComputeProgram,
        width: int,
        height: int,
        flip_y: bool = False,
        via: str | None = None,
        hlsl: dict[str, str] | None = None,
    ):
        if "frame" not in program.manifest:
            raise NeuralaoError("this program has no frame passes (generate_frame adds them)")
        self.program, self.m = program, program.manifest
        self.width, self.height, self.flip_y = int(width), int(height), bool(flip_y)
        self.sizes = frame_sizes(self.m, self.width, self.height)
        fmt = self.m["format"]
        if via == "hlsl":
            if fmt != "neuralao-glsl-compute":
                raise NeuralaoError("the HLSL is made from the GLSL 4.30 passes: give a glsl430 program")
            self.backend = _HlslBackend(self, hlsl)
        elif fmt == "neuralao-glsl-compute":
            self.backend = _GLBackend(self)
        else:
            self.backend = _WgpuBackend(self, via)

    def run(self, frame: FrameLike, radius: float) -> np.ndarray:
        if np.shape(frame["depth"]) != (self.height, self.width):
            raise NeuralaoError(
                f"frame is {np.shape(frame['depth'])[::-1]}, the runner {self.width}x{self.height}"
            )
        inputs = _inputs(frame, self.flip_y, "depth_back" in self.m["frame"]["inputs"])
        ub = uniform_bytes(float(frame["yfov"]), float(radius), self.width, self.height, self.flip_y)
        for ident, data in inputs.items():
            self.backend.upload(ident, data)
        self.backend.dispatch(ub)
        return self.read(self.m["frame"]["output"])[..., 0].copy()

    def read(self, ident: str) -> np.ndarray:
        """Texture ``ident`` as (h, w, 4 * layers) float32, top row first."""
        data = self.backend.read(ident)  # (layers, h, w, 4), texture rows
        layers, h, w, _ = data.shape
        out = np.ascontiguousarray(data.transpose(1, 2, 0, 3).reshape(h, w, layers * 4))
        return out[::-1].copy() if self.flip_y else out

    def release(self) -> None:
        """Free the textures and buffers (GL; WebGPU frees them with the runner)."""
        getattr(self.backend, "release", lambda: None)()

    def __enter__(self) -> FrameRunner:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def run_frame(
    program: ComputeProgram,
    frame: FrameLike,
    radius: float,
    flip_y: bool = False,
    via: str | None = None,
    hlsl: dict[str, str] | None = None,
) -> np.ndarray:
    """AO (H, W) float32 of one G-buffer frame (depth, normal_cam, mask, yfov) at AO radius ``radius``
    (scene units) by the program's whole frame on the GPU; 1 on background."""
    h, w = np.shape(frame["depth"])
    with FrameRunner(program, w, h, flip_y, via, hlsl) as runner:
        return runner.run(frame, radius)


# --------------------------------------------------------------------------- GL


class _GLBackend:
    def __init__(self, runner: FrameRunner):
        from neuralao.runtime import gl
        from neuralao.runtime.gl import GL
        from neuralao.runtime.glsl_runner import _program

        self.context = gl.context  # made current again before each use: a wgpu device made meanwhile
        self.context()  # (its GL backend's probe) leaves another context current
        self.GL, self.r = GL, runner
        self.textures = {}
        for ident, (tw, th, layers, fmt) in runner.sizes.items():
            internal = getattr(GL, _GL_FORMATS[fmt])
            tex = GL.glGenTextures(1)
            GL.glBindTexture(GL.GL_TEXTURE_2D_ARRAY, tex)
            GL.glTexStorage3D(GL.GL_TEXTURE_2D_ARRAY, 1, internal, tw, th, layers)
            self.textures[ident] = (tex, tw, th, layers, internal)
        self.ssbo = gl.create_buffer(np.frombuffer(runner.program.weights or b"\0" * 16, np.uint8))
        self.ubo = gl.create_buffer(nbytes=UNIFORM_BLOCK_BYTES, target=GL.GL_UNIFORM_BUFFER)
        frame = runner.m["frame"]
        by_name = {p["name"]: p for p in frame["passes"]}
        self.steps = []
        for step in active_steps(runner.m, runner.width, runner.height):
            p = by_name[step["frame_pass"]] if "frame_pass" in step else runner.m["passes"][step["index"]]
            self.steps.append((p, _program(compute=runner.program.sources[p["shader"]]), self._groups(p)))

    def _groups(self, p: dict) -> tuple[int, int, int]:
        _, tw, th, layers, _ = self.textures[p["output"]["texture"]]
        lx, ly, _ = p["local_size"]
        bx, by, bl = p.get("block", [1, 1, 1])
        frame_pass = "stage" in p  # a frame pass: one invocation writes every layer
        return (-(-tw // (lx * bx)), -(-th // (ly * by)), 1 if frame_pass else layers // bl)

    def upload(self, ident: str, data: np.ndarray) -> None:
        GL = self.GL
        self.context()
        tex, w, h, _, internal = self.textures[ident]
        fmt = GL.GL_RED if internal in {getattr(GL, _GL_FORMATS[f]) for f in _GL_ONE_LANE} else GL.GL_RGBA
        GL.glPixelStorei(GL.GL_UNPACK_ALIGNMENT, 1)
        GL.glBindTexture(GL.GL_TEXTURE_2D_ARRAY, tex)
        GL.glTexSubImage3D(GL.GL_TEXTURE_2D_ARRAY, 0, 0, 0, 0, w, h, 1, fmt, GL.GL_FLOAT, data)

    def dispatch(self, uniforms: bytes) -> None:
        GL = self.GL
        self.context()
        GL.glBindBuffer(GL.GL_UNIFORM_BUFFER, self.ubo)
        GL.glBufferSubData(GL.GL_UNIFORM_BUFFER, 0, len(uniforms), np.frombuffer(uniforms, np.uint8))
        barrier = GL.GL_TEXTURE_FETCH_BARRIER_BIT | GL.GL_SHADER_IMAGE_ACCESS_BARRIER_BIT
        for p, prog, groups in self.steps:
            GL.glUseProgram(prog)
            for inp in p["inputs"]:
                GL.glActiveTexture(GL.GL_TEXTURE0 + inp["binding"])
                GL.glBindTexture(GL.GL_TEXTURE_2D_ARRAY, self.textures[inp["texture"]][0])
            tex, _, _, _, internal = self.textures[p["output"]["texture"]]
            GL.glBindImageTexture(p["output"]["binding"], tex, 0, GL.GL_TRUE, 0, GL.GL_WRITE_ONLY, internal)
            if "stage" in p:
                GL.glBindBufferBase(GL.GL_UNIFORM_BUFFER, p["uniform_block"]["binding"], self.ubo)
            if "params" in p:
                prm = p["params"]
                GL.glBindBufferRange(
                    GL.GL_SHADER_STORAGE_BUFFER, prm["binding"], self.ssbo, prm["offset"], prm["bytes"]
                )
            if "u_flip_y" in p.get("uniforms", {}):
                GL.glUniform1i(p["uniforms"]["u_flip_y"]["location"], int(self.r.flip_y))
            GL.glDispatchCompute(*groups)
            GL.glMemoryBarrier(barrier)
        GL.glActiveTexture(GL.GL_TEXTURE0)

    def read(self, ident: str) -> np.ndarray:
        GL = self.GL
        self.context()
        tex, w, h, layers, _ = self.textures[ident]
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        GL.glBindTexture(GL.GL_TEXTURE_2D_ARRAY, tex)
        buf = np.empty((layers, h, w, 4), np.float32)
        GL.glGetTexImage(GL.GL_TEXTURE_2D_ARRAY, 0, GL.GL_RGBA, GL.GL_FLOAT, buf)
        return buf

    def release(self) -> None:
        self.context()
        self.GL.glDeleteTextures(len(self.textures), [t[0] for t in self.textures.values()])
        self.GL.glDeleteBuffers(2, [self.ssbo, self.ubo])


# --------------------------------------------------------------------------- WebGPU / Vulkan


class _WgpuBackend:
    def __init__(self, runner: FrameRunner, via: str | None):
        from neuralao.runtime.wgsl_runner import _device

        wgpu, _, dev = _device()
        self.wgpu, self.dev, self.r = wgpu, dev, runner
        vulkan = runner.m["format"] == "neuralao-vulkan-compute"
        self.via = (via or "passthrough") if vulkan else "naga"
        self._prepare()
        tu = wgpu.TextureUsage
        self.textures = {}
        for ident, (tw, th, layers, fmt) in runner.sizes.items():
            name, texel, _ = WGPU_FORMATS[fmt]
            tex = dev.create_texture(
                size=(tw, th, layers),
                format=gpu_format(name),
                usage=tu.TEXTURE_BINDING | tu.STORAGE_BINDING | tu.COPY_DST | tu.COPY_SRC,
            )
            self.textures[ident] = (tex, tex.create_view(dimension="2d-array"), tw, th, layers, texel, name)
        bu = wgpu.BufferUsage
        self.weights = dev.create_buffer_with_data(
            data=runner.program.weights or b"\0" * 16, usage=bu.STORAGE
        )
        self.ubo = dev.create_buffer(size=UNIFORM_BLOCK_BYTES, usage=bu.UNIFORM | bu.COPY_DST)
        flip = np.zeros(4, "<i4")
        flip[0] = int(runner.flip_y)
        self.flip = dev.create_buffer_with_data(data=flip.tobytes(), usage=bu.UNIFORM)
        frame = runner.m["frame"]
        by_name = {p["name"]: p for p in frame["passes"]}
        if vulkan:  # SPIR-V of every pass not read from an export, compiled side by side
            missing = [s for s in runner.program.sources if s not in runner.program.spirv]
            with ThreadPoolExecutor(4) as pool:
                words = pool.map(
                    lambda src: compile_spirv(runner.program.sources[src], validate=False), missing
                )
                runner.program.spirv.update(zip(missing, words, strict=True))
        self.steps = []
        for step in active_steps(runner.m, runner.width, runner.height):
            p = by_name[step["frame_pass"]] if "frame_pass" in step else runner.m["passes"][step["index"]]
            bgl, pipeline, group = self._pipeline(p)
            _, _, tw, th, layers, _, _ = self.textures[p["output"]["texture"]]
            lx, ly, _ = p["local_size"]
            bx, by, bl = p.get("block", [1, 1, 1])
            z = 1 if "stage" in p else layers // bl
            groups = (-(-tw // (lx * bx)), -(-th // (ly * by)), z)
            self.steps.append((pipeline, dev.create_bind_group(layout=bgl, entries=group), groups))

    def _pipeline(self, p: dict) -> tuple:
        """(bind group layout, pipeline, bind group entries) of pass ``p``."""
        from neuralao.runtime.wgsl_runner import _code, _pipeline

        layout, group = self._bindings(p)
        bgl, pipeline = _pipeline(_code(self.r.program, p["shader"]), json.dumps(layout), self.via)
        return bgl, pipeline, group

    def _prepare(self) -> None:
        """Work before the pipelines are made (the HLSL backend's cross-compiling)."""

    def _bindings(self, p: dict) -> tuple[list, list]:
        stage = self.wgpu.ShaderStage.COMPUTE
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
        fmt = gpu_format(self.textures[out["texture"]][6])
        layout.append(
            {
                "binding": out["binding"],
                "visibility": stage,
                "storage_texture": {"access": "write-only", "format": fmt, "view_dimension": "2d-array"},
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
        uniforms = []
        if "stage" in p:  # a frame pass: the frame's uniform block
            uniforms.append((p["uniform_block"]["binding"], self.ubo, UNIFORM_BLOCK_BYTES))
        for name, u in p.get("uniforms", {}).items():
            if name != "u_flip_y":
                raise NeuralaoError(f"pass {p['name']}: the frame sets no uniform {name!r}")
            uniforms.append((u["binding"], self.flip, 16))
        for binding, buf, size in uniforms:
            layout.append({"binding": binding, "visibility": stage, "buffer": {"type": "uniform"}})
            group.append({"binding": binding, "resource": {"buffer": buf, "offset": 0, "size": size}})
        return layout, group

    def upload(self, ident: str, data: np.ndarray) -> None:
        tex, _, w, h, _, texel, name = self.textures[ident]
        dtype = _CHANNEL_TYPES[name]
        data = np.asarray(data, np.float32).reshape(h, w, -1)[..., : texel // np.dtype(dtype).itemsize]
        self.dev.queue.write_texture(
            {"texture": tex},
            to_texels(data, dtype),
            {"bytes_per_row": w * texel, "rows_per_image": h},
            (w, h, 1),
        )

    def dispatch(self, uniforms: bytes) -> None:
        self.dev.queue.write_buffer(self.ubo, 0, uniforms)
        enc = self.dev.create_command_encoder()
        cp = enc.begin_compute_pass()
        for pipeline, group, groups in self.steps:  # one pass encoder: WebGPU orders the dispatches
            cp.set_pipeline(pipeline)
            cp.set_bind_group(0, group)
            cp.dispatch_workgroups(*groups)
        cp.end()
        self.dev.queue.submit([enc.finish()])

    def read(self, ident: str) -> np.ndarray:
        tex, _, w, h, layers, texel, name = self.textures[ident]
        raw = self.dev.queue.read_texture(
            {"texture": tex}, {"bytes_per_row": w * texel, "rows_per_image": h}, (w, h, layers)
        )
        data = from_texels(raw, _CHANNEL_TYPES[name]).reshape(layers, h, w, -1)
        out = np.zeros((layers, h, w, 4), np.float32)
        out[..., : data.shape[-1]] = data
        return out


# --------------------------------------------------------------------------- HLSL


class _HlslBackend(_WgpuBackend):
    """Every step from its HLSL (shader model 5.0, SPIRV-Cross's from the GLSL 4.30 passes; the files of
    an export written with HLSL / MSL, or made here from the program's GLSL as the export writer makes
    them), compiled to SPIR-V by glslang's HLSL front end and run through wgpu's SPIR-V passthrough. Bound
    as Unity or Unreal would from each pass's ``hlsl.resources``: a register's binding, each network pass's
    params a buffer of its own (its range of weights.bin), $Globals' u_flip_y a 16-byte buffer, every
    frame pass's ``FrameUniforms`` cbuffer the frame's one 32-byte buffer."""

    def __init__(self, runner: FrameRunner, hlsl: dict[str, str] | None):
        self.hlsl = dict(hlsl or {})
        self._weights: dict[tuple[int, int], dict] = {}
        super().__init__(runner, "passthrough")

    def _prepare(self) -> None:
        from neuralao.export.glsl import hlsl_interface
        from neuralao.runtime.wgsl_runner import hlsl_spirv

        entries = [*self.r.m["passes"], *self.r.m["frame"]["passes"]]
        self.interface = {p["name"]: p.get("hlsl") or hlsl_interface(p) for p in entries}
        missing = [p for p in entries if p["name"] not in self.hlsl]
        with ThreadPoolExecutor(4) as pool:
            texts = pool.map(lambda p: _cross_hlsl(self.r.program.sources[p["shader"]], p["name"]), missing)
            self.hlsl.update(zip([p["name"] for p in missing], texts, strict=True))
            # glslang compiles every pass side by side (hlsl_spirv caches them for _pipeline)
            names = [p["name"] for p in entries]
            list(pool.map(lambda n: hlsl_spirv(self.hlsl[n], self.interface[n]["entry"]), names))

    def _pipeline(self, p: dict) -> tuple:
        from neuralao.runtime.wgsl_runner import _pipeline, hlsl_bindings, hlsl_spirv, weights_range

        p = dict(p, hlsl=self.interface[p["name"]])

        def resource(r: dict):
            if "texture" in r:
                return self.textures[r["texture"]][1]
            if "weights" in r:
                key = (r["weights"]["offset"], r["weights"]["bytes"])
                if key not in self._weights:
                    self._weights[key] = weights_range(self.r.program.weights, r["weights"])
                return self._weights[key]
            if "uniform_block" in r:
                return {"buffer": self.ubo, "offset": 0, "size": UNIFORM_BLOCK_BYTES}
            if r["name"] != "u_flip_y":
                raise NeuralaoError(f"pass {p['name']}: the frame sets no uniform {r['name']!r}")
            return {"buffer": self.flip, "offset": 0, "size": 16}

        layout, group = hlsl_bindings(p, resource)
        entry = p["hlsl"]["entry"]
        spirv = hlsl_spirv(self.hlsl[p["name"]], entry)
        bgl, pipeline = _pipeline(spirv, json.dumps(layout), "passthrough", entry)
        return bgl, pipeline, group


@functools.cache
def _cross_hlsl(source: str, name: str) -> str:
    """The HLSL SPIRV-Cross writes of GLSL 4.30 pass ``source`` (entry point ``name``), cached."""
    from neuralao.export.glsl import cross_compile

    return cross_compile(source, name)["hlsl"]
