"""Headless executor for the generated GLSL (Mesa llvmpipe through :mod:`neuralao.runtime.gl`, or any GL
4.3+).

Everything here is driven by what an engine would read: shader sources, uniform-block / weight
files and the manifest. Passing an export folder instead of an in-memory object runs exactly the
files on disk, so the runner doubles as the check that an export is self-sufficient.

    run_mlp_fragment(shader_or_dir, normal_obj, mask, fp16=False, dialect=None) -> (H, W) f32
    run_vector_fragment(shader_or_dir, textures, fp16=False, dialect=None) -> (H, W) f32
    time_vector_fragment(shader_or_dir, height, width, repeats=30, fp16=False, dialect=None) -> s/frame
    time_mlp_fragment(shader_or_dir, height, width, repeats=30, fp16=False, dialect=None) -> s/frame
    time_vertex_colour(scene, camera, repeats=30, ao=None) -> s/frame
    run_compute(program_or_dir, x, flip_y=False, scalars=None, aliasing=False) -> (1, C, H, W) f32
                                                                            (first graph output)
    run_compute_all(program_or_dir, x, flip_y=False, scalars=None, aliasing=False)
        -> {onnx output name: (1, C, H, W) f32}
    time_compute(program_or_dir, height, width, repeats=5, scalars=None) -> s/frame
    scalar_inputs(program_or_dir) -> [ONNX names of the scalar graph inputs (uniforms)]
    texture_sizes(manifest, height, width) -> {texture id: (w, h, layers, bytes)}   (checks the size first)

``scalars`` gives each scalar graph input of a compute program (manifest ``uniforms``: e.g. the AO
radius of a (1, 1, 1, 1) input) by its ONNX name: a float or any one-element array. ``aliasing`` runs
the passes with textures sharing memory as an aliasing plan says (True: the program's own,
:func:`neuralao.export.glsl.memory_schedule`; or a list of slots, each a list of texture ids): the
check that the plan never lets a pass overwrite a texture that is still to be read.

Timings are medians of per-frame wall times, each frame closed by ``glFinish``.
"""

from __future__ import annotations

import ctypes
import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from neuralao.export.glsl import (
    DIALECTS,
    MAX_TEXTURE_SIZE,
    ComputeProgram,
    MLPShader,
    load_compute_export,
    load_mlp_export,
    memory_schedule,
)
from neuralao.export.glsl.templates import fill
from neuralao.runtime import gl
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.gl import GL

log = logging.getLogger(__name__)

_PROGRAMS: dict[tuple[tuple[str, str], ...], int] = {}


def _program(**sources: str) -> int:
    """Compiled program for these sources, cached for the life of the process-wide context."""
    key = tuple(sorted(sources.items()))
    if key not in _PROGRAMS:
        _PROGRAMS[key] = gl.compile_program(**sources)
    return _PROGRAMS[key]


# --------------------------------------------------------------------------- fragment MLP


def _mlp(shader_or_dir: MLPShader | str | Path, dialect: str | None) -> tuple[MLPShader, str, str]:
    shader = shader_or_dir if isinstance(shader_or_dir, MLPShader) else load_mlp_export(shader_or_dir)
    name = dialect or shader.dialect
    if name not in shader.sources:
        raise NeuralaoError(f"no {name!r} variant in this shader (have {sorted(shader.sources)})")
    vert, frag = shader.sources[name]
    return shader, vert, frag


def texture_names(shader: MLPShader) -> list[str]:
    """The input textures of a fragment pass in unit order (manifest ``passes[0].inputs``)."""
    return [t["texture"] for t in shader.manifest["passes"][0]["inputs"]]


class _MLPPass:
    """Input textures, output texture + FBO, uniform buffers and the program of one fragment draw."""

    def __init__(self, shader: MLPShader, vert: str, frag: str, height: int, width: int, fp16: bool):
        ctx = gl.context()
        self.vao = ctx.empty_vao
        self.h, self.w = int(height), int(width)
        self.internal = GL.GL_RGBA16F if fp16 else GL.GL_RGBA32F
        self.prog = _program(vertex=vert, fragment=frag)
        self.names = texture_names(shader)
        self.inputs = [gl.create_texture(self.w, self.h, self.internal) for _ in self.names]
        self.out = gl.create_texture(self.w, self.h, self.internal)
        self.fbo = gl.create_framebuffer([self.out], self.w, self.h, depth=False)
        GL.glUseProgram(self.prog)
        for inp in shader.manifest["passes"][0]["inputs"]:  # the sampler's name is the manifest's
            loc = GL.glGetUniformLocation(self.prog, inp["sampler"])
            if loc >= 0:
                GL.glUniform1i(loc, int(inp["unit"]))
        self.ubos = []
        for name, binding, data in shader.uniform_blocks:
            index = GL.glGetUniformBlockIndex(self.prog, name)
            if index == GL.GL_INVALID_INDEX:
                continue  # optimised out (unused)
            GL.glUniformBlockBinding(self.prog, index, binding)
            buf = gl.create_buffer(np.ascontiguousarray(data, np.float32), target=GL.GL_UNIFORM_BUFFER)
            self.ubos.append((binding, buf))

    def upload_all(self, textures: dict[str, np.ndarray]) -> None:
        for name, tex in zip(self.names, self.inputs, strict=True):
            gl.upload_texture(tex, np.ascontiguousarray(textures[name], np.float32), self.internal)

    def draw(self) -> None:
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self.fbo)
        GL.glViewport(0, 0, self.w, self.h)
        GL.glDisable(GL.GL_DEPTH_TEST)
        GL.glDisable(GL.GL_BLEND)
        GL.glUseProgram(self.prog)
        for unit, tex in enumerate(self.inputs):
            GL.glActiveTexture(GL.GL_TEXTURE0 + unit)
            GL.glBindTexture(GL.GL_TEXTURE_2D, tex)
        GL.glActiveTexture(GL.GL_TEXTURE0)
        for binding, buf in self.ubos:
            GL.glBindBufferBase(GL.GL_UNIFORM_BUFFER, binding, buf)
        GL.glBindVertexArray(self.vao)
        GL.glDrawArrays(GL.GL_TRIANGLES, 0, 3)

    def read(self) -> np.ndarray:
        return gl.read_texture(self.out, self.w, self.h, self.internal)

    def release(self) -> None:
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        GL.glDeleteFramebuffers(1, [self.fbo])
        GL.glDeleteTextures(len(self.inputs) + 1, [*self.inputs, self.out])
        if self.ubos:
            GL.glDeleteBuffers(len(self.ubos), [b for _, b in self.ubos])


def run_mlp_fragment(
    shader: MLPShader | str | Path,
    normal_obj: np.ndarray,
    mask: np.ndarray,
    fp16: bool = False,
    dialect: str | None = None,
) -> np.ndarray:
    """Render the MLP pass over a G-buffer and read the result back.

    normal_obj : (H, W, 3) float32 object-space normals (fed as stored); mask : (H, W) bool.
    fp16 : store the G-buffer and the target as RGBA16F (arithmetic stays fp32).
    dialect : which variant to run ("glsl330" | "es300" | "glsl430"; default: the shader's own).
    Returns (H, W) float32 when the network has one output, else (H, W, m); background = 1.
    """
    normal_obj = np.asarray(normal_obj, dtype=np.float32)
    mask = np.asarray(mask, dtype=bool)
    if normal_obj.ndim != 3 or normal_obj.shape[2] != 3 or mask.shape != normal_obj.shape[:2]:
        raise NeuralaoError(
            f"expected normal_obj (H, W, 3) and mask (H, W), got {normal_obj.shape}, {mask.shape}"
        )
    g = np.concatenate([normal_obj, mask.astype(np.float32)[..., None]], axis=-1)
    return run_vector_fragment(shader, {"gbuffer": g}, fp16=fp16, dialect=dialect)


def time_mlp_fragment(
    shader: MLPShader | str | Path,
    height: int,
    width: int,
    repeats: int = 30,
    warmup: int = 3,
    fp16: bool = False,
    dialect: str | None = None,
) -> float:
    """Median seconds per full-screen MLP pass at width x height (random unit normals, all foreground)."""
    rng = np.random.default_rng(0)
    n = rng.normal(size=(height, width, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    g = np.concatenate([n, np.ones((height, width, 1), np.float32)], axis=-1)
    return time_vector_fragment(
        shader, height, width, repeats, warmup, fp16, dialect, textures={"gbuffer": g}
    )


def run_vector_fragment(
    shader: MLPShader | str | Path,
    textures: dict[str, np.ndarray],
    fp16: bool = False,
    dialect: str | None = None,
) -> np.ndarray:
    """Render a generated fragment pass over its named input textures and read the result back.

    textures : texture name -> (H, W, 4) float32, the names of the manifest's pass inputs; the first
    texture's w channel is the mask (>= 0.5 foreground). Returns (H, W) float32 when the network has
    one output, else (H, W, m); background = 1.
    """
    sh, vert, frag = _mlp(shader, dialect)
    names = texture_names(sh)
    missing = [n for n in names if n not in textures]
    if missing:
        raise NeuralaoError(f"textures {missing} not given (the pass reads {names})")
    shapes = {np.shape(textures[n]) for n in names}
    if len(shapes) != 1 or len(next(iter(shapes))) != 3 or next(iter(shapes))[2] != 4:
        raise NeuralaoError(f"input textures must all be (H, W, 4), got {sorted(shapes)}")
    h, w, _ = next(iter(shapes))
    m = sh.output_width
    if h * w == 0:
        return np.ones((h, w) if m == 1 else (h, w, m), np.float32)
    p = _MLPPass(sh, vert, frag, h, w, fp16)
    try:
        p.upload_all(textures)
        p.draw()
        out = p.read()
    finally:
        p.release()
    return out[..., 0].copy() if m == 1 else out[..., :m].copy()


def time_vector_fragment(
    shader: MLPShader | str | Path,
    height: int,
    width: int,
    repeats: int = 30,
    warmup: int = 3,
    fp16: bool = False,
    dialect: str | None = None,
    textures: dict[str, np.ndarray] | None = None,
) -> float:
    """Median seconds per full-screen pass at width x height: the given textures, or random inputs in
    [-1, 1] with every pixel foreground."""
    sh, vert, frag = _mlp(shader, dialect)
    if textures is None:
        rng = np.random.default_rng(0)
        textures = {}
        for name in texture_names(sh):
            t = rng.uniform(-1, 1, size=(height, width, 4)).astype(np.float32)
            t[..., 3] = 1.0
            textures[name] = t
    p = _MLPPass(sh, vert, frag, height, width, fp16)
    try:
        p.upload_all(textures)
        return gl.median_frame_seconds(p.draw, repeats, warmup)
    finally:
        p.release()


def time_vertex_colour(
    scene, camera, repeats: int = 30, warmup: int = 3, ao: np.ndarray | None = None
) -> float:
    """Median seconds per frame of the plain baked-AO draw: the mesh with one float per vertex as its
    colour, depth-tested, into an RGBA8 target of the camera's size (the engine's cheapest AO).

    scene : neuralao.pipeline.geometry.scene.Scene; camera : neuralao.pipeline.geometry.camera.Camera; ao :
    (n_vertices,) float32 or None (then a deterministic pattern; the cost does not depend on the values).
    """
    ctx = gl.context()
    d = DIALECTS["glsl330"]
    prog = _program(
        vertex=fill("vertex_colour_vert", header=d.header()),
        fragment=fill("vertex_colour_frag", header=d.header()),
    )
    v = np.ascontiguousarray(scene.vertices, dtype=np.float32)
    f = np.ascontiguousarray(scene.faces, dtype=np.uint32)
    a = np.linspace(0.2, 1.0, len(v), dtype=np.float32) if ao is None else np.asarray(ao, np.float32)
    if a.shape != (len(v),):
        raise NeuralaoError(f"ao must have one value per vertex ({len(v)}), got {a.shape}")
    w, h = camera.width, camera.height
    colour = gl.create_texture(w, h, GL.GL_RGBA8)
    fbo = gl.create_framebuffer([colour], w, h, depth=True)
    vao = GL.glGenVertexArrays(1)
    GL.glBindVertexArray(vao)
    bufs = []
    for loc, arr, comps in ((0, v, 3), (1, a, 1)):
        buf = gl.create_buffer(arr, target=GL.GL_ARRAY_BUFFER)
        GL.glVertexAttribPointer(loc, comps, GL.GL_FLOAT, GL.GL_FALSE, 0, None)
        GL.glEnableVertexAttribArray(loc)
        bufs.append(buf)
    ebo = gl.create_buffer(f, target=GL.GL_ELEMENT_ARRAY_BUFFER)
    bufs.append(ebo)
    mvp = (camera.projection @ camera.view).astype(np.float32)
    GL.glUseProgram(prog)
    GL.glUniformMatrix4fv(GL.glGetUniformLocation(prog, "u_mvp"), 1, GL.GL_TRUE, mvp)
    count = int(f.size)

    def frame() -> None:
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fbo)
        GL.glViewport(0, 0, w, h)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glClearColor(1.0, 1.0, 1.0, 1.0)
        GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
        GL.glUseProgram(prog)
        GL.glBindVertexArray(vao)
        GL.glDrawElements(GL.GL_TRIANGLES, count, GL.GL_UNSIGNED_INT, None)

    try:
        return gl.median_frame_seconds(frame, repeats, warmup)
    finally:
        GL.glDisable(GL.GL_DEPTH_TEST)
        GL.glBindVertexArray(ctx.empty_vao)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        GL.glDeleteVertexArrays(1, [vao])
        GL.glDeleteBuffers(len(bufs), bufs)
        GL.glDeleteFramebuffers(1, [fbo])
        GL.glDeleteTextures(1, [colour])


# --------------------------------------------------------------------------- compute passes

_IMAGE_FORMATS = {"RGBA32F": GL.GL_RGBA32F, "RGBA16F": GL.GL_RGBA16F}


def _size(dim: dict, sizes: dict[str, int]) -> int:
    v = sizes[dim["of"]] * dim["num"]
    if v % dim["den"]:
        raise NeuralaoError(
            f"texture size {dim['formula']} is fractional for {dim['of']} = {sizes[dim['of']]}"
        )
    return v // dim["den"] + dim["offset"]


def size_multiples(manifest: dict) -> tuple[int, int]:
    """(height, width) multiples a compute program's input size must be: textures sized from the unpadded
    H and W (the cropped outputs, e.g. ``W*1/8``) must come out whole; padded sizes always do."""
    out = {"H": 1, "W": 1}
    for t in manifest["textures"].values():
        for dim in (t["height"], t["width"]):
            if dim["of"] in out:
                need = dim["den"] // math.gcd(dim["num"], dim["den"])
                out[dim["of"]] = math.lcm(out[dim["of"]], need)
    return out["H"], out["W"]


def texture_sizes(
    manifest: dict, height: int, width: int, max_size: int = MAX_TEXTURE_SIZE, max_bytes: int | None = None
) -> dict:
    """{texture id: (width, height, layers, bytes)} of a compute program at an input of width x height,
    checked before anything is allocated: the program's fixed size if it has one, at least the pad
    multiple, whole texture sizes (:func:`size_multiples`), all textures together within ``max_bytes``
    (when given), each within 1..max_size. Raises NeuralaoError (one line) otherwise."""
    multiple = int(manifest["pad"]["multiple"])
    static = manifest.get("static_input_size")
    if static is not None and [height, width] != list(static):
        raise NeuralaoError(
            f"this program was generated for a fixed {static[1]}x{static[0]} input, got {width}x{height}"
        )
    if height < multiple or width < multiple:
        raise NeuralaoError(f"image {width}x{height} is smaller than the pad multiple {multiple}")
    mh, mw = size_multiples(manifest)
    if height % mh or width % mw:
        raise NeuralaoError(
            f"image {width}x{height}: the width must be a multiple of {mw} and the height of {mh} "
            "(output textures are sized from them by the program's strides)"
        )
    hp, wp = math.ceil(height / multiple) * multiple, math.ceil(width / multiple) * multiple
    sizes = {"H": height, "W": width, "Hp": hp, "Wp": wp}
    out = {}
    for ident, t in manifest["textures"].items():
        tw, th = _size(t["width"], sizes), _size(t["height"], sizes)
        texel = 16 if t["format"] == "RGBA32F" else 8
        out[ident] = (tw, th, int(t["layers"]), tw * th * int(t["layers"]) * texel)
    total = sum(t[3] for t in out.values())
    if max_bytes is not None and total > max_bytes:
        raise NeuralaoError(
            f"a {width}x{height} image needs {total / (1 << 30):.3g} GiB of textures, over the "
            f"bound of {max_bytes / (1 << 30):.3g} GiB: choose a smaller size"
        )
    for ident, (tw, th, _, _) in out.items():
        if not (1 <= tw <= max_size and 1 <= th <= max_size):
            raise NeuralaoError(
                f"texture {ident} would be {tw}x{th} for a {width}x{height} image, outside 1..{max_size}"
            )
    return out


def _array_texture(width: int, height: int, layers: int, internal: int) -> int:
    tex = GL.glGenTextures(1)
    GL.glBindTexture(GL.GL_TEXTURE_2D_ARRAY, tex)
    GL.glTexStorage3D(GL.GL_TEXTURE_2D_ARRAY, 1, internal, width, height, layers)
    for p, v in ((GL.GL_TEXTURE_MIN_FILTER, GL.GL_NEAREST), (GL.GL_TEXTURE_MAG_FILTER, GL.GL_NEAREST)):
        GL.glTexParameteri(GL.GL_TEXTURE_2D_ARRAY, p, v)
    return tex


def scalar_values(manifest: dict, scalars: dict | None) -> dict[str, float]:
    """{ONNX input name: float32 value} for every uniform of a compute manifest, from ``scalars``.

    A missing name, or a value of more than one element, is a one-line NeuralaoError; names the
    program does not take are ignored (one dict serves exports with and without, e.g., a radius input)."""
    names = [u["onnx_input"] for u in manifest.get("uniforms", [])]
    given = dict(scalars or {})
    missing = [n for n in names if n not in given]
    if missing:
        raise NeuralaoError(f"scalar input {missing[0]!r} not given (pass scalars={{{missing[0]!r}: value}})")
    out = {}
    for n in names:
        v = np.asarray(given[n], dtype=np.float32)
        if v.size != 1 or not np.isfinite(v).all():
            raise NeuralaoError(f"scalar input {n!r} must be one finite value, got shape {list(v.shape)}")
        out[n] = float(v.reshape(()))
    return out


Aliasing = bool | Sequence[Sequence[str]]


class _ComputeRun:
    """Textures sized for one input resolution, compiled passes and the parameter buffer.

    scalars : {ONNX name: value} of the scalar inputs (uniforms); settable later by :meth:`set_scalars`,
    needed before :meth:`dispatch`. aliasing : False (a texture each), True (the program's aliasing
    plan) or slots (lists of texture ids; ids of other textures are ignored).

    Aliased, the textures of one slot with the same format and size are one GL texture with the most
    layers of them (the passes touch only their own layers). GL cannot place textures of different
    sizes in one memory, so whenever a texture's lifetime begins (before the pass that first writes
    it, or the upload of the input) every GL texture of its slot is filled with NaN: what that first
    write would do to the other members' data in shared memory, and more. A plan that lets two members
    live at once then changes the output."""

    def __init__(
        self,
        program: ComputeProgram,
        height: int,
        width: int,
        scalars: dict | None = None,
        aliasing: Aliasing = False,
    ):
        gl.context()
        m = program.manifest
        self.manifest = m
        self.scalars: dict[str, float] | None = None
        if scalars is not None or not m.get("uniforms"):
            self.set_scalars(scalars)
        sizes = texture_sizes(m, height, width, int(GL.glGetIntegerv(GL.GL_MAX_TEXTURE_SIZE)))
        self.textures: dict[str, tuple[int, int, int, int, int]] = {}  # id -> (tex, w, h, layers, internal)
        self.allocated: dict[int, int] = {}  # GL texture -> layers allocated
        # pass index (None: the input's upload) -> the GL textures of each slot a lifetime begins in
        self.acquire: dict[int | None, list[list[int]]] = {}
        schedule = memory_schedule(m) if aliasing is not False else None
        slots = [] if schedule is None else schedule.slots if aliasing is True else aliasing
        slots = [[t for t in slot if t in m["textures"]] for slot in slots]  # the network's textures
        slot_of = {ident: k for k, slot in enumerate(slots) for ident in slot}
        keys = {  # textures of one key share a GL texture: one slot, format and size
            ident: (slot_of.get(ident, ident), m["textures"][ident]["format"], tw, th)
            for ident, (tw, th, _, _) in sizes.items()
        }
        shared: dict[tuple, int] = {}
        for key in dict.fromkeys(keys.values()):
            layers = max(sizes[ident][2] for ident, k in keys.items() if k == key)
            shared[key] = _array_texture(key[2], key[3], layers, _IMAGE_FORMATS[key[1]])
            self.allocated[shared[key]] = layers
        for ident, (tw, th, layers, _) in sizes.items():
            self.textures[ident] = (shared[keys[ident]], tw, th, layers, _IMAGE_FORMATS[keys[ident][1]])
        if schedule is not None:  # as each texture's lifetime begins, its slot's GL textures are poisoned
            for ident, k in slot_of.items():
                step = schedule.steps[schedule.textures[ident].first]
                at = None if ident == m["input"]["texture"] else step.pass_index
                members = sorted({shared[key] for key in shared if key[0] == k})
                self.acquire.setdefault(at, []).append(members)
        self.ssbo = None
        if program.weights:
            align = int(GL.glGetIntegerv(GL.GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT))
            if int(m["weights"]["range_alignment"]) % align:
                raise NeuralaoError(
                    f"parameter ranges aligned to {m['weights']['range_alignment']}, GL needs {align}"
                )
            self.ssbo = gl.create_buffer(np.frombuffer(program.weights, dtype=np.uint8))
        self.passes = []
        for p in m["passes"]:
            prog = _program(compute=program.sources[p["shader"]])
            tex, tw, th, layers, internal = self.textures[p["output"]["texture"]]
            lx, ly, _ = p["local_size"]
            bx, by, bl = p.get("block", [1, 1, 1])  # texels x, y and layers per invocation
            groups = (-(-tw // (lx * bx)), -(-th // (ly * by)), layers // bl)
            self.passes.append((p, prog, groups))

    def _poison(self, at: int | None) -> None:
        nan = np.full(4, np.nan, np.float32)
        for slot in self.acquire.get(at, []):
            for tex in slot:
                GL.glClearTexImage(tex, 0, GL.GL_RGBA, GL.GL_FLOAT, nan)

    def upload(self, x: np.ndarray) -> None:
        self._poison(None)
        ident = self.manifest["input"]["texture"]
        tex, w, h, layers, _ = self.textures[ident]
        c = x.shape[1]
        data = np.zeros((layers * 4, h, w), np.float32)
        data[:c] = x[0]
        data = np.ascontiguousarray(data.reshape(layers, 4, h, w).transpose(0, 2, 3, 1))
        GL.glPixelStorei(GL.GL_UNPACK_ALIGNMENT, 1)
        GL.glBindTexture(GL.GL_TEXTURE_2D_ARRAY, tex)
        GL.glTexSubImage3D(GL.GL_TEXTURE_2D_ARRAY, 0, 0, 0, 0, w, h, layers, GL.GL_RGBA, GL.GL_FLOAT, data)

    def set_scalars(self, scalars: dict | None) -> None:
        self.scalars = scalar_values(self.manifest, scalars)

    def dispatch(self, flip_y: bool = False) -> None:
        if self.scalars is None:  # names the first missing input
            self.set_scalars(None)
        barrier = GL.GL_TEXTURE_FETCH_BARRIER_BIT | GL.GL_SHADER_IMAGE_ACCESS_BARRIER_BIT
        for k, (p, prog, groups) in enumerate(self.passes):
            self._poison(k)
            GL.glUseProgram(prog)
            for inp in p["inputs"]:
                GL.glActiveTexture(GL.GL_TEXTURE0 + inp["binding"])
                GL.glBindTexture(GL.GL_TEXTURE_2D_ARRAY, self.textures[inp["texture"]][0])
            tex, _, _, _, internal = self.textures[p["output"]["texture"]]
            GL.glBindImageTexture(p["output"]["binding"], tex, 0, GL.GL_TRUE, 0, GL.GL_WRITE_ONLY, internal)
            if "params" in p:
                prm = p["params"]
                GL.glBindBufferRange(
                    GL.GL_SHADER_STORAGE_BUFFER, prm["binding"], self.ssbo, prm["offset"], prm["bytes"]
                )
            if p["kind"] == "uniform":
                for u in p["uniforms"].values():
                    GL.glUniform1f(u["location"], self.scalars[u["onnx_input"]])
            elif "uniforms" in p:
                GL.glUniform1i(p["uniforms"]["u_flip_y"]["location"], int(flip_y))
            GL.glDispatchCompute(*groups)
            GL.glMemoryBarrier(barrier)
        GL.glActiveTexture(GL.GL_TEXTURE0)

    def read(self, ident: str, channels: int) -> np.ndarray:
        tex, w, h, layers, _ = self.textures[ident]
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        GL.glBindTexture(GL.GL_TEXTURE_2D_ARRAY, tex)
        buf = np.empty((self.allocated[tex], h, w, 4), np.float32)
        GL.glGetTexImage(GL.GL_TEXTURE_2D_ARRAY, 0, GL.GL_RGBA, GL.GL_FLOAT, buf)
        buf = buf[:layers]
        return np.ascontiguousarray(buf.transpose(0, 3, 1, 2).reshape(layers * 4, h, w)[None, :channels])

    def release(self) -> None:
        GL.glDeleteTextures(len(self.allocated), list(self.allocated))
        if self.ssbo is not None:
            GL.glDeleteBuffers(1, [self.ssbo])


def _compute_program(program_or_dir: ComputeProgram | str | Path) -> ComputeProgram:
    return (
        program_or_dir if isinstance(program_or_dir, ComputeProgram) else load_compute_export(program_or_dir)
    )


def scalar_inputs(program_or_dir: ComputeProgram | str | Path) -> list[str]:
    """ONNX names of a compute program's scalar graph inputs (its uniforms), in graph order."""
    return [u["onnx_input"] for u in _compute_program(program_or_dir).manifest.get("uniforms", [])]


def compute_input(manifest: dict, x: np.ndarray) -> np.ndarray:
    """x as float32 if it is (1, C, H, W) with the C of a compute manifest's input, else a NeuralaoError.

    Shared by this GL runner and runtime/wgsl_runner.py: both take the same manifest."""
    x = np.asarray(x, dtype=np.float32)
    want_c = manifest["input"]["channels"]
    if x.ndim != 4 or x.shape[0] != 1 or x.shape[1] != want_c:
        raise NeuralaoError(f"expected input (1, {want_c}, H, W), got {x.shape}")
    return x


def compute_outputs(manifest: dict, read: Callable[[str, int], np.ndarray]) -> dict[str, np.ndarray]:
    """{ONNX output name: array} of a compute manifest's outputs, each from ``read(texture, channels)``.

    An image output stays (1, C_out, H, W) float32; one that is not an image ((1, 1000) logits after a
    Gemm) is reshaped to the shape the manifest gives it."""
    out = {o["onnx_name"]: read(o["texture"], o["channels"]) for o in manifest["outputs"]}
    return {
        o["onnx_name"]: out[o["onnx_name"]].reshape(o["shape"]) if "shape" in o else out[o["onnx_name"]]
        for o in manifest["outputs"]
    }


def run_compute_all(
    program_or_dir: ComputeProgram | str | Path,
    x: np.ndarray,
    flip_y: bool = False,
    scalars: dict[str, float] | None = None,
    aliasing: Aliasing = False,
) -> dict:
    """Run every pass on x : (1, C, H, W) float32; returns {onnx output name: (1, C_out, H, W) float32}.

    flip_y : the input/output textures are bottom-up GL images (here: x is given bottom row first).
    scalars : {ONNX input name: float} for each scalar graph input (manifest ``uniforms``).
    aliasing : textures share memory per the program's aliasing plan (True) or the slots given
    (lists of texture ids), see :class:`_ComputeRun`; False: a texture each.
    """
    prog = _compute_program(program_or_dir)
    x = compute_input(prog.manifest, x)
    values = scalar_values(prog.manifest, scalars)  # before any GL object exists
    run = _ComputeRun(prog, x.shape[2], x.shape[3], values, aliasing)
    try:
        run.upload(x)
        run.dispatch(flip_y)
        return compute_outputs(prog.manifest, run.read)
    finally:
        run.release()


def run_compute(
    program_or_dir: ComputeProgram | str | Path,
    x: np.ndarray,
    flip_y: bool = False,
    scalars: dict[str, float] | None = None,
    aliasing: Aliasing = False,
) -> np.ndarray:
    """The first graph output of :func:`run_compute_all`: (1, C_out, H, W) float32 (the U-Net's ao)."""
    prog = _compute_program(program_or_dir)
    return run_compute_all(prog, x, flip_y, scalars, aliasing)[prog.manifest["outputs"][0]["onnx_name"]]


def time_compute(
    program_or_dir: ComputeProgram | str | Path,
    height: int,
    width: int,
    repeats: int = 5,
    warmup: int = 1,
    scalars: dict[str, float] | None = None,
) -> float:
    """Median seconds for all passes (pad, network, crop) at width x height, random input; scalar
    inputs from ``scalars``, 1.0 where not given (the cost does not depend on them)."""
    prog = _compute_program(program_or_dir)
    c = prog.manifest["input"]["channels"]
    values = {n: 1.0 for n in scalar_inputs(prog)} | dict(scalars or {})
    run = _ComputeRun(prog, height, width, values)
    try:
        run.upload(np.random.default_rng(0).normal(size=(1, c, height, width)).astype(np.float32))
        return gl.median_frame_seconds(run.dispatch, repeats, warmup)
    finally:
        run.release()


# --------------------------------------------------------------------------- vertex functions


def run_vertex_feedback(
    vertex: str,
    fragment: str,
    attributes: list[np.ndarray],
    uniforms_vec4: dict[str, np.ndarray] | None = None,
    varying: str = "v_ao",
) -> np.ndarray:
    """Run a vertex shader once per point and read one float output back (transform feedback).

    attributes    : per location 0, 1, ...: (n, c) float32 arrays (c in 1..4)
    uniforms_vec4 : uniform ``vec4`` arrays by name: (count, 4) float32
    Returns (n,) float32, the vertex shader's ``varying`` for each point (rasterisation discarded).
    """
    ctx = gl.context()
    n = len(attributes[0]) if attributes else 0
    if n == 0 or any(len(a) != n for a in attributes):
        raise NeuralaoError("attributes must be non-empty arrays of equal length")
    prog = gl.compile_program(feedback=(varying,), vertex=vertex, fragment=fragment)
    vao = GL.glGenVertexArrays(1)
    GL.glBindVertexArray(vao)
    bufs = []
    try:
        for loc, arr in enumerate(attributes):
            a = np.ascontiguousarray(arr, dtype=np.float32).reshape(n, -1)
            bufs.append(gl.create_buffer(a, target=GL.GL_ARRAY_BUFFER))
            GL.glVertexAttribPointer(loc, a.shape[1], GL.GL_FLOAT, GL.GL_FALSE, 0, None)
            GL.glEnableVertexAttribArray(loc)
        out = gl.create_buffer(nbytes=4 * n, target=GL.GL_TRANSFORM_FEEDBACK_BUFFER)
        bufs.append(out)
        GL.glUseProgram(prog)
        for name, value in (uniforms_vec4 or {}).items():
            v = np.ascontiguousarray(value, dtype=np.float32).reshape(-1, 4)
            loc = GL.glGetUniformLocation(prog, name)
            if loc < 0:
                raise NeuralaoError(f"uniform {name!r} is not in the program")
            GL.glUniform4fv(loc, len(v), v)
        GL.glEnable(GL.GL_RASTERIZER_DISCARD)
        GL.glBindBufferBase(GL.GL_TRANSFORM_FEEDBACK_BUFFER, 0, out)
        GL.glBeginTransformFeedback(GL.GL_POINTS)
        GL.glDrawArrays(GL.GL_POINTS, 0, n)
        GL.glEndTransformFeedback()
        GL.glDisable(GL.GL_RASTERIZER_DISCARD)
        gl.finish()
        # Mapped read: glGetBufferSubData into a numpy array corrupted the heap for this target here.
        GL.glBindBuffer(GL.GL_TRANSFORM_FEEDBACK_BUFFER, out)
        ptr = GL.glMapBufferRange(GL.GL_TRANSFORM_FEEDBACK_BUFFER, 0, 4 * n, GL.GL_MAP_READ_BIT)
        try:
            return np.ctypeslib.as_array(ctypes.cast(ptr, ctypes.POINTER(ctypes.c_float)), shape=(n,)).copy()
        finally:
            GL.glUnmapBuffer(GL.GL_TRANSFORM_FEEDBACK_BUFFER)
    finally:
        GL.glBindBufferBase(GL.GL_TRANSFORM_FEEDBACK_BUFFER, 0, 0)
        GL.glBindVertexArray(ctx.empty_vao)
        GL.glDeleteVertexArrays(1, [vao])
        GL.glDeleteBuffers(len(bufs), bufs)
        GL.glDeleteProgram(prog)
