"""The compute target: NCHW image networks as GLSL 4.30 compute passes over 2-D array textures, the
parameters in one weights.bin. :class:`ImageOps` is the op table, ``_pack_conv`` the weight packing,
the ``_write_*`` functions the writer, :func:`generate_compute` the entry point.

One module of about 2,900 lines on purpose: the op table is one class (as a renderer's op table is in
tinygrad), and its ~90 handlers share the pass builders, views and epilogue fusion around them; split
by op family, each part would import the others' private helpers. Dialect text lives in templates.py,
storage and memory planning in memory.py, reading the graph in graph.py and views.py."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np
import onnx

from neuralao.export.glsl.activations import Act, clip_bounds
from neuralao.export.glsl.dialects import COMPUTE_DIALECTS, Dialect
from neuralao.export.glsl.graph import (
    FORMAT_VERSION,
    OnnxGraph,
    OpTable,
    _node_label,
    ceil4,
    glsl_float,
    read_graph,
    sha256_hex,
    shape_dims,
)
from neuralao.export.glsl.memory import FP32_KINDS, memory_section, texture_sizes
from neuralao.export.glsl.views import (
    Atom,
    Axes,
    axes_shape,
    coordinates,
    image_axes,
    is_image,
    per_channel,
    reduction,
    reshape,
    transpose,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.metadata import metadata_pad_multiple

# Portable GL 4.5 minimums: GL_MAX_TEXTURE_SIZE, GL_MAX_ARRAY_TEXTURE_LAYERS,
# GL_MAX_SHADER_STORAGE_BLOCK_SIZE.
MAX_TEXTURE_SIZE = 16384
MAX_ARRAY_LAYERS = 2048
MAX_PARAM_BYTES = 1 << 27
MAX_KERNEL = 15
# Dense conv passes: texels x, texels y and output layers per invocation (bench/bench_unet.py measures
# the choices); at most MAX_BLOCK_ACCUMULATORS vec4 accumulators per invocation.
CONV_BLOCK = (8, 4, 2)
MAX_BLOCK_ACCUMULATORS = 64


@dataclass(frozen=True)
class ComputePreset:
    """How the compute passes are shaped for the machine that runs them (``generate_compute(preset=)``,
    ``neuralao glsl --preset``). Every preset computes the same outputs (to float rounding)."""

    name: str
    # invocations per workgroup (x, y); z is 1, the grid's z runs over output layers / block layers
    local_size: tuple[int, int]
    # a dense conv invocation's output: texels x, texels y, output layers ((1, 1, 1): one texel, one layer)
    conv_block: tuple[int, int, int]
    # fold cheap passes into a neighbour: a two-image op into the conv producing one operand, the
    # output crop into the pass producing its input, the input's pad, 2x2 average pools and x2 linear
    # resizes into the convs reading them (CONV_READS; fewer dispatches, barriers and textures)
    fuse: bool
    # what the preset is for, in the manifest
    purpose: str


PRESETS: dict[str, ComputePreset] = {
    "gpu": ComputePreset(
        "gpu",
        (8, 8),
        (1, 1, 1),
        True,
        "GPUs: one output texel of one layer per invocation in 8x8 workgroups, so that the smallest conv "
        "pass of the shipped U-Nets (1/8 of the network's size, 8 output layers) still launches about "
        "15,000 threads at 1080p; cheap passes fused into their neighbours",
    ),
    "cpu": ComputePreset(
        "cpu",
        (8, 8),
        CONV_BLOCK,
        False,
        "CPU rasterisers (Mesa llvmpipe): 8x4 texels x 2 output layers per invocation, so each of a few "
        "hundred workgroups reuses every fetched texel and weight; no fusion",
    ),
}
# The frame whose per-pass workgroups and threads the manifest states ("occupancy").
OCCUPANCY_FRAME = (1920, 1080)
# Alignment of each pass's parameter range in weights.bin (>= any GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT).
PARAM_ALIGN = 256


@dataclass(frozen=True)
class Dim:
    """A spatial size: ``base * scale + offset`` where base is the padded input size (Hp or Wp).

    scale 0 means a static size. The lowering keeps ``base * scale`` an integer by requiring the
    input to be padded to a multiple of every scale's denominator (``pad_multiple``).
    """

    scale: Fraction
    offset: int

    def eval(self, base: int) -> int:
        v = base * self.scale + self.offset
        if v.denominator != 1:
            raise NeuralaoError(f"size {self.describe('n')} is fractional for n = {base}")
        return int(v)

    def describe(self, symbol: str) -> str:
        if self.scale == 0:
            return str(self.offset)
        s = symbol if self.scale == 1 else f"{symbol}*{self.scale.numerator}/{self.scale.denominator}"
        return s if self.offset == 0 else f"{s}{self.offset:+d}"

    def to_json(self, symbol: str) -> dict:
        return {
            "of": symbol,
            "num": self.scale.numerator,
            "den": self.scale.denominator,
            "offset": self.offset,
            "formula": self.describe(symbol),
        }


@dataclass
class Texture:
    """A tensor (1, channels, height, width) as a 2-D array texture, 4 channels per layer.

    base "padded": sizes relative to the padded input (Hp, Wp); "raw": to the input (H, W).
    """

    ident: str
    channels: int
    height: Dim
    width: Dim
    base: str = "padded"
    onnx_name: str = ""

    @property
    def layers(self) -> int:
        return ceil4(self.channels)


@dataclass
class ConcatValue:
    """A channel concatenation not yet materialised (a consuming Conv reads the parts directly)."""

    parts: list[Texture]
    texture: Texture | None = None  # set once materialised (one concat pass however many readers)

    @property
    def channels(self) -> int:
        return sum(p.channels for p in self.parts)


@dataclass
class View:
    """An image tensor read through Reshape / Transpose / Flatten (see :mod:`.views`): ``texture``
    holds the data, ``axes`` the atoms of each logical axis. Static sizes only."""

    texture: Texture
    axes: Axes

    @property
    def shape(self) -> list[int]:
        return axes_shape(self.axes)

    @property
    def channels(self) -> int:
        return self.texture.channels


@dataclass
class Epilogue:
    """Per-texel step after a pass's body, on ``r`` (the vec4 of output layer gid.z).

    form "act": ``act``; "affine": r * prm[arrays[0]] + prm[arrays[1]] (batch norm, arithmetic with
    per-channel constants); "prelu": slope prm[arrays[0]] where r < 0; "rdiv": prm[arrays[0]] / r;
    "guard": padding lanes set to 0 (after an activation that can make them non-finite); "binary": r
    op'd with a texel of another input (``side``), a two-image op fused into its operand's conv pass.
    """

    act: Act | None = None
    form: str = "act"
    arrays: tuple[str, ...] = ()  # param array names, in the order above
    # form "binary" (a two-image op fused into the conv producing one operand): (input index of the
    # other operand, its fetch: full | pixel | channel | scalar, the op, 0 if r is the op's A else 1)
    side: tuple = ()


@dataclass
class Pass:
    """One compute dispatch: reads ``inputs`` (sampler2DArray src0..), writes ``output`` (image dst)."""

    index: int
    # pad | crop | conv | conv_depthwise | conv_transpose | pool_avg | pool_max | global_pool_avg |
    # global_pool_max | resize_linear | resize_nearest | resize_filter | concat | elementwise | binary |
    # spatial_pad | uniform (a scalar graph input: writes uniform float fields["uniform"] to a 1x1
    # texture) | gather (a view materialised: DepthToSpace, channel shuffles) | reduce | moments (mean
    # and 1/std per group) | normalize | softmax | lrn | pool_lp | global_pool_lp
    kind: str
    ops: list[str]
    inputs: list[Texture]
    output: Texture
    fields: dict[str, Any] = field(default_factory=dict)
    params: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (n, 4) float32
    epilogue: list[Epilogue] = field(default_factory=list)
    nodes: list[str] = field(default_factory=list)
    folded_bn: bool = False

    @property
    def name(self) -> str:
        return f"p{self.index:02d}_{self.kind}"

    def param_offsets(self) -> dict[str, int]:
        out, off = {}, 0
        for name, arr in self.params.items():
            out[name] = off
            off += int(arr.shape[0])
        return out


# Single-element graph inputs beside the image (each one becomes a uniform float).
MAX_SCALAR_INPUTS = 64


def _is_scalar_input(vi: onnx.ValueInfoProto) -> bool:
    """A static shape of one element, rank 0 to 4: (), (1,), ..., (1, 1, 1, 1)."""
    dims = shape_dims(vi)
    return vi.type.tensor_type.HasField("shape") and len(dims) <= 4 and all(d == 1 for d in dims)


# An ONNX name that can be a GLSL identifier as it is (no "__": reserved in GLSL), at most 32 characters.
_SAFE_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9]*(_[A-Za-z0-9]+)*$")


def _uniform_name(onnx_name: str, index: int, used: set[str]) -> str:
    """``u_<name>`` for a plain identifier (what an engine programmer expects: u_radius), else the
    generated ``u_scalar<index>``: other ONNX names never reach shader source."""
    name = f"u_{onnx_name}" if _SAFE_NAME.match(onnx_name) and len(onnx_name) <= 32 else f"u_scalar{index}"
    base, n = name, 1
    while name in used:  # an input literally named scalar<k> beside a generated u_scalar<k>
        name, n = f"{base}_{n}", n + 1
    return name


def _split_inputs(graph: OnnxGraph) -> tuple[onnx.ValueInfoProto, list[onnx.ValueInfoProto]]:
    """(the image input, the scalar inputs in graph order). The image is the one input that is not a
    single-element scalar (the first input when every one is); anything else is refused, by name."""
    inputs = graph.inputs or [graph.input]
    if len(inputs) == 1:
        return inputs[0], []
    images = [vi for vi in inputs if not _is_scalar_input(vi)] or inputs[:1]
    image = images[0]
    if len(images) > 1:
        vi = images[1]
        raise NeuralaoError(
            f"graph input {vi.name!r} of shape {shape_dims(vi) or 'unknown'}: the image target takes one "
            f"image input ({image.name!r}) and single-element scalars ((1, 1, 1, 1), (1,) or ()) as uniforms"
        )
    return image, [vi for vi in inputs if vi is not image]


def _spatial_pairs(values: list[int] | None, default: int, what: str) -> tuple[int, int]:
    v = [default, default] if values is None else [int(x) for x in values]
    if len(v) != 2:
        raise ValueError(f"{what} must have 2 entries (2-D images), got {v}")
    return v[0], v[1]


def _same_total(n: int, kernel: int, stride: int, dilation: int) -> int:
    """Total auto_pad SAME padding so that the output has ceil(n / stride) samples. For a symbolic
    size ``base * scale + n`` the result is the same: base * scale is a multiple of the stride (the
    output's scale denominator enters the pad multiple), so only the offset ``n`` matters."""
    return max(0, (-(-n // stride) - 1) * stride + dilation * (kernel - 1) + 1 - n)


def _split_same(total: int, auto_pad: str) -> tuple[int, int]:
    """(begin, end) padding: SAME_UPPER puts the odd sample at the end, SAME_LOWER at the beginning."""
    begin = total // 2 if auto_pad == "SAME_UPPER" else total - total // 2
    return begin, total - begin


def _group_dense(w: np.ndarray, group: int) -> np.ndarray:
    """Grouped conv weight (M, C / group, kH, kW) as the equivalent dense (M, C, kH, kW), block diagonal."""
    m, cg = w.shape[:2]
    mg = m // group
    dense = np.zeros((m, cg * group) + w.shape[2:], w.dtype)
    for g in range(group):
        dense[g * mg : (g + 1) * mg, g * cg : (g + 1) * cg] = w[g * mg : (g + 1) * mg]
    return dense


def _constant_binary(op: str, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Arithmetic on two constants (exporters emit shape arithmetic): numpy; ONNX integer division
    truncates."""
    if op == "Div" and np.issubdtype(a.dtype, np.integer) and np.issubdtype(b.dtype, np.integer):
        return np.fix(a / b).astype(np.result_type(a, b))
    return {"Add": np.add, "Sub": np.subtract, "Mul": np.multiply, "Div": np.divide}[op](a, b)


CONV_KINDS = ("conv", "conv_depthwise", "conv_transpose")
# Ops the image target evaluates on constants only (exporters compute pads, sizes and scales with
# them: torch's F.pad and padding_mode="reflect" emit ConstantOfShape, Concat, Reshape, Slice,
# Transpose and Cast; F.interpolate(size=x.shape[2:]) emits Shape, Gather, Unsqueeze on a static size).
# Reshape, Transpose, Squeeze, Unsqueeze and Shape also take image tensors (a View); Expand, Tile and Range
# build weights from small constants (onnx's light models make every weight with ConstantOfShape).
FOLDED_OPS = (
    "ConstantOfShape",
    "Reshape",
    "Slice",
    "Transpose",
    "Cast",
    "Shape",
    "Gather",
    "Unsqueeze",
    "Squeeze",
    "Expand",
    "Tile",
    "Range",
)
# Largest constant a folded op may create (elements): as many float32 as weights.bin can hold, so a weight
# built inside the graph is as welcome as an initializer; a hostile shape (2^40 elements) is still refused.
MAX_FOLDED_ELEMENTS = MAX_PARAM_BYTES // 4
# Widest separable resize filter (taps per axis): antialiased cubic downscaling by 1/16.
MAX_FILTER_TAPS = 64


def _split_transpose(total: int, auto_pad: str) -> tuple[int, int]:
    """ConvTranspose (begin, end) padding (ONNX spec, as onnxruntime does it): SAME_UPPER puts the odd
    sample at the end; SAME_LOWER and an explicit output_shape without auto_pad at the beginning."""
    begin = total // 2 if auto_pad == "SAME_UPPER" else total - total // 2
    return begin, total - begin


class ImageOps(OpTable):
    """ONNX -> compute passes over (1, C, H, W) images (GLSL 4.3 compute, texture storage)."""

    OPS = (
        "Conv",
        "ConvTranspose",
        "BatchNormalization",
        "Relu",
        "LeakyRelu",
        "PRelu",
        "Sigmoid",
        "Tanh",
        "Clip",
        "Elu",
        "Softplus",
        "HardSigmoid",
        "HardSwish",
        "Sin",
        "Cos",
        "Add",
        "Sub",
        "Mul",
        "Div",
        "AveragePool",
        "MaxPool",
        "GlobalAveragePool",
        "GlobalMaxPool",
        "Resize",
        "Upsample",
        "Pad",
        "Concat",
        "Identity",
        "Constant",
        *FOLDED_OPS,
        "Erf",
        "Gelu",
        "Mish",
        "Sqrt",
        "Exp",
        "Log",
        "Abs",
        "Neg",
        "Reciprocal",
        "Sign",
        "Softsign",
        "Floor",
        "Ceil",
        "Pow",
        "Sum",
        "Mean",
        "Min",
        "Max",
        "Dropout",
        "DepthToSpace",
        "SpaceToDepth",
        "Flatten",
        "InstanceNormalization",
        "GroupNormalization",
        "LayerNormalization",
        "ReduceMean",
        "ReduceMax",
        "ReduceMin",
        "ReduceSum",
        "ReduceL1",
        "ReduceL2",
        "ReduceSumSquare",
        "ReduceProd",
        "ReduceLogSum",
        "Softmax",
        "LogSoftmax",
        "LRN",
        "LpPool",
        "GlobalLpPool",
        "Gemm",
        "MatMul",
    )
    target = "compute (image)"

    def __init__(self, graph: OnnxGraph, metadata_multiple: int | None):
        super().__init__(graph)
        self.passes: list[Pass] = []
        self.textures: list[Texture] = []
        self.producer: dict[str, Pass] = {}
        self.denominators: set[int] = {1}
        self.global_reads: list[str] = []  # global pools over a dynamic size (padding would enter them)
        self.param_count = 0
        self.image_input, scalars = _split_inputs(graph)
        dims = shape_dims(self.image_input)
        name = self.image_input.name
        if len(dims) != 4:
            raise NeuralaoError(
                f"image input {name!r} must have rank 4 (N, C, H, W), got shape {dims or 'unknown'}"
            )
        n, c, h, w = dims
        if isinstance(n, int) and n != 1:
            raise NeuralaoError(f"image input {name!r} has batch {n}; the compute target runs batch 1")
        if not isinstance(c, int) or c <= 0:
            raise NeuralaoError(f"image input {name!r} needs a static channel count, got {c!r}")
        if ceil4(c) > MAX_ARRAY_LAYERS:
            raise NeuralaoError(f"image input {name!r}: {c} channels exceed {4 * MAX_ARRAY_LAYERS}")
        self.static = isinstance(h, int) and isinstance(w, int)
        if not self.static and (isinstance(h, int) or isinstance(w, int)):
            raise NeuralaoError(
                f"image input {name!r}: H and W must be both static or both symbolic, got {h!r}, {w!r}"
            )
        if self.static:
            for v in (h, w):
                if v <= 0 or v > MAX_TEXTURE_SIZE:
                    raise NeuralaoError(f"image input {name!r}: size {v} outside 1..{MAX_TEXTURE_SIZE}")
            hd, wd = Dim(Fraction(0), h), Dim(Fraction(0), w)
        else:
            hd = wd = Dim(Fraction(1), 0)
        self.input_dims = (h, w)
        self.label = f"graph input {name!r}"
        self.metadata_multiple = metadata_multiple
        raw = self.new_texture(c, hd, wd, base="raw", onnx_name=name)
        padded = self.new_texture(c, hd, wd, onnx_name=name)
        # The pad pass is the only reader of the raw input: it zeroes the lanes past channel c of the
        # last layer, so whatever an engine leaves there (NaN included) never reaches a conv (a conv
        # that reads the input in its place zeroes them as it reads: conv_read_reflect_guard).
        guard = [Epilogue(form="guard")] if c % 4 else []
        self.add_pass(Pass(0, "pad", ["Pad"], [raw], padded, epilogue=guard))
        self.env[name] = padded
        self.input_texture, self.padded_texture = raw, padded
        # Scalar inputs: a 1x1 one-channel texture each, written from a uniform by its own pass, so
        # every op that broadcasts a 1x1 image (the binary ops' "scalar" fetch) takes them unchanged.
        self.uniforms: list[tuple[onnx.ValueInfoProto, Pass]] = []
        # texture ident -> declared ONNX rank of a scalar input (Shape folds rank 4 only)
        self.scalar_ranks: dict[str, int] = {}
        point = Dim(Fraction(0), 1)
        used: set[str] = set()
        for k, vi in enumerate(scalars):
            self.label = f"graph input {vi.name!r}"
            t = self.new_texture(1, point, point, onnx_name=vi.name)
            p = self.add_pass(Pass(0, "uniform", ["Uniform"], [], t))
            p.fields = {"uniform": _uniform_name(vi.name, k, used), "location": 0}
            used.add(p.fields["uniform"])
            self.uniforms.append((vi, p))
            self.scalar_ranks[t.ident] = len(shape_dims(vi))
            self.env[vi.name] = t

    # -- IR helpers
    def new_texture(
        self, channels: int, h: Dim, w: Dim, base: str = "padded", onnx_name: str = ""
    ) -> Texture:
        if ceil4(channels) > MAX_ARRAY_LAYERS:
            raise self.fail(f"{channels} channels exceed the texture-array limit {4 * MAX_ARRAY_LAYERS}")
        for d in (h, w):
            if d.scale == 0 and not 1 <= d.offset <= MAX_TEXTURE_SIZE:
                raise self.fail(f"output size {d.offset} outside 1..{MAX_TEXTURE_SIZE}")
            if d.scale != 0:
                self.denominators.add(d.scale.denominator)
                if d.scale > 64:
                    raise self.fail(f"output size {d.describe('n')} grows beyond 64x the input")
        t = Texture(f"t{len(self.textures)}", int(channels), h, w, base, onnx_name)
        self.textures.append(t)
        return t

    def add_pass(self, p: Pass) -> Pass:
        p.index = len(self.passes)
        self.passes.append(p)
        self.producer[p.output.ident] = p
        return p

    def image(self, value: Any, what: str) -> Texture:
        """A real texture for ``value`` (materialising a pending concatenation or a view)."""
        if isinstance(value, ConcatValue):
            return self.materialise(value)
        if isinstance(value, View):
            return self.materialise_view(value, what)
        if not isinstance(value, Texture):
            raise self.fail(f"input {what} must be an image tensor, not a constant")
        return value

    def materialise(self, value: ConcatValue) -> Texture:
        if value.texture is None:
            first = value.parts[0]
            value.texture = self.new_texture(value.channels, first.height, first.width)
            self.add_pass(Pass(0, "concat", ["Concat"], list(value.parts), value.texture, nodes=[self.label]))
        return value.texture

    def fusible_pass(self, index: int) -> Pass | None:
        assert self.node is not None
        value = self.env.get(self.node.input[index])
        p = self.producer.get(value.ident) if isinstance(value, Texture) else None
        if p is None or p.kind in ("pad", "crop") or not self.fusible(index):
            return None
        # fusible() counts readers still to come; one already lowered (a pass, or a Concat waiting to
        # be fused into its consumer) must keep seeing the unfused value.
        if any(t is value for q in self.passes if q is not p for t in q.inputs):
            return None
        if any(isinstance(v, ConcatValue) and any(t is value for t in v.parts) for v in self.env.values()):
            return None
        return p

    def output_dim(
        self,
        d: Dim,
        kernel: int,
        stride: int,
        dilation: int,
        pad_begin: int,
        pad_end: int,
        ceil_mode: int = 0,
    ) -> Dim:
        """floor (or ceil) of (n + pads - dilation (k - 1) - 1) / stride, + 1, kept symbolic (exact when
        stride divides Hp * scale, which the pad multiple guarantees). ceil_mode drops a last window
        that would start in the trailing padding (as onnxruntime and PyTorch do)."""
        c = pad_begin + pad_end - dilation * (kernel - 1) - 1
        q = -(-(d.offset + c) // stride) if ceil_mode else (d.offset + c) // stride
        if ceil_mode and q * stride >= d.offset + pad_begin:
            q -= 1  # the same test for a symbolic size: base * scale cancels on both sides
        if d.scale == 0:
            if q + 1 < 1:
                raise self.fail(f"window larger than the padded input ({d.offset})")
            return Dim(Fraction(0), q + 1)
        return Dim(d.scale / stride, q + 1)

    def _window(self, kernel_shape, strides, dilations, pads, auto_pad, dims: tuple[Dim, Dim]) -> tuple:
        kh, kw = _spatial_pairs(kernel_shape, 1, "kernel_shape")
        sy, sx = _spatial_pairs(strides, 1, "strides")
        dy, dx = _spatial_pairs(dilations, 1, "dilations")
        if min(kh, kw, sy, sx, dy, dx) < 1:
            raise self.fail("kernel_shape, strides and dilations must be positive")
        if max(kh, kw) > MAX_KERNEL:
            raise self.fail(f"kernel {kh}x{kw} exceeds {MAX_KERNEL}x{MAX_KERNEL}")
        if auto_pad in ("NOTSET", ""):
            p = [0, 0, 0, 0] if pads is None else [int(v) for v in pads]
            if len(p) != 4 or min(p) < 0:
                raise self.fail(f"pads must be 4 non-negative values, got {p}")
        elif auto_pad == "VALID":
            p = [0, 0, 0, 0]
        elif auto_pad in ("SAME_UPPER", "SAME_LOWER"):
            p = [0, 0, 0, 0]
            for i, (d, k, st, dl) in enumerate(zip(dims, (kh, kw), (sy, sx), (dy, dx), strict=True)):
                p[i], p[i + 2] = _split_same(_same_total(d.offset, k, st, dl), auto_pad)
        else:
            raise self.unsupported("auto_pad", auto_pad)
        return (kh, kw), (sy, sx), (dy, dx), p  # p: top, left, bottom, right

    def param_name(self, prefix: str) -> str:
        """A parameter array name unique in the program (epilogues of several nodes share a pass)."""
        self.param_count += 1
        return f"{prefix}{self.param_count}"

    def channel_const(self, value: Any, channels: int, what: str) -> np.ndarray:
        """(channels,) float64 of a constant that broadcasts per channel over (1, C, H, W)."""
        a = np.asarray(self.const(value, what), dtype=np.float64)
        shape = (1,) * (4 - a.ndim) + a.shape if a.ndim <= 4 else a.shape
        if len(shape) != 4 or shape[0] != 1 or shape[2:] != (1, 1) or shape[1] not in (1, channels):
            raise self.fail(
                f"constant {what} of shape {list(a.shape)} does not broadcast per channel over {channels} "
                "channels (scalar, (C, 1, 1) or (1, C, 1, 1) expected)"
            )
        out = np.broadcast_to(a.reshape(-1), (channels,)).copy()
        if not np.all(np.isfinite(out)):
            raise self.fail(f"constant {what} has non-finite values")
        return out

    def _elementwise(
        self, X: Any, epi: Epilogue, params: dict[str, np.ndarray], op: str, index: int | None = 0
    ) -> Texture:
        """Append ``epi`` to the pass producing X (input ``index`` of the node) or to a new elementwise pass
        (always when ``index`` is None: X is not one of the node's inputs as they stand)."""
        x = self.image(X, "X")
        p = self.fusible_pass(index) if isinstance(X, Texture) and index is not None else None
        if p is None:
            out = self.new_texture(x.channels, x.height, x.width)
            p = self.add_pass(Pass(0, "elementwise", [], [x], out))
        p.params.update(params)
        p.epilogue.append(epi)
        p.ops.append(op)
        p.nodes.append(self.label)
        return p.output

    def _activation(self, X: Any, act: Act) -> Texture:
        return self._elementwise(X, Epilogue(act=act), {}, act.op)

    def _conv_pass(
        self,
        kind: str,
        X: Any,
        parts: list[Texture],
        w: np.ndarray,
        bias: np.ndarray,
        window: tuple,
        h: Dim,
        wd: Dim,
    ) -> Texture:
        """A conv-like pass; w is the (M, C, kH, kW) dense equivalent ((C, 1, kH, kW) for depthwise)."""
        (kh, kw), (sy, sx), (dy, dx), p = window
        cout = w.shape[0]
        if bias.shape != (cout,):
            raise self.fail(f"B must have {cout} entries, got {bias.shape}")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(bias))):
            raise self.fail("weights contain non-finite values")
        out = self.new_texture(cout, h, wd)
        layer_offsets, off = [], 0
        for t in parts:
            if t.height != parts[0].height or t.width != parts[0].width:
                raise self.fail("concatenated inputs differ in size")
            layer_offsets.append(off)
            off += t.layers
        conv = Pass(0, kind, [self.node.op_type], parts, out, nodes=[self.label])
        conv.fields = {
            "kernel": (kh, kw),
            "strides": (sy, sx),
            "dilations": (dy, dx),
            "pads": p,
            "layer_offsets": layer_offsets,
            "in_layers": off,
        }
        conv.fields["weight64"], conv.fields["bias64"] = w, bias  # packed by _pack_conv (after BN folding)
        if isinstance(X, ConcatValue) and parts == X.parts:
            conv.ops.insert(0, "Concat")
        return self.add_pass(conv).output

    def _conv_inputs(self, X: Any, W: Any, B: Any) -> tuple[list[Texture], np.ndarray, np.ndarray | None]:
        parts = list(X.parts) if isinstance(X, ConcatValue) else [self.image(X, "X")]
        w = self.const(W, "W").astype(np.float64)
        if w.ndim != 4:
            raise self.fail(f"W must be 4-D (2-D images), got shape {list(w.shape)}")
        bias = None if B is None else self.const(B, "B").astype(np.float64).reshape(-1)
        return parts, w, bias

    # -- handlers
    def Conv(
        self,
        X,
        W,
        B=None,
        *,
        auto_pad="NOTSET",
        dilations=None,
        group=1,
        kernel_shape=None,
        pads=None,
        strides=None,
    ) -> Texture:
        parts, w, bias = self._conv_inputs(X, W, B)
        if kernel_shape is not None and list(kernel_shape) != list(w.shape[2:]):
            raise self.fail(f"kernel_shape {list(kernel_shape)} does not match W {list(w.shape)}")
        cin, cout = sum(t.channels for t in parts), w.shape[0]
        if group < 1 or cout % group or w.shape[1] * group != cin:
            raise self.fail(
                f"W of shape {list(w.shape)} with group={group} does not take {cin} input channels"
            )
        dims = (parts[0].height, parts[0].width)
        window = self._window(list(w.shape[2:]), strides, dilations, pads, auto_pad, dims)
        (kh, kw), (sy, sx), (dy, dx), p = window
        h = self.output_dim(dims[0], kh, sy, dy, p[0], p[2])
        wd = self.output_dim(dims[1], kw, sx, dx, p[1], p[3])
        bias = np.zeros(cout) if bias is None else bias
        if group > 1 and group == cin == cout:  # depthwise: one vec4 weight per tap, no channel mixing
            return self._conv_pass("conv_depthwise", X, [self.image(X, "X")], w, bias, window, h, wd)
        w = _group_dense(w, group) if group > 1 else w
        return self._conv_pass("conv", X, parts, w, bias, window, h, wd)

    def ConvTranspose(
        self,
        X,
        W,
        B=None,
        *,
        auto_pad="NOTSET",
        dilations=None,
        group=1,
        kernel_shape=None,
        output_padding=None,
        output_shape=None,
        pads=None,
        strides=None,
    ) -> Texture:
        parts, w, bias = self._conv_inputs(X, W, B)
        cin = sum(t.channels for t in parts)
        if group < 1 or w.shape[0] != cin or cin % group:
            raise self.fail(
                f"W of shape {list(w.shape)} with group={group} does not take {cin} input channels"
            )
        if kernel_shape is not None and list(kernel_shape) != list(w.shape[2:]):
            raise self.fail(f"kernel_shape {list(kernel_shape)} does not match W {list(w.shape)}")
        kh, kw = (int(v) for v in w.shape[2:])
        sy, sx = _spatial_pairs(strides, 1, "strides")
        dy, dx = _spatial_pairs(dilations, 1, "dilations")
        adj = _spatial_pairs(output_padding, 0, "output_padding")
        if min(sy, sx, dy, dx) < 1 or max(kh, kw) > MAX_KERNEL:
            raise self.fail(
                f"strides and dilations must be positive, the kernel {kh}x{kw} at most {MAX_KERNEL}"
            )
        if auto_pad not in ("NOTSET", "", "VALID", "SAME_UPPER", "SAME_LOWER"):
            raise self.unsupported("auto_pad", auto_pad)
        shape = None if output_shape is None else [int(v) for v in output_shape][-2:]
        if shape is not None and len(shape) != 2:
            raise self.fail(f"output_shape {output_shape} must give H and W")
        p = [0, 0, 0, 0] if pads is None or auto_pad not in ("NOTSET", "") else [int(v) for v in pads]
        if len(p) != 4 or min(p) < 0:
            raise self.fail(f"pads must be 4 non-negative values, got {p}")
        dims = []
        sizes = (parts[0].height, parts[0].width)
        for i, (d, k, st, dl) in enumerate(zip(sizes, (kh, kw), (sy, sx), (dy, dx), strict=True)):
            if adj[i] < 0 or adj[i] >= max(st, dl):
                raise self.fail(f"output_padding {list(adj)} must be below the stride or the dilation")
            full = dl * (k - 1) + 1 + adj[i] - st  # out = stride * n + full - pads
            if shape is not None or auto_pad in ("SAME_UPPER", "SAME_LOWER"):
                if shape is not None and d.scale != 0:
                    raise self.fail("output_shape needs a static input size")
                target = Dim(Fraction(0), shape[i]) if shape is not None else Dim(d.scale * st, d.offset * st)
                total = max(0, st * d.offset + full - target.offset)
                p[i], p[i + 2] = _split_transpose(total, auto_pad)
                dims.append(target)
            else:
                dims.append(Dim(d.scale * st, d.offset * st + full - p[i] - p[i + 2]))
            if dims[-1].scale == 0 and dims[-1].offset < 1:
                raise self.fail(f"output size {dims[-1].offset} is not positive")
        mg, cg = w.shape[1], cin // group
        dense = np.zeros((mg * group, cin, kh, kw))  # the gather form: out[m] += W[c, m] * in[c]
        for g in range(group):
            dense[g * mg : (g + 1) * mg, g * cg : (g + 1) * cg] = w[g * cg : (g + 1) * cg].transpose(
                1, 0, 2, 3
            )
        bias = np.zeros(mg * group) if bias is None else bias
        window = ((kh, kw), (sy, sx), (dy, dx), p)
        return self._conv_pass("conv_transpose", X, parts, dense, bias, window, dims[0], dims[1])

    def BatchNormalization(
        self, X, scale, B, input_mean, input_var, *, epsilon=1e-5, momentum=0.9, training_mode=0, spatial=1
    ) -> Texture:
        if training_mode:
            raise self.unsupported("training_mode", training_mode)
        if spatial != 1:
            raise self.unsupported("spatial", spatial)
        x = self.image(X, "X")
        arrs = [
            self.const(v, n).astype(np.float64).reshape(-1)
            for v, n in ((scale, "scale"), (B, "B"), (input_mean, "input_mean"), (input_var, "input_var"))
        ]
        if any(a.shape != (x.channels,) for a in arrs):
            raise self.fail(f"batch-norm parameters must have {x.channels} entries")
        gamma, beta, mean, var = arrs
        s = gamma / np.sqrt(var + float(epsilon))
        shift = beta - mean * s
        if not (np.all(np.isfinite(s)) and np.all(np.isfinite(shift))):
            raise self.fail("batch-norm parameters give non-finite scale/shift")
        return self._affine(X, s, shift, "BatchNormalization")

    def _affine(self, X: Any, s: np.ndarray, shift: np.ndarray, op: str, index: int | None = 0) -> Texture:
        """X * s + shift per channel: folded into a producing conv without epilogue, else an epilogue."""
        x = self.image(X, "X")
        if not (np.all(np.isfinite(s)) and np.all(np.isfinite(shift))):
            raise self.fail("per-channel scale/shift is non-finite")
        p = self.fusible_pass(index) if isinstance(X, Texture) and index is not None else None
        if p is not None and p.kind in CONV_KINDS and not p.epilogue:
            # Fold into the conv: W' = W * s (per output channel), b' = b * s + shift.
            p.fields["weight64"] = p.fields["weight64"] * s[:, None, None, None]
            p.fields["bias64"] = p.fields["bias64"] * s + shift
            p.ops.append(op)
            p.nodes.append(self.label)
            p.folded_bn = p.folded_bn or op == "BatchNormalization"
            return p.output
        names = (self.param_name("scale"), self.param_name("shift"))
        params = {names[0]: _vec4_rows(s, x.layers), names[1]: _vec4_rows(shift, x.layers)}
        return self._elementwise(X, Epilogue(form="affine", arrays=names), params, op, index)

    def _arithmetic(self, op: str, A: Any, B: Any) -> Any:
        if isinstance(A, np.ndarray) and isinstance(B, np.ndarray):
            return np.asarray(_constant_binary(op, A, B))  # 0-d operands give a numpy scalar
        if not isinstance(A, np.ndarray) and not isinstance(B, np.ndarray):
            return self._binary(op, A, B)
        first = isinstance(A, np.ndarray)  # constant (op) image
        X, index = (B, 1) if first else (A, 0)
        x = self.image(X, "B" if first else "A")
        c = self.channel_const(A if first else B, x.channels, "A" if first else "B")
        one, zero = np.ones(x.channels), np.zeros(x.channels)
        if op == "Add":
            return self._affine(X, one, c, op, index)
        if op == "Sub":
            return self._affine(X, -one, c, op, index) if first else self._affine(X, one, -c, op, index)
        if op == "Mul":
            return self._affine(X, c, zero, op, index)
        if not first:
            with np.errstate(divide="ignore"):
                return self._affine(X, 1.0 / c, zero, op, index)  # x * (1/c): within 1.5 ulp of x / c
        name = self.param_name("numerator")
        params = {name: _vec4_rows(c, x.layers)}
        return self._elementwise(X, Epilogue(form="rdiv", arrays=(name,)), params, op, index)

    def _binary(self, op: str, A: Any, B: Any) -> Texture:
        """Two images: equal shapes, or one of them 1 x 1 in space and/or of one channel (broadcast)."""
        a, b = self.image(A, "A"), self.image(B, "B")
        channels = max(a.channels, b.channels)
        point = (Dim(Fraction(0), 1), Dim(Fraction(0), 1))
        big = a if (a.height, a.width) != point else b
        fetch = []
        for t in (a, b):
            spatial = (t.height, t.width) == (big.height, big.width)
            if not (spatial or (t.height, t.width) == point) or t.channels not in (1, channels):
                raise self.fail(
                    f"inputs of {a.channels}x{a.height.describe('H')}x{a.width.describe('W')} and "
                    f"{b.channels}x{b.height.describe('H')}x{b.width.describe('W')} do not broadcast "
                    "(equal shapes, 1x1 in space or one channel)"
                )
            full = t.channels == channels
            fetch.append(("full" if full else "channel") if spatial else ("pixel" if full else "scalar"))
        out = self.new_texture(channels, big.height, big.width)
        ps = Pass(0, "binary", [op], [a, b], out, nodes=[self.label])
        ps.fields = {"op": op, "fetch": fetch}
        return self.add_pass(ps).output

    def Add(self, A, B) -> Any:
        return self._arithmetic("Add", A, B)

    def Sub(self, A, B) -> Any:
        return self._arithmetic("Sub", A, B)

    def Mul(self, A, B) -> Any:
        return self._arithmetic("Mul", A, B)

    def Div(self, A, B) -> Any:
        return self._arithmetic("Div", A, B)

    def PRelu(self, X, slope) -> Texture:
        x = self.image(X, "X")
        name = self.param_name("slope")
        params = {name: _vec4_rows(self.channel_const(slope, x.channels, "slope"), x.layers)}
        return self._elementwise(X, Epilogue(form="prelu", arrays=(name,)), params, "PRelu")

    def Elu(self, X, *, alpha=1.0) -> Texture:
        return self._activation(X, Act("Elu", {"alpha": float(alpha)}))

    def Softplus(self, X) -> Texture:
        return self._activation(X, Act("Softplus"))

    def HardSigmoid(self, X, *, alpha=0.2, beta=0.5) -> Texture:
        return self._activation(X, Act("HardSigmoid", {"alpha": float(alpha), "beta": float(beta)}))

    def HardSwish(self, X) -> Texture:
        return self._activation(X, Act("HardSwish"))

    def Sin(self, input) -> Texture:  # noqa: A002
        return self._activation(input, Act("Sin"))

    def Cos(self, input) -> Texture:  # noqa: A002
        return self._activation(input, Act("Cos"))

    def Relu(self, X) -> Texture:
        return self._activation(X, Act("Relu"))

    def LeakyRelu(self, X, *, alpha=0.01) -> Texture:
        return self._activation(X, Act("LeakyRelu", {"alpha": float(alpha)}))

    def Sigmoid(self, X) -> Texture:
        return self._activation(X, Act("Sigmoid"))

    def Tanh(self, X) -> Texture:
        return self._activation(X, Act("Tanh"))

    def Clip(self, input, min=None, max=None) -> Texture:  # noqa: A002
        lo = None if min is None else self.const(min, "min")
        hi = None if max is None else self.const(max, "max")
        return self._activation(input, Act("Clip", clip_bounds(lo, hi)))

    def Identity(self, input) -> Any:  # noqa: A002
        return input

    def _pool(self, kind, X, kernel_shape, strides, pads, dilations, auto_pad, ceil_mode) -> Pass:
        x = self.image(X, "X")
        window = self._window(kernel_shape, strides, dilations, pads, auto_pad, (x.height, x.width))
        (kh, kw), (sy, sx), (dy, dx), p = window
        if ceil_mode not in (0, 1):
            raise self.unsupported("ceil_mode", ceil_mode)
        # SAME pads make the division exact, so ceil_mode cannot change its size; VALID takes it (onnxruntime)
        h = self.output_dim(x.height, kh, sy, dy, p[0], p[2], ceil_mode)
        w = self.output_dim(x.width, kw, sx, dx, p[1], p[3], ceil_mode)
        out = self.new_texture(x.channels, h, w)
        ps = Pass(0, kind, [self.node.op_type], [x], out, nodes=[self.label])
        ps.fields = {"kernel": (kh, kw), "strides": (sy, sx), "dilations": (dy, dx), "pads": p}
        return self.add_pass(ps)

    def AveragePool(
        self,
        X,
        *,
        auto_pad="NOTSET",
        ceil_mode=0,
        count_include_pad=0,
        dilations=None,
        kernel_shape,
        pads=None,
        strides=None,
    ) -> Texture:
        if count_include_pad not in (0, 1):
            raise self.unsupported("count_include_pad", count_include_pad)
        ps = self._pool("pool_avg", X, kernel_shape, strides, pads, dilations, auto_pad, ceil_mode)
        # count_include_pad=1 divides by the taps inside the padded input (not those past the pads,
        # which ceil_mode windows can reach), as onnxruntime does.
        ps.fields["include_pad"] = bool(count_include_pad)
        return ps.output

    def MaxPool(
        self,
        X,
        *,
        auto_pad="NOTSET",
        ceil_mode=0,
        dilations=None,
        kernel_shape,
        pads=None,
        storage_order=0,
        strides=None,
    ) -> Texture:
        if storage_order not in (0, 1):  # it orders only the Indices output, which is refused
            raise self.unsupported("storage_order", storage_order)
        return self._pool("pool_max", X, kernel_shape, strides, pads, dilations, auto_pad, ceil_mode).output

    def _global_pool(self, kind: str, X: Any) -> Texture:
        x = self.image(X, "X")
        if x.height.scale != 0 or x.width.scale != 0:
            self.global_reads.append(self.label)
        point = Dim(Fraction(0), 1)
        out = self.new_texture(x.channels, point, point)
        return self.add_pass(Pass(0, kind, [self.node.op_type], [x], out, nodes=[self.label])).output

    def GlobalAveragePool(self, X) -> Texture:
        return self._global_pool("global_pool_avg", X)

    def GlobalMaxPool(self, X) -> Texture:
        return self._global_pool("global_pool_max", X)

    PAD_MODES = ("constant", "reflect", "edge", "wrap")

    def Pad(
        self, data, pads_input=None, constant_value=None, axes=None, *, mode="constant", pads=None, value=0.0
    ) -> Texture:
        """Opset 11+: pads (here ``pads_input``: Python needs it apart from the opset-2 attribute of the
        same ONNX name), constant_value and axes are inputs; opset 2: pads and value are attributes."""
        x = self.image(data, "data")
        if mode not in self.PAD_MODES:
            raise self.unsupported("mode", mode)
        if pads_input is not None:
            pv = [int(v) for v in self.const(pads_input, "pads").reshape(-1)]
        elif pads is not None:
            pv = [int(v) for v in pads]
        else:
            raise self.fail("pads is missing")
        if constant_value is not None:
            cv = self.const(constant_value, "constant_value").astype(np.float64).reshape(-1)
            if cv.size > 1:
                raise self.fail("constant_value must be a scalar")
            value = float(cv[0]) if cv.size else 0.0
        if not np.isfinite(np.float32(value)):
            raise self.fail(f"constant_value {value!r} is not finite")
        ax = list(range(4)) if axes is None else [int(a) % 4 for a in self.const(axes, "axes").reshape(-1)]
        if len(pv) != 2 * len(ax):
            raise self.fail(f"{len(pv)} pads for {len(ax)} axes")
        full = [0] * 8
        for i, a in enumerate(ax):
            full[a], full[a + 4] = pv[i], pv[i + len(ax)]
        if any(full[k] for k in (0, 1, 4, 5)):
            raise self.fail(f"only the spatial axes (H, W) may be padded, got pads {pv}")
        top, left, bottom, right = full[2], full[3], full[6], full[7]
        h = Dim(x.height.scale, x.height.offset + top + bottom)
        w = Dim(x.width.scale, x.width.offset + left + right)
        if (h.scale == 0 and h.offset < 1) or (w.scale == 0 and w.offset < 1):
            raise self.fail(f"pads {pv} leave no pixels")
        out = self.new_texture(x.channels, h, w)
        ps = Pass(0, "spatial_pad", ["Pad"], [x], out, nodes=[self.label])
        ps.fields = {"mode": mode, "pads": [top, left, bottom, right], "value": float(value)}
        return self.add_pass(ps).output

    RESIZE_COORDS = (
        "half_pixel",
        "pytorch_half_pixel",
        "align_corners",
        "asymmetric",
        "half_pixel_symmetric",
        "tf_crop_and_resize",
    )
    NEAREST_MODES = ("round_prefer_floor", "round_prefer_ceil", "floor", "ceil")
    KEEP_ASPECT = ("stretch", "not_larger", "not_smaller")

    def Resize(
        self,
        X,
        roi=None,
        scales=None,
        sizes=None,
        *,
        antialias=0,
        axes=None,
        coordinate_transformation_mode="half_pixel",
        cubic_coeff_a=-0.75,
        exclude_outside=0,
        extrapolation_value=0.0,
        keep_aspect_ratio_policy="stretch",
        mode="nearest",
        nearest_mode="round_prefer_floor",
    ) -> Texture:
        x = self.image(X, "X")
        coord = coordinate_transformation_mode
        if mode not in ("nearest", "linear", "cubic"):
            raise self.unsupported("mode", mode)
        if coord not in self.RESIZE_COORDS:
            raise self.unsupported("coordinate_transformation_mode", coord)
        if mode == "nearest" and nearest_mode not in self.NEAREST_MODES:
            raise self.unsupported("nearest_mode", nearest_mode)
        for name, v in (("antialias", antialias), ("exclude_outside", exclude_outside)):
            if v not in (0, 1):
                raise self.unsupported(name, v)
        if keep_aspect_ratio_policy not in self.KEEP_ASPECT:
            raise self.unsupported("keep_aspect_ratio_policy", keep_aspect_ratio_policy)
        ax = [0, 1, 2, 3] if axes is None else [int(a) % 4 for a in axes]
        full_scales: list[float | None] = [1.0, 1.0, None, None]
        full_sizes: list[int | None] = [None, None, None, None]
        sc = None if scales is None else self.const(scales, "scales").astype(np.float32).reshape(-1)
        sz = None if sizes is None else self.const(sizes, "sizes").astype(np.int64).reshape(-1)
        if sc is not None and sc.size == 0:
            sc = None
        if sz is not None and sz.size == 0:
            sz = None
        if (sc is None) == (sz is None):
            raise self.fail("exactly one of scales and sizes must be given as a constant")
        vals = sc if sc is not None else sz
        if vals.size != len(ax):
            raise self.fail(f"{vals.size} scales/sizes for {len(ax)} axes")
        for a, v in zip(ax, vals, strict=True):
            if sc is not None:
                full_scales[a] = float(v)
            else:
                full_sizes[a] = int(v)
        roi_box = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]  # starts then ends, per axis (N, C, H, W)
        if coord == "tf_crop_and_resize" and roi is not None and self.const(roi, "roi").size:
            r = self.const(roi, "roi").astype(np.float32).reshape(-1)
            if r.size != 2 * len(ax):
                raise self.fail(f"roi has {r.size} values for {len(ax)} axes")
            for i, a in enumerate(ax):
                roi_box[a], roi_box[a + 4] = float(r[i]), float(r[i + len(ax)])
            if roi_box[:2] != [0.0, 0.0] or roi_box[4:6] != [1.0, 1.0]:
                raise self.fail("roi may crop only the spatial axes (H, W)")
        in_sizes = [1, x.channels, x.height.offset, x.width.offset]
        if sz is not None and keep_aspect_ratio_policy != "stretch":
            if x.height.scale != 0 or x.width.scale != 0:
                raise self.fail(
                    f"keep_aspect_ratio_policy={keep_aspect_ratio_policy!r} needs a static input size"
                )
            ratios = [np.float32(full_sizes[a]) / np.float32(in_sizes[a]) for a in ax]
            s = min(ratios) if keep_aspect_ratio_policy == "not_larger" else max(ratios)
            for a in ax:
                full_sizes[a] = int(math.floor(float(np.float32(s) * np.float32(in_sizes[a])) + 0.5))
                full_scales[a] = float(s)
            if full_sizes[0] not in (None, 1) or full_sizes[1] not in (None, x.channels):
                raise self.fail("keep_aspect_ratio_policy would resize the batch or channel axis")
            sc = np.asarray([full_scales[a] for a in ax], np.float32)  # the coordinates use this scale
        if sz is not None and ((full_sizes[0] not in (None, 1)) or (full_sizes[1] not in (None, x.channels))):
            raise self.fail("only the spatial axes (H, W) may be resized")
        if sz is None:
            if full_scales[0] != 1.0 or full_scales[1] != 1.0:
                raise self.fail("only the spatial axes (H, W) may be resized")
            for a in (2, 3):
                if full_scales[a] is None:
                    full_scales[a] = 1.0
                if not full_scales[a] > 0:
                    raise self.fail(f"scale {full_scales[a]} must be positive")
        dims, scale_exprs, support = [], [], []
        for a, d in ((2, x.height), (3, x.width)):
            crop = (
                np.float32(roi_box[a + 4]) - np.float32(roi_box[a]) if coord == "tf_crop_and_resize" else 1.0
            )
            n = full_sizes[a]
            if n is not None:
                if n < 1:
                    raise self.fail(f"size {n} must be positive")
                dims.append(Dim(Fraction(0), int(n)))
            elif d.scale == 0:
                dims.append(
                    Dim(
                        Fraction(0), int(np.float32(d.offset) * np.float32(crop) * np.float32(full_scales[a]))
                    )
                )
            else:
                f = Fraction(float(np.float32(full_scales[a])))
                if crop != 1.0 or f.denominator > 64 or (d.offset * f).denominator != 1:
                    raise self.fail(
                        f"scale {full_scales[a]} is not exact on a dynamic size; give sizes or a 1/2^k scale"
                    )
                dims.append(Dim(d.scale * f, int(d.offset * f)))
            if sc is not None:
                s = float(np.float32(full_scales[a]))
                scale_exprs.append(("literal", glsl_float(s)))
            else:
                scale_exprs.append(("ratio", ""))
                if n is None:
                    s = 1.0
                else:
                    s = float(np.float32(n) / np.float32(d.offset)) if d.scale == 0 else None
            support.append(s)
        return self._resize_pass(
            x,
            dims,
            scale_exprs,
            support,
            mode,
            coord,
            nearest_mode,
            antialias,
            cubic_coeff_a,
            exclude_outside,
            extrapolation_value,
            roi_box,
        )

    def _resize_pass(
        self,
        x: Texture,
        dims: list[Dim],
        scale_exprs: list,
        scales: list[float | None],
        mode: str,
        coord: str,
        nearest_mode: str,
        antialias: int,
        cubic_a: float,
        exclude_outside: int,
        extrapolation: float,
        roi_box: list[float],
    ) -> Texture:
        """scales: the per-axis scale when known at generation time (None: a ratio of dynamic sizes)."""
        if mode == "nearest":
            kind = "resize_nearest"
        elif mode == "cubic" or (antialias and any(s is None or s < 1 for s in scales)):
            kind = "resize_filter"
        else:
            kind = "resize_linear"  # antialias does not change upscaling (the kernel is not widened)
        fields = {
            "mode": mode,
            "coord": coord,
            "nearest_mode": nearest_mode,
            "scales": scale_exprs,
            "extrapolation": float(extrapolation) if coord == "tf_crop_and_resize" else None,
            "roi": [roi_box[2], roi_box[3], roi_box[6], roi_box[7]],
        }
        if kind == "resize_filter":
            if antialias and any(s is None for s in scales):
                raise self.fail(
                    "antialias with sizes needs a static input size (the filter width depends on the scale)"
                )
            widen = [min(s, 1.0) if antialias else 1.0 for s in scales]
            reach = 2 if mode == "cubic" else 1
            half = [math.ceil(reach / w) for w in widen]
            if 2 * max(half) > MAX_FILTER_TAPS:
                raise self.fail(f"antialiased scale {min(scales)} needs over {MAX_FILTER_TAPS} taps per axis")
            fields.update(
                kernel=mode,
                cubic_coeff_a=float(cubic_a),
                exclude_outside=bool(exclude_outside),
                widen=widen,
                half=half,
            )
        out = self.new_texture(x.channels, dims[0], dims[1])
        ps = Pass(0, kind, [self.node.op_type], [x], out, nodes=[self.label])
        ps.fields = fields
        return self.add_pass(ps).output

    def Upsample(self, X, scales_input=None, *, mode="nearest", scales=None) -> Texture:
        """Opsets 7-9: scales as an attribute (7, 8) or an input (9; ``scales_input``, apart from the
        attribute of the same ONNX name), each >= 1. Asymmetric coordinates, nearest rounds down."""
        x = self.image(X, "X")
        if mode not in ("nearest", "linear"):
            raise self.unsupported("mode", mode)
        if scales_input is not None:
            sc = self.const(scales_input, "scales").astype(np.float32).reshape(-1)
        elif scales is not None:
            sc = np.asarray(scales, np.float32)
        else:
            raise self.fail("scales is missing")
        if sc.size != 4 or sc[0] != 1 or sc[1] != 1 or not np.all(sc >= 1):
            raise self.fail(f"scales {sc.tolist()} must be (1, 1, sH, sW) with sH, sW >= 1")
        dims, exprs = [], []
        for s, d in ((sc[2], x.height), (sc[3], x.width)):
            if d.scale == 0:
                dims.append(Dim(Fraction(0), int(np.float32(d.offset) * s)))
            else:
                f = Fraction(float(s))
                if f.denominator > 64 or (d.offset * f).denominator != 1:
                    raise self.fail(f"scale {float(s)} is not exact on a dynamic size")
                dims.append(Dim(d.scale * f, int(d.offset * f)))
            exprs.append(("literal", glsl_float(float(s))))
        return self._resize_pass(
            x,
            dims,
            exprs,
            [float(sc[2]), float(sc[3])],
            mode,
            "asymmetric",
            "floor",
            0,
            -0.75,
            0,
            0.0,
            [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 1.0],
        )

    def Concat(self, *inputs, axis) -> ConcatValue | np.ndarray:
        if inputs and all(isinstance(v, np.ndarray) for v in inputs):
            return np.concatenate([np.atleast_1d(v) for v in inputs], axis=int(axis))  # shape arithmetic
        if int(axis) not in (1, -3):
            raise self.unsupported("axis", axis)
        parts: list[Texture] = []
        for k, v in enumerate(inputs):
            if isinstance(v, ConcatValue):
                parts.extend(v.parts)
            else:
                parts.append(self.image(v, f"#{k}"))
        if not parts:
            raise self.fail("Concat without inputs")
        if any(t.height != parts[0].height or t.width != parts[0].width for t in parts):
            raise self.fail("Concat inputs differ in spatial size")
        return ConcatValue(parts)

    # -- views (Reshape / Transpose / Flatten of image tensors; see views.py)
    def static_size(self, t: Texture) -> tuple[int, int]:
        if t.height.scale != 0 or t.width.scale != 0:
            raise self.fail(
                "reshaping or transposing an image tensor needs a static image size; give the input one"
            )
        return t.height.offset, t.width.offset

    def view(self, value: Any, what: str) -> View:
        if isinstance(value, View):
            return value
        t = self.image(value, what)
        h, w = self.static_size(t)
        return View(t, image_axes(t.channels, h, w))

    def simplify(self, v: View) -> View | Texture:
        """The texture itself where the view reads it element for element."""
        h, w = self._digit_sizes(v.texture)
        return v.texture if is_image(v.axes, v.texture.channels, h, w) else v

    def reshape_view(self, v: View, shape: list[int], allowzero: int) -> View | Texture:
        s = [v.shape[i] if d == 0 and not allowzero and i < len(v.shape) else d for i, d in enumerate(shape)]
        if s.count(-1) > 1:
            raise self.fail(f"shape {shape} has more than one -1")
        if -1 in s:
            known = math.prod(d for d in s if d != -1)
            s[s.index(-1)] = math.prod(v.shape) // known if known else 0
        axes = reshape(v.axes, s)
        if isinstance(axes, str):
            raise self.fail(axes)
        return self.simplify(View(v.texture, axes))

    def materialise_view(self, v: View, what: str) -> Texture:
        """A texture holding the view as a (1, C, H, W) image (a gather pass unless it already is one)."""
        if not isinstance(self.simplify(v), View):
            return v.texture
        if len(v.shape) != 4 or v.axes[0]:
            raise self.fail(f"input {what} of shape {v.shape} is not an image (1, C, H, W)")
        _, c, h, w = v.shape
        return self._gather(v.texture, v.axes, Dim(Fraction(0), h), Dim(Fraction(0), w))

    def _gather(self, src: Texture, axes: Axes, h: Dim, w: Dim) -> Texture:
        """Output texel (x, y, channel c) reads the input element the atoms of axes[1:] (c, y, x) give."""
        out = self.new_texture(axes_shape(axes[1:2])[0], h, w)
        ps = Pass(0, "gather", [self.node.op_type], [src], out, nodes=[self.label])
        ps.fields = {"digits": [[(a.axis, a.size, a.stride) for a in run] for run in axes[1:]]}
        return self.add_pass(ps).output

    def Flatten(self, input, *, axis=1) -> View | Texture:  # noqa: A002
        v = self.view(input, "input")
        a = int(axis) % (len(v.shape) + 1)
        return self.reshape_view(v, [math.prod(v.shape[:a]), math.prod(v.shape[a:])], 1)

    def DepthToSpace(self, input, *, blocksize, mode="DCR") -> Texture:  # noqa: A002
        b = int(blocksize)
        t = self.image(input, "input")
        if mode not in ("DCR", "CRD"):
            raise self.unsupported("mode", mode)
        if b < 1 or t.channels % (b * b):
            raise self.fail(f"{t.channels} channels do not split into blocks of {b}x{b}")
        c = t.channels // (b * b)
        h, w = self._digit_sizes(t)
        axes = image_axes(t.channels, h, w)
        if mode == "DCR":
            axes = self._steps(axes, [1, b, b, c, h, w], [0, 3, 4, 1, 5, 2])
        else:
            axes = self._steps(axes, [1, c, b, b, h, w], [0, 1, 4, 2, 5, 3])
        axes = self._steps(axes, [1, c, h * b, w * b], [0, 1, 2, 3])
        return self._gather(
            t, axes, Dim(t.height.scale * b, t.height.offset * b), Dim(t.width.scale * b, t.width.offset * b)
        )

    def SpaceToDepth(self, input, *, blocksize, mode="DCR") -> Texture:  # noqa: A002
        """mode (opset 25): DCR puts the block offset outermost in the channels (the older opsets'
        only layout), CRD innermost."""
        b = int(blocksize)
        t = self.image(input, "input")
        h, w = self._digit_sizes(t)
        if mode not in ("DCR", "CRD"):
            raise self.unsupported("mode", mode)
        if b < 1 or (t.height.scale == 0 and (h % b or w % b)):
            raise self.fail(f"a {h}x{w} image does not split into blocks of {b}x{b}")
        perm = [0, 3, 5, 1, 2, 4] if mode == "DCR" else [0, 1, 3, 5, 2, 4]
        axes = self._steps(image_axes(t.channels, h, w), [1, t.channels, h // b, b, w // b, b], perm)
        axes = self._steps(axes, [1, t.channels * b * b, h // b, w // b], [0, 1, 2, 3])
        dims = [Dim(d.scale / b, Fraction(d.offset, b)) for d in (t.height, t.width)]
        if any(d.offset.denominator != 1 for d in dims):
            raise self.fail(f"the image size does not split into blocks of {b}x{b}")
        return self._gather(t, axes, *(Dim(d.scale, int(d.offset)) for d in dims))

    def _digit_sizes(self, t: Texture) -> tuple[int, int]:
        """H and W for the atoms of an image: the static sizes, or for a dynamic image a stand-in (2^24,
        divisible by every block size up to 2^12) that never reaches the shader. Only ops that keep it
        whole use it: a space/depth rearrangement leaves a spatial digit outermost in its output axis,
        which the gather reads without a modulo; whole-axis reductions never read it."""
        if t.height.scale or t.width.scale:
            return 1 << 24, 1 << 24
        return t.height.offset, t.width.offset

    def _steps(self, axes: Axes, shape: list[int], perm: list[int]) -> Axes:
        axes = reshape(axes, shape)
        if isinstance(axes, str):
            raise self.fail(axes)
        return transpose(axes, perm)

    # -- reductions, normalisations, softmax
    @property
    def opset(self) -> int:
        return next((int(o.version) for o in self.graph.model.opset_import if o.domain in ("", "ai.onnx")), 1)

    def _axes_list(self, rank: int, axes_input: Any, axes: Any) -> list[int] | None:
        """The reduced axes, normalised; None when none are given."""
        if axes_input is not None:
            ax = [int(a) for a in self._folded(axes_input, "axes").reshape(-1)]
        elif axes is not None:
            ax = [int(a) for a in axes]
        else:
            return None
        if any(not -rank <= a < rank for a in ax):
            raise self.fail(f"axes {ax} out of range for rank {rank}")
        return sorted({a % rank for a in ax})

    def _reduction(self, v: View, reduced: list[int]):
        r = reduction(v.axes, reduced, v.texture.channels)
        if isinstance(r, str):
            raise self.fail(r)
        return r

    def _reduced_dims(self, t: Texture, spatial: tuple[bool, bool]) -> tuple[Dim, Dim]:
        point = Dim(Fraction(0), 1)
        if any(spatial) and (t.height.scale or t.width.scale):
            self.global_reads.append(self.label)
        return (point if spatial[0] else t.height), (point if spatial[1] else t.width)

    def _member_params(self, base: np.ndarray, offsets: np.ndarray) -> dict[str, np.ndarray]:
        names = (self.param_name("base"), self.param_name("offsets"))
        return {
            names[0]: _vec4_rows(base.astype(np.float64), ceil4(len(base))),
            names[1]: _vec4_rows(offsets.astype(np.float64), ceil4(len(offsets))),
        }

    def _reduce(self, op: str, data: Any, axes_input: Any, axes: Any, keepdims: int, noop: int) -> Any:
        if isinstance(data, np.ndarray):
            raise self.fail("input data is a constant; the image target reduces image tensors only")
        v = self.dense_view(data, "data")
        rank = len(v.shape)
        ax = self._axes_list(rank, axes_input, axes)
        if not ax:
            if noop:
                return data
            ax = list(range(rank))
        r = self._reduction(v, ax)
        h, w = self._reduced_dims(v.texture, r.spatial)
        out = self.new_texture(r.groups, h, w)
        ps = Pass(0, "reduce", [self.node.op_type], [v.texture], out, nodes=[self.label])
        ps.params = self._member_params(r.base, r.offsets)
        ps.fields = {
            "op": op,
            "spatial": r.spatial,
            "groups": r.groups,
            "members": len(r.offsets),
            "tables": tuple(ps.params),
        }
        self.add_pass(ps)
        kept = r.kept if keepdims else tuple(run for i, run in enumerate(r.kept) if i not in ax)
        result = self.simplify(View(out, kept))
        if isinstance(result, View) and (out.height.scale or out.width.scale):
            raise self.fail("a reduction of an image of dynamic size must keep its dimensions (keepdims=1)")
        return result

    def dense_view(self, value: Any, what: str) -> View:
        """A view of ``value``; a dynamic-size image is read as (1, C, H, W) with stand-in spatial sizes
        (only whole-axis reductions of it are allowed, which never read the stand-ins)."""
        if not isinstance(value, View):
            t = self.image(value, what)
            if t.height.scale or t.width.scale:
                return View(t, image_axes(t.channels, *self._digit_sizes(t)))
        return self.view(value, what)

    def ReduceMean(self, data, axes_input=None, *, axes=None, keepdims=1, noop_with_empty_axes=0) -> Any:
        return self._reduce("Mean", data, axes_input, axes, keepdims, noop_with_empty_axes)

    def ReduceSum(self, data, axes_input=None, *, axes=None, keepdims=1, noop_with_empty_axes=0) -> Any:
        return self._reduce("Sum", data, axes_input, axes, keepdims, noop_with_empty_axes)

    def ReduceMax(self, data, axes_input=None, *, axes=None, keepdims=1, noop_with_empty_axes=0) -> Any:
        return self._reduce("Max", data, axes_input, axes, keepdims, noop_with_empty_axes)

    def ReduceMin(self, data, axes_input=None, *, axes=None, keepdims=1, noop_with_empty_axes=0) -> Any:
        return self._reduce("Min", data, axes_input, axes, keepdims, noop_with_empty_axes)

    def ReduceL1(self, data, axes_input=None, *, axes=None, keepdims=1, noop_with_empty_axes=0) -> Any:
        return self._reduce("L1", data, axes_input, axes, keepdims, noop_with_empty_axes)

    def ReduceL2(self, data, axes_input=None, *, axes=None, keepdims=1, noop_with_empty_axes=0) -> Any:
        return self._reduce("L2", data, axes_input, axes, keepdims, noop_with_empty_axes)

    def ReduceSumSquare(self, data, axes_input=None, *, axes=None, keepdims=1, noop_with_empty_axes=0) -> Any:
        return self._reduce("SumSquare", data, axes_input, axes, keepdims, noop_with_empty_axes)

    def ReduceProd(self, data, axes_input=None, *, axes=None, keepdims=1, noop_with_empty_axes=0) -> Any:
        return self._reduce("Prod", data, axes_input, axes, keepdims, noop_with_empty_axes)

    def ReduceLogSum(self, data, axes_input=None, *, axes=None, keepdims=1, noop_with_empty_axes=0) -> Any:
        return self._reduce("LogSum", data, axes_input, axes, keepdims, noop_with_empty_axes)

    def _normalize(
        self,
        X: Any,
        reduced_from: int | list[int],
        epsilon: float,
        scale: Any,
        shift: Any,
        align: str,
        op: str,
    ) -> Any:
        """(x - mean) / sqrt(var + epsilon) over the logical axes ``reduced_from`` (an int: that axis and
        all after it), then * scale + shift. align "trailing": scale / shift broadcast numpy-style over the
        trailing axes (LayerNormalization); "axis1": they are (shape[1],) (Instance-, GroupNormalization)."""
        v = self.dense_view(X, "X")
        rank = len(v.shape)
        reduced = list(range(reduced_from % rank, rank)) if isinstance(reduced_from, int) else reduced_from
        r = self._reduction(v, reduced)
        h, w = self._reduced_dims(v.texture, r.spatial)
        t = v.texture
        stats = self.new_texture(2 * r.groups, h, w)
        ps = Pass(0, "moments", [op], [t], stats, nodes=[self.label])
        ps.params = self._member_params(r.base, r.offsets)
        ps.fields = {
            "spatial": r.spatial,
            "groups": r.groups,
            "members": len(r.offsets),
            "epsilon": float(np.float32(epsilon)),
            "tables": tuple(ps.params),
        }
        self.add_pass(ps)
        out = self.new_texture(t.channels, t.height, t.width)
        norm = Pass(0, "normalize", [op], [t, stats], out, nodes=[self.label])
        group = self.param_name("group")
        norm.params = {group: _vec4_rows(r.group_of.astype(np.float64), t.layers)}
        norm.fields = {"groups": r.groups, "spatial": r.spatial, "group": group}
        self.add_pass(norm)
        sc, sh = (
            self._broadcast_channel(v, val, align, what) if val is not None else None
            for val, what in ((scale, "scale"), (shift, "B"))
        )
        if sc is not None or sh is not None:
            sc = np.ones(t.channels) if sc is None else sc
            sh = np.zeros(t.channels) if sh is None else sh
            names = (self.param_name("scale"), self.param_name("shift"))
            norm.params.update({names[0]: _vec4_rows(sc, t.layers), names[1]: _vec4_rows(sh, t.layers)})
            norm.epilogue.append(Epilogue(form="affine", arrays=names))
        return out if isinstance(X, Texture) or not isinstance(X, View) else self.simplify(View(out, v.axes))

    def _broadcast_channel(self, v: View, value: Any, align: str, what: str) -> np.ndarray:
        a = self.const(value, what).astype(np.float64)
        if align == "axis1":
            a = a.reshape([1, -1] + [1] * (len(v.shape) - 2)) if a.size > 1 else a.reshape(())
        out = per_channel(v.axes, a, v.texture.channels)
        if isinstance(out, str):
            raise self.fail(f"{what}: {out}")
        if not np.all(np.isfinite(out)):
            raise self.fail(f"{what} has non-finite values")
        return out

    def InstanceNormalization(self, input, scale, B, *, epsilon=1e-5) -> Any:  # noqa: A002
        return self._normalize(input, 2, epsilon, scale, B, "axis1", "InstanceNormalization")

    def GroupNormalization(self, X, scale, bias, *, epsilon=1e-5, num_groups, stash_type=1) -> Any:
        v = self.dense_view(X, "X")
        if len(v.shape) != 4:
            raise self.fail(f"X of shape {v.shape} is not an image (1, C, H, W)")
        c, g = v.shape[1], int(num_groups)
        if g < 1 or c % g:
            raise self.fail(f"{c} channels do not split into {g} groups")
        sc, sh = (
            self.const(a, n).astype(np.float64).reshape(-1) for a, n in ((scale, "scale"), (bias, "bias"))
        )
        if sc.size == g and g != c:  # opset 18: one value per group
            sc, sh = np.repeat(sc, c // g), np.repeat(sh, c // g)
        grouped = self._steps(v.axes, [1, g, c // g, v.shape[2], v.shape[3]], [0, 1, 2, 3, 4])
        out = self._normalize(View(v.texture, grouped), 2, epsilon, None, None, "axis1", "GroupNormalization")
        t = out.texture if isinstance(out, View) else out
        return self._affine_view(View(t, v.axes), sc.reshape(1, c, 1, 1), sh.reshape(1, c, 1, 1), X)

    def _affine_view(self, v: View, scale: np.ndarray, shift: np.ndarray, like: Any) -> Any:
        s = self._broadcast_channel(v, scale, "trailing", "scale")
        b = self._broadcast_channel(v, shift, "trailing", "bias")
        p = self.producer[v.texture.ident]
        names = (self.param_name("scale"), self.param_name("shift"))
        p.params.update(
            {names[0]: _vec4_rows(s, v.texture.layers), names[1]: _vec4_rows(b, v.texture.layers)}
        )
        p.epilogue.append(Epilogue(form="affine", arrays=names))
        return self.simplify(v) if isinstance(like, View) else v.texture

    def LayerNormalization(self, X, Scale, B=None, *, axis=-1, epsilon=1e-5, stash_type=1) -> Any:
        return self._normalize(X, int(axis), epsilon, Scale, B, "trailing", "LayerNormalization")

    def _softmax(self, input: Any, axis: int | None, log: bool) -> Any:
        v = self.dense_view(input, "input")
        rank = len(v.shape)
        if axis is None:
            axis = -1 if self.opset >= 13 else 1
        a = int(axis) % rank
        reduced = [a] if self.opset >= 13 else list(range(a, rank))  # before 13: the flattened tail
        r = self._reduction(v, reduced)
        if any(r.spatial):
            raise self.fail(
                f"softmax over axes {reduced} of shape {v.shape} reaches the image's height or width; "
                "the image target takes it over channels only"
            )
        t = v.texture
        out = self.new_texture(t.channels, t.height, t.width)
        ps = Pass(0, "softmax", [self.node.op_type], [t], out, nodes=[self.label])
        ps.params = self._member_params(r.base[r.group_of], r.offsets)
        ps.fields = {"log": log, "members": len(r.offsets), "tables": tuple(ps.params)}
        self.add_pass(ps)
        return out if not isinstance(input, View) else self.simplify(View(out, v.axes))

    def Softmax(self, input, *, axis=None) -> Any:  # noqa: A002
        return self._softmax(input, axis, False)

    def LogSoftmax(self, input, *, axis=None) -> Any:  # noqa: A002
        return self._softmax(input, axis, True)

    def LRN(self, X, *, alpha=1e-4, beta=0.75, bias=1.0, size) -> Texture:
        x = self.image(X, "X")
        n = int(size)
        if n < 1:
            raise self.fail(f"size {n} must be positive")
        out = self.new_texture(x.channels, x.height, x.width)
        ps = Pass(0, "lrn", ["LRN"], [x], out, nodes=[self.label])
        ps.fields = {
            "before": (n - 1) // 2,
            "after": n - 1 - (n - 1) // 2,
            "alpha": float(np.float32(alpha) / n),
            "beta": float(beta),
            "bias": float(bias),
        }
        return self.add_pass(ps).output

    def LpPool(
        self, X, *, auto_pad="NOTSET", ceil_mode=0, dilations=None, kernel_shape, p=2, pads=None, strides=None
    ) -> Texture:
        if float(p) <= 0:
            raise self.unsupported("p", p)
        ps = self._pool("pool_lp", X, kernel_shape, strides, pads, dilations, auto_pad, ceil_mode)
        ps.fields["p"] = float(p)
        return ps.output

    def GlobalLpPool(self, X, *, p=2) -> Texture:
        if float(p) <= 0:
            raise self.unsupported("p", p)
        out = self._global_pool("global_pool_lp", X)
        self.producer[out.ident].fields["p"] = float(p)
        return out

    def Gemm(self, A, B, C=None, *, alpha=1.0, beta=1.0, transA=0, transB=0) -> Any:
        if isinstance(A, np.ndarray) and isinstance(B, np.ndarray):
            a, b = (A.T if transA else A), (B.T if transB else B)
            return alpha * (a @ b) + (0 if C is None else beta * C)
        if transA:
            raise self.unsupported("transA", transA)
        b = self.const(B, "B").astype(np.float64)
        b = b.T if transB else b  # (features, outputs)
        bias = None if C is None else beta * self.const(C, "C").astype(np.float64)
        return self._dense(A, alpha * b, bias)

    def MatMul(self, A, B) -> Any:
        if isinstance(A, np.ndarray) and isinstance(B, np.ndarray):
            return A @ B
        return self._dense(A, self.const(B, "B").astype(np.float64), None)

    def _dense(self, A: Any, b: np.ndarray, bias: np.ndarray | None) -> Any:
        """(1, F) @ (F, K) on a flattened image: a conv whose kernel covers the whole image."""
        v = self.view(A, "A")
        if len(v.shape) != 2 or v.shape[0] != 1 or b.ndim != 2 or b.shape[0] != v.shape[1]:
            raise self.fail(
                f"A of shape {v.shape} and B of shape {list(b.shape)}: the image target takes "
                "(1, F) @ (F, K) on a flattened image"
            )
        t = v.texture
        h, w = t.height.offset, t.width.offset
        if max(h, w) > MAX_KERNEL:
            raise self.fail(
                f"a dense layer over a {h}x{w} image needs a kernel beyond {MAX_KERNEL}x{MAX_KERNEL}"
            )
        k = b.shape[1]
        xyz = coordinates(v.axes[1:])
        weight = np.zeros((k, t.channels, h, w))
        weight[:, xyz["c"], xyz["y"], xyz["x"]] = b.T
        bias_k = np.zeros(k)
        if bias is not None:
            try:
                bias_k = np.broadcast_to(bias, (1, k)).reshape(k).copy()
            except ValueError:
                raise self.fail(f"C of shape {list(bias.shape)} does not broadcast to (1, {k})") from None
        window = ((h, w), (1, 1), (1, 1), [0, 0, 0, 0])
        point = Dim(Fraction(0), 1)
        out = self._conv_pass("conv", t, [t], weight, bias_k, window, point, point)
        return View(out, ((), (Atom("c", k, 1),) if k > 1 else ()))

    # -- elementwise additions
    def Erf(self, input) -> Any:  # noqa: A002
        return self._activation_any(input, Act("Erf"))

    def Gelu(self, X, *, approximate="none") -> Any:
        if approximate not in ("none", "tanh"):
            raise self.unsupported("approximate", approximate)
        return self._activation_any(X, Act("Gelu" if approximate == "none" else "GeluTanh"))

    def Mish(self, X) -> Any:
        return self._activation_any(X, Act("Mish"))

    def Sqrt(self, X) -> Any:
        return self._activation_any(X, Act("Sqrt"))

    def Exp(self, input) -> Any:  # noqa: A002
        return self._activation_any(input, Act("Exp"))

    def Log(self, input) -> Any:  # noqa: A002
        return self._activation_any(input, Act("Log"))

    def Abs(self, X) -> Any:
        return self._activation_any(X, Act("Abs"))

    def Neg(self, X) -> Any:
        return self._activation_any(X, Act("Neg"))

    def Reciprocal(self, X) -> Any:
        return self._activation_any(X, Act("Reciprocal"))

    def Sign(self, input) -> Any:  # noqa: A002
        return self._activation_any(input, Act("Sign"))

    def Softsign(self, input) -> Any:  # noqa: A002
        return self._activation_any(input, Act("Softsign"))

    def Floor(self, X) -> Any:
        return self._activation_any(X, Act("Floor"))

    def Ceil(self, X) -> Any:
        return self._activation_any(X, Act("Ceil"))

    def Pow(self, X, Y) -> Any:
        if isinstance(X, np.ndarray) and isinstance(Y, np.ndarray):
            return np.power(X, Y)
        e = self.const(Y, "Y")
        if e.size != 1:
            raise self.fail(f"the exponent Y of shape {list(e.shape)} must be a scalar")
        return self._activation_any(X, Act("Pow", {"e": float(e.reshape(()))}))

    def _activation_any(self, X: Any, act: Act, index: int | None = 0) -> Any:
        """An activation on an image, a pending concatenation or a view (the view keeps its atoms);
        ``index``: X's input position for fusion (None: X is an intermediate value of this node)."""
        if isinstance(X, np.ndarray):
            raise self.fail("the input is a constant; the image target applies this op to image tensors")
        if isinstance(X, View):
            out = self._elementwise(X.texture, Epilogue(act=act), {}, act.op, index=None)
            result: Any = View(out, X.axes)
        else:
            out = result = self._elementwise(X, Epilogue(act=act), {}, act.op, index)
        if act.op in _GUARDED and out.channels % 4:
            p = self.producer[out.ident]
            p.epilogue.append(Epilogue(form="guard"))
        if act.op in ("Erf", "Gelu"):
            self.producer[out.ident].fields["erf"] = True
        return result

    def Dropout(self, data, ratio_input=None, training_mode=None, *, is_test=1, ratio=0.5, seed=0) -> Any:
        """Inference: the identity. Opset 12+: ratio and training_mode are inputs (``ratio_input``);
        before, ratio (and is_test) are attributes."""
        if training_mode is not None and (not isinstance(training_mode, np.ndarray) or training_mode.any()):
            raise self.fail("training_mode must be a constant false: the image target runs inference")
        if not is_test:
            raise self.unsupported("is_test", is_test)
        return data

    def _variadic(self, op: str, inputs: tuple) -> Any:
        if not inputs:
            raise self.fail("no inputs")
        if all(isinstance(v, np.ndarray) for v in inputs):
            f = {"Add": np.add, "Max": np.maximum, "Min": np.minimum}[op]
            out = inputs[0]
            for v in inputs[1:]:
                out = f(out, v)
            return out
        acc = inputs[0]
        for v in inputs[1:]:
            acc = self._pair(op, acc, v)
        return acc

    def _pair(self, op: str, a: Any, b: Any) -> Any:
        """One step of a variadic op; no fusion into the inputs' passes (a is an intermediate value)."""
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            c, x = (a, b) if isinstance(a, np.ndarray) else (b, a)
            if op == "Add":
                t = self.image(x, "data_0")
                return self._affine(
                    t, np.ones(t.channels), self.channel_const(c, t.channels, "data_0"), "Sum", None
                )
            if c.size != 1:
                raise self.fail(
                    f"{op} with a constant of shape {list(c.shape)}: the image target takes scalars only"
                )
            bound = {"lo": float(c.reshape(()))} if op == "Max" else {"hi": float(c.reshape(()))}
            return self._activation_any(x, Act("Clip", bound), None)
        return self._binary(op, a, b)

    def Sum(self, *data_0) -> Any:
        return self._variadic("Add", data_0)

    def Max(self, *data_0) -> Any:
        return self._variadic("Max", data_0)

    def Min(self, *data_0) -> Any:
        return self._variadic("Min", data_0)

    def Mean(self, *data_0) -> Any:
        total = self._variadic("Add", data_0)
        if len(data_0) == 1 or isinstance(total, np.ndarray):
            return total / len(data_0) if isinstance(total, np.ndarray) else total
        x = self.image(total, "sum")
        return self._affine(x, np.full(x.channels, 1.0 / len(data_0)), np.zeros(x.channels), "Mean", None)

    # -- constant folding (FOLDED_OPS): numpy on constants; an image input is refused by _folded
    def _folded(self, value: Any, what: str) -> np.ndarray:
        if not isinstance(value, np.ndarray):
            raise self.fail(
                f"input {what} is an image tensor; the image target evaluates this op on constants only"
            )
        return value

    def _small(self, a: np.ndarray) -> np.ndarray:
        if a.size > MAX_FOLDED_ELEMENTS:
            raise self._too_large(list(a.shape))
        return a

    def _too_large(self, shape: list[int]) -> NeuralaoError:
        """The folded-constant limit, naming the constant and the node that would use it (through any
        further folded ops): that is the layer the user recognises (a Conv weight, a Gemm matrix)."""
        assert self.node is not None
        name = self.node.output[0]
        users, seen, todo = [], {name}, [name]
        while todo and len(users) < 3:
            tensor = todo.pop(0)
            for k, node in enumerate(self.graph.nodes):
                if tensor not in node.input:
                    continue
                if node.op_type in (*FOLDED_OPS, "Identity") and node.output and node.output[0] not in seen:
                    seen.add(node.output[0])
                    todo.append(node.output[0])
                else:
                    users.append(f"{_node_label(node, k)} (input {list(node.input).index(tensor)})")
        used_by = f"used by {', '.join(users)}" if users else "used by no op the image target lowers"
        return self.fail(
            f"the constant {name!r} of shape {shape} ({math.prod(shape):,} elements), {used_by}, exceeds the "
            f"{MAX_FOLDED_ELEMENTS:,}-element limit on constants computed inside the graph (what weights.bin "
            "can hold)"
        )

    def ConstantOfShape(self, input, *, value=None) -> np.ndarray:  # noqa: A002
        shape = [int(v) for v in self._folded(input, "input").reshape(-1)]
        fill_value = np.zeros(1, np.float32) if value is None else np.asarray(value).reshape(-1)
        if fill_value.size != 1 or min(shape, default=0) < 0:
            raise self.fail(f"value must hold one element and the shape {shape} be non-negative")
        if math.prod(shape) > MAX_FOLDED_ELEMENTS:
            raise self._too_large(shape)
        return np.full(shape, fill_value[0], fill_value.dtype)

    def Reshape(self, data, shape, *, allowzero=0) -> Any:
        s = [int(v) for v in self._folded(shape, "shape").reshape(-1)]
        if not isinstance(data, np.ndarray):
            return self.reshape_view(self.view(data, "data"), s, allowzero)
        if not allowzero:  # 0 copies the input's dimension
            s = [data.shape[i] if v == 0 and i < data.ndim else v for i, v in enumerate(s)]
        return data.reshape(s)

    def Slice(self, data, starts, ends, axes=None, steps=None) -> np.ndarray:
        d = self._folded(data, "data")
        st, en = (
            self._folded(v, n).astype(np.int64).reshape(-1) for v, n in ((starts, "starts"), (ends, "ends"))
        )
        ax = range(st.size) if axes is None else [int(a) for a in self._folded(axes, "axes").reshape(-1)]
        sp = [1] * st.size if steps is None else [int(v) for v in self._folded(steps, "steps").reshape(-1)]
        index = [slice(None)] * d.ndim
        for a, s, e, k in zip(ax, st, en, sp, strict=True):
            if k == 0:
                raise self.fail("Slice step 0")
            # Python slices clamp out-of-range starts and ends as the ONNX spec does (onnx.reference too).
            index[int(a) % d.ndim] = slice(int(s), int(e), k)
        return d[tuple(index)]

    def Transpose(self, data, *, perm=None) -> Any:
        if not isinstance(data, np.ndarray):
            v = self.view(data, "data")
            order = list(range(len(v.shape)))[::-1] if perm is None else [int(p) % len(v.shape) for p in perm]
            if sorted(order) != list(range(len(v.shape))):
                raise self.fail(f"perm {order} is not a permutation of {len(v.shape)} axes")
            return self.simplify(View(v.texture, transpose(v.axes, order)))
        return np.transpose(data, None if perm is None else [int(p) for p in perm])

    def Cast(self, input, *, to, saturate=1) -> np.ndarray:  # noqa: A002  (saturate: float8 targets only)
        return self._folded(input, "input").astype(onnx.helper.tensor_dtype_to_np_dtype(int(to)))

    def Shape(self, data, *, end=None, start=0) -> np.ndarray:
        """Of an image of static size only: (1, C, H, W), or a view's logical shape."""
        if isinstance(data, np.ndarray):
            return np.asarray(data.shape, np.int64)[start:end]
        if isinstance(data, View):
            return np.asarray(data.shape, np.int64)[start:end]
        t = data.parts[0] if isinstance(data, ConcatValue) else self.image(data, "data")  # no concat pass
        if self.scalar_ranks.get(t.ident, 4) != 4:
            raise self.fail(
                f"Shape of the rank-{self.scalar_ranks[t.ident]} scalar input {t.onnx_name!r} "
                "cannot be folded"
            )
        if t.height.scale != 0 or t.width.scale != 0:
            raise self.fail(
                "Shape of an image of dynamic size cannot be folded; give the input a static size"
            )
        return np.asarray([1, data.channels, t.height.offset, t.width.offset], np.int64)[start:end]

    def Gather(self, data, indices, *, axis=0) -> np.ndarray:
        d, i = self._folded(data, "data"), self._folded(indices, "indices").astype(np.int64)
        return self._small(np.asarray(np.take(d, i, axis=int(axis))))  # 0-d indices give a numpy scalar

    def Unsqueeze(self, data, axes_input=None, *, axes=None) -> np.ndarray:
        """Opset 13+: axes is an input (``axes_input``); before: an attribute."""
        ax = axes if axes_input is None else self._folded(axes_input, "axes").reshape(-1)
        if ax is None:
            raise self.fail("axes is missing")
        if not isinstance(data, np.ndarray):
            v = self.view(data, "data")
            rank = len(v.shape) + len(ax)
            where = sorted(int(a) % rank for a in ax)
            shape, rest = [], iter(v.shape)
            for i in range(rank):
                shape.append(1 if i in where else next(rest))
            return self.reshape_view(v, shape, 1)
        return np.expand_dims(data, tuple(int(a) for a in ax))

    def Squeeze(self, data, axes_input=None, *, axes=None) -> np.ndarray:
        """Opset 13+: axes is an input (``axes_input``); before: an attribute. None: every size-1 axis."""
        ax = axes if axes_input is None else self._folded(axes_input, "axes").reshape(-1)
        if not isinstance(data, np.ndarray):
            v = self.view(data, "data")
            gone = (
                {i for i, n in enumerate(v.shape) if n == 1}
                if ax is None
                else {int(a) % len(v.shape) for a in ax}
            )
            if any(v.shape[i] != 1 for i in gone):
                raise self.fail(f"cannot squeeze axes {sorted(gone)} of shape {v.shape}")
            return self.reshape_view(v, [n for i, n in enumerate(v.shape) if i not in gone], 1)
        return np.squeeze(data) if ax is None else np.squeeze(data, tuple(int(a) for a in ax))

    def Expand(self, input, shape) -> np.ndarray:  # noqa: A002
        d, s = self._folded(input, "input"), [int(v) for v in self._folded(shape, "shape").reshape(-1)]
        out = np.broadcast_shapes(d.shape, tuple(s))
        if math.prod(out) > MAX_FOLDED_ELEMENTS:
            raise self._too_large(list(out))
        return np.broadcast_to(d, out).copy()

    def Tile(self, input, repeats) -> np.ndarray:  # noqa: A002
        d, r = self._folded(input, "input"), [int(v) for v in self._folded(repeats, "repeats").reshape(-1)]
        if math.prod(d.shape) * math.prod(r) > MAX_FOLDED_ELEMENTS:
            raise self._too_large([a * b for a, b in zip(d.shape, r, strict=False)])
        return np.tile(d, r)

    def Range(self, start, limit, delta) -> np.ndarray:
        a, b, k = (
            self._folded(v, n).reshape(()) for v, n in ((start, "start"), (limit, "limit"), (delta, "delta"))
        )
        if k == 0:
            raise self.fail("Range delta 0")
        n = max(int(np.ceil((b - a) / k)), 0)
        if n > MAX_FOLDED_ELEMENTS:
            raise self._too_large([n])
        return (a + np.arange(n, dtype=np.result_type(a, b, k)) * k).astype(np.result_type(a, b, k))


# Activations that can turn a padding lane's finite junk into inf or NaN (which a later conv's zero
# weights would not cancel): their passes zero the padding lanes.
_GUARDED = ("Sqrt", "Log", "Reciprocal", "Exp", "Pow")


def _vec4_rows(v: np.ndarray, n4: int) -> np.ndarray:
    out = np.zeros(n4 * 4, np.float32)
    out[: v.shape[0]] = v
    return out.reshape(n4, 4)


def _pack_conv(p: Pass) -> None:
    """Conv weights as mat4 taps: element (r, c) of tap [oz, ky, kx, l] = W[4oz+r, channel(l, c), ky, kx].
    Depthwise: one vec4 per tap [layer, ky, kx], lane r = W[4 layer + r, 0, ky, kx]."""
    w64, b64 = p.fields.pop("weight64"), p.fields.pop("bias64")
    cout, _, kh, kw = w64.shape
    ol, il = p.output.layers, p.fields["in_layers"]
    if p.kind == "conv_depthwise":
        packed = np.zeros((ol * 4, kh, kw), np.float64)
        packed[:cout] = w64[:, 0]
        taps = packed.reshape(ol, 4, kh, kw).transpose(0, 2, 3, 1)
        p.params = {"weight": taps.reshape(-1, 4).astype(np.float32), "bias": _vec4_rows(b64, ol), **p.params}
        return
    packed = np.zeros((ol * 4, il * 4, kh, kw), np.float64)  # (out padded, in padded by part)
    c0 = 0
    for t, loff in zip(p.inputs, p.fields["layer_offsets"], strict=True):
        packed[:cout, 4 * loff : 4 * loff + t.channels] = w64[:, c0 : c0 + t.channels]
        c0 += t.channels
    # (oz, r, l, c, ky, kx) -> (oz, ky, kx, l, c, r): column c (input lane) of 4 rows r (output lanes)
    taps = packed.reshape(ol, 4, il, 4, kh, kw).transpose(0, 4, 5, 2, 3, 1)
    p.params = {"weight": taps.reshape(-1, 4).astype(np.float32), "bias": _vec4_rows(b64, ol), **p.params}


# ----------------------------------------------------------------------- compute writer


def _resize_coords(p: Pass, d: Dialect) -> list[str]:
    """The source coordinate expression per axis (y, x) for a resize pass."""
    f = p.fields
    coords = []
    for i, (axis, (kind, value)) in enumerate(zip("yx", f["scales"], strict=True)):
        len_in = d.fill("float_of", v=f"in_size.{axis}")
        len_out = d.fill("float_of", v=f"out_size.{axis}")
        scale = (
            d.fill("scale_literal", value=value)
            if kind == "literal"
            else d.fill("scale_ratio", len_out=len_out, len_in=len_in)
        )
        fields = {
            "x": d.fill("float_of", v=f"gid.{axis}"),
            "scale": scale,
            "len_in": len_in,
            "len_out": len_out,
            "start": glsl_float(f["roi"][i]),
            "end": glsl_float(f["roi"][i + 2]),
        }
        tpl = f"coord_{f['coord']}"
        wanted = {
            "coord_half_pixel": ("x", "scale"),
            "coord_asymmetric": ("x", "scale"),
            "coord_pytorch_half_pixel": ("x", "scale", "len_out"),
            "coord_align_corners": ("x", "len_in", "len_out"),
            "coord_half_pixel_symmetric": ("x", "scale", "len_in", "len_out"),
            "coord_tf_crop_and_resize": ("x", "len_in", "len_out", "start", "end"),
        }[tpl]
        coords.append(d.fill(tpl, **{k: fields[k] for k in wanted}))
    return coords


def _resize_body(p: Pass, d: Dialect) -> str:
    f = p.fields
    coord_y, coord_x = _resize_coords(p, d)
    if f["extrapolation"] is None:
        outside = d.fill("resize_inside")
        extrapolation = glsl_float(0.0)
    else:
        outside = d.fill("resize_outside")
        extrapolation = glsl_float(f["extrapolation"])
    common = {"coord_y": coord_y, "coord_x": coord_x, "outside": outside, "extrapolation": extrapolation}
    if p.kind == "resize_linear":
        return d.fill("resize_linear_body", **common)
    if p.kind == "resize_nearest":
        rt = f"round_{f['nearest_mode']}"
        return d.fill("resize_nearest_body", round_y=d.fill(rt, v="fy"), round_x=d.fill(rt, v="fx"), **common)
    weights = []
    for axis, widen in zip("yx", f["widen"], strict=True):
        t = d.fill("filter_arg", i=f"i{axis}", f=f"f{axis}", widen=glsl_float(widen))
        if f["kernel"] == "cubic":
            weights.append(d.fill("kernel_cubic", t=t, a=glsl_float(f["cubic_coeff_a"])))
        else:
            weights.append(d.fill("kernel_linear", t=t))
    exclude = [
        d.fill(f"filter_exclude_{a}") if f["exclude_outside"] else d.fill(f"filter_edge_{a}") for a in "yx"
    ]
    return d.fill(
        "resize_filter_body",
        half_y=f["half"][0],
        half_x=f["half"][1],
        taps_y=2 * f["half"][0],
        taps_x=2 * f["half"][1],
        weight_y=weights[0],
        weight_x=weights[1],
        exclude_y=exclude[0],
        exclude_x=exclude[1],
        **common,
    )


def _conv_body(p: Pass, offs: dict[str, int], d: Dialect) -> str:
    f = p.fields
    (kh, kw), (sy, sx), (dy, dx), pads = f["kernel"], f["strides"], f["dilations"], f["pads"]
    window = {
        "bias_offset": offs["bias"],
        "kh": kh,
        "kw": kw,
        "sy": sy,
        "sx": sx,
        "dy": dy,
        "dx": dx,
        "pad_top": pads[0],
        "pad_left": pads[1],
        "weight_offset": offs["weight"],
    }
    if p.kind == "conv_depthwise":
        return d.fill("conv_depthwise_body", **window)
    parts = _conv_parts(p)
    reads = f.get("reads", ["texel"] * len(parts))
    sizes = "\n".join(_conv_size(i, read, f.get("pad_multiple", 1), d) for i, read in enumerate(reads))
    gathered = p.kind == "conv" and (f["kernel"], f["strides"], f["dilations"], tuple(f["pads"])) == (
        (3, 3),
        (1, 1),
        (1, 1),
        (1, 1, 1, 1),
    )
    loops = "\n".join(
        _conv_input_loop(i, t, read, f["layer_offsets"][i], d)
        for i, (t, read) in enumerate(zip(parts, reads, strict=True))
        if not (gathered and read == "up2")
    )
    if _blocked(p):
        return _conv_block_body(p, window, d)
    if p.kind == "conv_transpose":
        return d.fill(
            "conv_transpose_body", sizes=sizes, tap_stride=4 * f["in_layers"], input_loops=loops, **window
        )
    loop_fields = {k: v for k, v in window.items() if k != "bias_offset"}
    taps = (
        [d.fill("conv_tap_loops", tap_stride=4 * f["in_layers"], input_loops=loops, **loop_fields)]
        if loops
        else []
    )
    taps += [
        _conv_up2_taps(i, t, f["layer_offsets"][i], window["weight_offset"], 4 * f["in_layers"], d)
        for i, (t, read) in enumerate(zip(parts, reads, strict=True))
        if gathered and read == "up2"
    ]
    return d.fill("conv_body", sizes=sizes, taps="\n".join(taps), bias_offset=window["bias_offset"])


def _conv_up2_taps(
    i: int, t: Texture, layer_offset: int, weight_offset: int, tap_stride: int, d: Dialect
) -> str:
    """Input part i of a 3x3 conv (stride 1, pads 1) read upsampled x2: its 9 taps from the 3x3 low texels
    (template conv_up2_taps); the blends in the tap read's order (low column 0 before 1)."""
    fetches = [d.fill("conv_up2_fetch", i=r, j=c, src=f"src{i}") for r in range(3) for c in range(3)]
    # tap k's pair of low columns / rows and weight on the second, even (ox / oy false) and odd
    pairs = {0: ((0, 0), "w0"), 1: ((0, 1), "w1"), 2: ((1, 1), "w0")}
    blends = []

    def pair(first: tuple[int, int], name: str, odd: str, k: int) -> tuple[str, str]:
        even, oddj = first
        if even == oddj:
            return name.format(even), name.format(even + 1)
        pick = lambda a, b: d.fill("pick", cond=odd, a=b, b=a)  # noqa: E731  (odd: the second)
        return pick(name.format(even), name.format(oddj)), pick(name.format(even + 1), name.format(oddj + 1))

    for r in range(3):  # rows of low texels, blended across: h<r><k>
        for k, (cols, w) in pairs.items():
            a, b = pair(cols, f"c{r}{{}}", "ox", k)
            blends.append(
                d.fill("conv_up2_blend", name=f"h{r}{k}", a=a, b=b, w="wx" if w == "w0" else "(1.0 - wx)")
            )
    for ky, (rows, w) in pairs.items():  # tap rows, blended down: u<ky><kx>
        for kx in range(3):
            a, b = pair(rows, f"h{{}}{kx}", "oy", ky)
            blends.append(
                d.fill("conv_up2_blend", name=f"u{ky}{kx}", a=a, b=b, w="wy" if w == "w0" else "(1.0 - wy)")
            )
    valid = {0: ["vy0"], 1: [], 2: ["vy2"]}, {0: ["vx0"], 1: [], 2: ["vx2"]}
    taps = [
        d.fill(
            "conv_up2_tap",
            k=3 * ky + kx,
            tap_stride=tap_stride,
            valid=" && ".join(valid[0][ky] + valid[1][kx]) or "true",
            u=f"u{ky}{kx}",
        )
        for ky in range(3)
        for kx in range(3)
    ]
    return d.fill(
        "conv_up2_taps",
        part=i,
        src=f"src{i}",
        src_size=f"src_size{i}",
        size=f"size{i}",
        wx=d.fill("pick", cond="ox", a="0.75", b="0.25"),
        wy=d.fill("pick", cond="oy", a="0.75", b="0.25"),
        layers=t.layers,
        fetches="\n".join(fetches),
        blends="\n".join(blends),
        weight_offset=weight_offset,
        layer_offset=layer_offset,
        tap_stride=tap_stride,
        taps="\n".join(taps),
    )


def _conv_size(i: int, read: str, multiple: int, d: Dialect) -> str:
    """Declares ``size<i>``, the size of conv input part i as the conv sees it (see :data:`CONV_READS`)."""
    if read == "texel":
        return d.fill("size_decl", size=f"size{i}", src=f"src{i}")
    source = d.fill("size_decl", size=f"src_size{i}", src=f"src{i}")
    pad = {"below": multiple - 1, "multiple": multiple} if read == "reflect" else {}
    return source + "\n" + d.fill(CONV_READS[read][1], size=f"size{i}", src_size=f"src_size{i}", **pad)


def _conv_input_loop(i: int, t: Texture, read: str, layer_offset: int, d: Dialect) -> str:
    """The accumulation over conv input part i (texture src<i>, read as :data:`CONV_READS` says)."""
    if read == "texel":
        return d.fill(
            "conv_input_loop", size=f"size{i}", layers=t.layers, src=f"src{i}", layer_offset=layer_offset
        )
    sizes = {"src_size": f"src_size{i}"} | ({"size": f"size{i}"} if read == "reflect" else {})
    setup = d.fill(f"conv_setup_{read}", src=f"src{i}", **({} if read == "pool2" else sizes))
    return d.fill(
        "conv_input_loop_fused",
        size=f"size{i}",
        layers=t.layers,
        layer_offset=layer_offset,
        setup=setup,
        read=_conv_read_expr(i, t, read, d),
    )


def _conv_read_expr(i: int, t: Texture, read: str, d: Dialect) -> str:
    """The vec4 that conv input part i contributes at (ix, iy), layer l, in mode ``read``."""
    if read == "reflect" and t.channels % 4:  # the pad pass's guard: lanes past the last channel are 0
        return d.fill("conv_read_reflect_guard", src=f"src{i}", channels=t.channels)
    return d.fill(f"conv_read_{read}", src=f"src{i}")


def _conv_parts(p: Pass) -> list[Texture]:
    """The inputs a conv pass convolves (a concatenation's parts); inputs after them are the other
    operands of fused two-image ops (epilogue form "binary")."""
    return p.inputs[: len(p.fields.get("layer_offsets", [0]))]


def _blocked(p: Pass) -> bool:
    """A dense conv pass whose invocation computes more than one texel of one layer (fields["block"],
    set for every dense conv by :func:`generate_compute`)."""
    return p.kind == "conv" and p.fields["block"] != (1, 1, 1)


def _conv_block_body(p: Pass, window: dict, d: Dialect) -> str:
    """A conv whose invocation computes a block of texels x output layers (fields["block"])."""
    f = p.fields
    bx, by, bl = f["block"]
    texels = bx * by
    acc = [d.fill("conv_block_bias", o=o, bias_offset=window["bias_offset"]) for o in range(bl)]
    sep = d.fill("conv_block_acc_sep")
    acc += [
        d.fill(
            "conv_block_acc", names=sep.join(d.fill("conv_block_acc_name", o=o, p=k) for k in range(texels))
        )
        for o in range(bl)
    ]
    coords = "\n".join(
        d.fill("conv_block_coord", p=k, qx=(k % bx) * window["sx"], qy=(k // bx) * window["sy"])
        for k in range(texels)
    )
    layer_stride = window["kh"] * window["kw"] * 4 * f["in_layers"]  # vec4s between output layers' taps
    loops = []
    for i, t in enumerate(_conv_parts(p)):
        fetches = "\n".join(d.fill("conv_block_fetch", p=k, src=f"src{i}") for k in range(texels))
        products = []
        for o in range(bl):
            products.append(d.fill("conv_block_weight", o=o, off=o * layer_stride))
            for k0 in range(0, texels, 4):  # four accumulations a line
                fmas = " ".join(d.fill("conv_block_fma", o=o, p=k) for k in range(k0, min(k0 + 4, texels)))
                products.append(d.fill("conv_block_fmas", fmas=fmas))
        loops.append(
            d.fill(
                "conv_block_input_loop",
                layers=t.layers,
                layer_offset=f["layer_offsets"][i],
                fetches=fetches,
                products="\n".join(products),
            )
        )
    return d.fill(
        "conv_block_body",
        acc_init="\n".join(acc),
        kh=window["kh"],
        kw=window["kw"],
        weight_offset=window["weight_offset"],
        tap_stride=4 * f["in_layers"],
        sx=window["sx"],
        sy=window["sy"],
        dx=window["dx"],
        dy=window["dy"],
        pad_left=window["pad_left"],
        pad_top=window["pad_top"],
        coords=coords,
        input_loops="\n".join(loops),
    )


def _lp_steps(p: float, d: Dialect) -> tuple[str, str]:
    """(accumulate, finish) templates of an Lp pool."""
    if p == 1:
        return d.fill("pool_acc_l1"), d.fill("pool_finish_l1")
    if p == 2:
        return d.fill("pool_acc_l2"), d.fill("pool_finish_l2")
    return d.fill("pool_acc_lp", p=glsl_float(p)), d.fill("pool_finish_lp", inv_p=glsl_float(1.0 / p))


def _pool_body(p: Pass, d: Dialect) -> str:
    f = p.fields
    (kh, kw), (sy, sx), (dy, dx), pads = f["kernel"], f["strides"], f["dilations"], f["pads"]
    if p.kind == "pool_max":
        init, acc, finish = d.fill("pool_init_max"), d.fill("pool_acc_max"), d.fill("pool_finish_none")
    elif p.kind == "pool_lp":
        init, (acc, finish) = d.fill("pool_init_lp"), _lp_steps(f["p"], d)
    else:
        init, acc = d.fill("pool_init_avg"), d.fill("pool_acc_avg")
        finish = d.fill("pool_finish_padded") if f["include_pad"] else d.fill("pool_finish_count")
    return d.fill(
        "pool_body",
        init=init,
        kh=kh,
        kw=kw,
        sy=sy,
        sx=sx,
        dy=dy,
        dx=dx,
        pad_top=pads[0],
        pad_left=pads[1],
        pad_bottom=pads[2],
        pad_right=pads[3],
        accumulate=acc,
        finish=finish,
    )


def _binary_body(p: Pass, d: Dialect) -> str:
    f = p.fields
    fetch = [d.fill(f"fetch_{how}", src=f"src{i}") for i, how in enumerate(f["fetch"])]
    guard = (
        d.fill("binary_guard_div", channels=p.output.channels)
        if f["op"] == "Div"
        else d.fill("binary_guard_none")
    )
    return d.fill(
        "binary_body", fetch_a=fetch[0], fetch_b=fetch[1], guard=guard, expr=d.fill(f"binop_{f['op']}")
    )


def _pointwise_body(p: Pass, offs: dict[str, int], d: Dialect) -> str:
    """A pointwise group (:func:`_inline_pointwise`): each member, in graph order, computes every layer
    of its output at this texel into a local array ``v<k>``, reading the pass's inputs (src<i>) or an
    earlier member's array; the pass stores layer gid.z of the last. 1x1 convs accumulate in fp32."""
    members, inputs = p.fields["members"], [t.ident for t in p.inputs]
    made: dict[str, int] = {}
    lines = []
    reflected = p.fields.get("reflected")  # the padded input, read from the raw one (src<k>) by reflection
    if reflected:
        k = p.fields["reads"].index("reflect")
        lines += [
            d.fill("size_decl", size=f"src_size{k}", src=f"src{k}"),
            d.fill(
                CONV_READS["reflect"][1],
                size=f"size{k}",
                src_size=f"src_size{k}",
                below=p.fields["pad_multiple"] - 1,
                multiple=p.fields["pad_multiple"],
            ),
            d.fill("pointwise_reflect_setup", src=f"src{k}", src_size=f"src_size{k}", size=f"size{k}"),
        ]

    def operand(t: Texture, how: str, layer: int) -> str:
        if t.ident in made:
            k = made[t.ident]
            return f"v{k}[0].xxxx" if how == "channel" else f"v{k}[{layer}]"
        if t.ident == reflected:
            k, layer = p.fields["reads"].index("reflect"), 0 if how == "channel" else layer
            raw = p.inputs[k]
            guard = {"channels": raw.channels} if raw.channels % 4 else {}
            texel = d.fill(
                "pointwise_reflect_guard" if guard else "pointwise_reflect",
                src=f"src{k}",
                layer=layer,
                **guard,
            )
            return texel + (".xxxx" if how == "channel" else "")
        at = {"full": {"xy": "gid.xy", "z": layer}, "pixel": {"z": layer}, "channel": {"xy": "gid.xy"}}
        return d.fill(f"side_{how}", src=f"src{inputs.index(t.ident)}", **at.get(how, {}))

    for k, m in enumerate(members):
        own = {name: offs[f"m{k}_{name}"] for name in m.params}
        lines.append(d.fill("pointwise_array", name=f"v{k}", n=m.output.layers))
        for layer in range(m.output.layers):
            if m.kind == "conv":
                tap = own["weight"] + layer * 4 * m.fields["in_layers"]
                terms = [
                    d.fill("pointwise_conv_term", o=tap + 4 * (off + j), x=operand(t, "full", j))
                    for t, off in zip(_conv_parts(m), m.fields["layer_offsets"], strict=True)
                    for j in range(t.layers)
                ]
                body = d.fill("pointwise_conv", bias=own["bias"] + layer, terms="\n".join(terms))
            elif m.kind == "binary":
                a, b = (operand(t, how, layer) for t, how in zip(m.inputs, m.fields["fetch"], strict=True))
                guard = (
                    d.fill("epilogue_guard_div", channels=m.output.channels, z=layer)
                    if m.fields["op"] == "Div"
                    else d.fill("binary_guard_none")
                )
                body = d.fill(
                    "binary_body", fetch_a=a, fetch_b=b, guard=guard, expr=d.fill(f"binop_{m.fields['op']}")
                )
            else:
                body = d.fill("pointwise_copy", x=operand(m.inputs[0], "full", layer))
            epi = _epilogue(
                m,
                own,
                "gid.xy",
                str(layer),
                d,
                side=lambda e, m=m, layer=layer: operand(m.inputs[e.side[0]], e.side[1], layer),
            )
            lines.append(d.fill("pointwise_layer", body=body, epilogue=epi, name=f"v{k}", layer=layer))
        made[m.output.ident] = k
    lines.append(d.fill("pointwise_result", name=f"v{len(members) - 1}"))
    return "\n".join(lines)


def _gather_body(p: Pass, d: Dialect) -> str:
    digits = []
    for run in p.fields["digits"]:
        lines = []
        for i, (axis, size, stride) in enumerate(reversed(run)):  # innermost first
            coord = {"c": "z", "y": "y", "x": "x"}[axis]
            last = i == len(run) - 1
            lines.append(
                d.fill("gather_digit_last", coord=coord, stride=stride)
                if last
                else d.fill("gather_digit", coord=coord, size=size, stride=stride)
            )
        digits.append("\n".join(lines))
    return d.fill(
        "gather_body", channels=p.output.channels, digits_c=digits[0], digits_y=digits[1], digits_x=digits[2]
    )


def _window_bounds(spatial: tuple[bool, bool]) -> dict[str, str]:
    """The member loops' pixel range: the whole image on a reduced axis, else the output texel's own."""
    out = {}
    for axis, reduced in zip("yx", spatial, strict=True):
        out[f"{axis}_begin"] = "0" if reduced else f"gid.{axis}"
        out[f"{axis}_end"] = f"in_size.{axis}" if reduced else f"gid.{axis} + 1"
    return out


_REDUCE_STEPS = {
    "Sum": ("zero", "sum", "none"),
    "Mean": ("zero", "sum", "mean"),
    "Max": ("max", "max", "none"),
    "Min": ("min", "min", "none"),
    "L1": ("zero", "abs", "none"),
    "L2": ("zero", "square", "sqrt"),
    "SumSquare": ("zero", "square", "none"),
    "Prod": ("one", "prod", "none"),
    "LogSum": ("zero", "sum", "log"),
}


def _reduce_body(p: Pass, offs: dict[str, int], d: Dialect) -> str:
    f = p.fields
    init, acc, finish = _REDUCE_STEPS[f["op"]]
    bounds = _window_bounds(f["spatial"])
    base, offsets = f["tables"]
    loops = d.fill(
        "member_loops",
        members=f["members"],
        offsets_offset=offs[offsets],
        statement=d.fill(f"reduce_acc_{acc}"),
        **bounds,
    )
    return d.fill(
        "reduce_body",
        groups=f["groups"],
        base_offset=offs[base],
        members=f["members"],
        init=d.fill(f"reduce_init_{init}"),
        loops=loops,
        finish=d.fill(f"reduce_finish_{finish}"),
        **bounds,
    )


def _moments_body(p: Pass, offs: dict[str, int], d: Dialect) -> str:
    f = p.fields
    bounds = _window_bounds(f["spatial"])
    base, offsets = f["tables"]
    loops = [
        d.fill(
            "member_loops",
            members=f["members"],
            offsets_offset=offs[offsets],
            statement=d.fill(acc),
            **bounds,
        )
        for acc in ("reduce_acc_sum", "moments_acc_square")
    ]
    return d.fill(
        "moments_body",
        channels=p.output.channels,
        groups=f["groups"],
        base_offset=offs[base],
        members=f["members"],
        sum_loops=loops[0],
        square_loops=loops[1],
        epsilon=glsl_float(f["epsilon"]),
        **bounds,
    )


def _normalize_body(p: Pass, offs: dict[str, int], d: Dialect) -> str:
    f = p.fields
    sy, sx = ("0" if reduced else f"gid.{axis}" for axis, reduced in zip("yx", f["spatial"], strict=True))
    return d.fill("normalize_body", group_offset=offs[f["group"]], groups=f["groups"], stats_x=sx, stats_y=sy)


def _softmax_body(p: Pass, offs: dict[str, int], d: Dialect) -> str:
    f = p.fields
    base, offsets = f["tables"]
    return d.fill(
        "softmax_body",
        channels=p.output.channels,
        base_offset=offs[base],
        offsets_offset=offs[offsets],
        members=f["members"],
        finish=d.fill("log_softmax_finish" if f["log"] else "softmax_finish"),
    )


def _lrn_body(p: Pass, d: Dialect) -> str:
    f = p.fields
    return d.fill(
        "lrn_body",
        channels=p.output.channels,
        before=f["before"],
        after=f["after"],
        bias=glsl_float(f["bias"]),
        alpha=glsl_float(f["alpha"]),
        beta=glsl_float(f["beta"]),
    )


def _spatial_pad_body(p: Pass, d: Dialect) -> str:
    f = p.fields
    mode = (
        d.fill("pad_constant", value=glsl_float(f["value"]))
        if f["mode"] == "constant"
        else d.fill(f"pad_{f['mode']}")
    )
    return d.fill("spatial_pad_body", top=f["pads"][0], left=f["pads"][1], mode=mode)


def _write_compute_pass(p: Pass, precision: str, local_size: tuple[int, int], d: Dialect) -> str:
    """One pass's shader source in dialect ``d`` (GLSL 4.30 compute, WGSL or Vulkan GLSL)."""
    fmt = "rgba16f" if precision == "fp16" and not _fp32_output(p) else "rgba32f"
    slots = d.compute_slots(len(p.inputs))
    decls = [d.fill("sampler_array_decl", binding=i, name=f"src{i}") for i in range(len(p.inputs))]
    decls.append(d.fill("image_array_decl", binding=slots["output"], format=d.fill(f"storage_format_{fmt}")))
    if p.params:
        decls.append(d.fill("params_decl", binding=slots["params"]))
    if _flips(p):
        decls.append(d.fill("uniform_int_decl", slot=slots["uniform"], name="u_flip_y"))
    if p.kind == "uniform":
        slot = p.fields["location"] if d.name == "glsl430" else slots["uniform"]
        decls.append(d.fill("uniform_float_decl", slot=slot, name=p.fields["uniform"]))
    offs = p.param_offsets()
    if p.kind in CONV_KINDS:
        body = _conv_body(p, offs, d)
    elif p.kind in ("pool_avg", "pool_max", "pool_lp"):
        body = _pool_body(p, d)
    elif p.kind in ("global_pool_avg", "global_pool_max", "global_pool_lp"):
        if p.kind == "global_pool_max":
            init, acc, finish = d.fill("pool_init_max"), d.fill("pool_acc_max"), d.fill("pool_finish_none")
        elif p.kind == "global_pool_lp":
            init, (acc, finish) = d.fill("pool_init_lp"), _lp_steps(p.fields["p"], d)
        else:
            init, acc, finish = d.fill("pool_init_avg"), d.fill("pool_acc_avg"), d.fill("global_finish_mean")
        body = d.fill("global_pool_body", init=init, accumulate=acc, finish=finish)
    elif p.kind.startswith("resize"):
        body = _resize_body(p, d)
    elif p.kind == "concat":
        branches, begin = [], 0
        for i, t in enumerate(p.inputs):
            branches.append(d.fill("concat_branch", begin=begin, end=begin + t.channels, src=f"src{i}"))
            begin += t.channels
        body = d.fill("concat_body", branches="\n".join(branches))
    elif p.kind == "elementwise":
        body = d.fill("elementwise_body")
    elif p.kind == "binary":
        body = _binary_body(p, d)
    elif p.kind == "pointwise":
        body = _pointwise_body(p, offs, d)
    elif p.kind == "spatial_pad":
        body = _spatial_pad_body(p, d)
    elif p.kind == "pad":
        body = d.fill("pad_reflect_body")
    elif p.kind == "crop":
        body = d.fill("crop_body")
    elif p.kind == "uniform":
        body = d.fill("uniform_body", name=p.fields["uniform"])
    elif p.kind == "gather":
        body = _gather_body(p, d)
    elif p.kind == "reduce":
        body = _reduce_body(p, offs, d)
    elif p.kind == "moments":
        body = _moments_body(p, offs, d)
    elif p.kind == "normalize":
        body = _normalize_body(p, offs, d)
    elif p.kind == "softmax":
        body = _softmax_body(p, offs, d)
    elif p.kind == "lrn":
        body = _lrn_body(p, d)
    else:  # pragma: no cover - kinds are created above only
        raise AssertionError(p.kind)
    prelude = [d.fill("prelude")]
    if p.kind.startswith("resize"):
        prelude.append(d.fill("prelude_div"))
    if p.kind == "resize_filter" and p.fields["kernel"] == "cubic":
        prelude.append(d.fill("prelude_cubic"))
    if any(m.fields.get("erf") for m in _members(p)):
        prelude.append(d.fill("prelude_erf"))
    epi = _epilogue(p, offs, "gid.xy", "gid.z", d)
    if _blocked(p):
        bx, by, bl = p.fields["block"]
        stores = [
            d.fill("conv_block_store", px=k % bx, py=k // bx, o=o, p=k)
            for o in range(bl)
            for k in range(bx * by)
        ]
        epi_z = "\n".join("    " + line for line in _epilogue(p, offs, "xy", "z", d).split("\n"))
        return d.fill(
            "compute_pass_block",
            header=d.header(),
            pass_index=p.index,
            summary=" + ".join(p.ops),
            block_x=bx,
            block_y=by,
            block_layers=bl,
            local_x=local_size[0],
            local_y=local_size[1],
            prelude="\n\n".join(prelude),
            declarations="\n".join(decls),
            epilogue=epi_z,
            body=body,
            stores="\n".join(stores),
            arithmetic=d.fill(f"arithmetic_{precision}"),
            store_xy=_store_xy(p, "xy", d.fill("dst_size"), d),
        )
    return d.fill(
        "compute_pass",
        header=d.header(),
        pass_index=p.index,
        summary=" + ".join(p.ops),
        local_x=local_size[0],
        local_y=local_size[1],
        prelude="\n\n".join(prelude),
        declarations="\n".join(decls),
        out_layers=p.output.layers,
        body=body,
        epilogue=epi,
        arithmetic=d.fill(f"arithmetic_{precision}"),
        store_xy=_store_xy(p, "gid.xy", "out_size", d),
    )


def _fp32_output(p: Pass) -> bool:
    """The pass writes an RGBA32F texture whatever the precision: a cropped output, a scalar input, a
    texture computed from the input pixel by pixel (:func:`_mark_input_derived`)."""
    return p.kind in FP32_KINDS or p.output.base == "raw" or bool(p.fields.get("input_derived"))


# Passes that combine values of one pixel only (a 1x1 conv too): what they compute from the input is
# still the input, at its precision.
PER_PIXEL_KINDS = ("pad", "spatial_pad", "crop", "uniform", "elementwise", "binary", "pointwise", "concat")


def _mark_input_derived(table) -> None:
    """Mark (``fields["input_derived"]``) each pass that computes its output from the graph's inputs pixel
    by pixel, through such passes only: the padded input, log depth, the radius channel. At fp16 they
    keep RGBA32F, as the input does: neighbours' depths differ by far less than half a float's rounding
    of the depth itself (2^-11 relative), and the first spatial conv reads exactly those differences."""
    derived = {t.ident for p in table.passes for t in p.inputs if t.base == "raw"}
    for p in table.passes:
        per_pixel = p.kind in PER_PIXEL_KINDS or (p.kind == "conv" and tuple(p.fields["kernel"]) == (1, 1))
        if per_pixel and all(t.ident in derived for t in p.inputs):
            p.fields["input_derived"] = True
            derived.add(p.output.ident)


def _flips(p: Pass) -> bool:
    """The pass reads or writes an engine's texture, which may be stored bottom-up (uniform u_flip_y):
    the pad and crop passes, a pass the crop was fused into and a conv reading the input as the pad would."""
    reflects = "reflect" in p.fields.get("reads", ())
    return p.kind in ("pad", "crop") or bool(p.fields.get("flip_store")) or reflects


def _store_xy(p: Pass, xy: str, size: str, d: Dialect) -> str:
    """Where texel ``xy`` is stored: itself, or row-flipped when a crop was fused into the pass."""
    return d.fill("flip_xy", xy=xy, size=size) if p.fields.get("flip_store") else xy


def _side_operand(e: Epilogue, xy: str, z: str, d: Dialect) -> str:
    """The other operand of a fused two-image op at output texel ``xy``, layer ``z``."""
    index, how = e.side[0], e.side[1]
    at = {"full": {"xy": xy, "z": z}, "pixel": {"z": z}, "channel": {"xy": xy}, "scalar": {}}[how]
    return d.fill(f"side_{how}", src=f"src{index}", **at)


def _epilogue(p: Pass, offs: dict[str, int], xy: str, z: str, d: Dialect, side=None) -> str:
    """The pass's per-texel epilogue on ``r``; ``xy`` and ``z`` are the expressions of the output texel
    and layer; ``side(e)``, where given, spells a fused two-image op's other operand (a pointwise
    group's member reads it from an earlier member)."""
    epi = []
    for e in p.epilogue:
        if e.form == "binary":
            _, _, op, r_is = e.side
            other = side(e) if side else _side_operand(e, xy, z, d)
            a, b = ("r", other) if r_is == 0 else (other, "r")
            guard = (
                d.fill("epilogue_guard_div", channels=p.output.channels, z=z)
                if op == "Div"
                else d.fill("binary_guard_none")
            )
            epi.append(d.fill("epilogue_binary", a=a, b=b, guard=guard, expr=d.fill(f"binop_{op}")))
        elif e.form == "act":
            epi.append(d.fill("epilogue_act", expr=e.act.expr("r", d.fill)))
        elif e.form == "affine":
            epi.append(
                d.fill("epilogue_affine", scale_offset=offs[e.arrays[0]], shift_offset=offs[e.arrays[1]], z=z)
            )
        elif e.form == "prelu":
            epi.append(d.fill("epilogue_prelu", slope_offset=offs[e.arrays[0]], z=z))
        elif e.form == "guard":
            epi.append(d.fill("epilogue_guard", channels=p.output.channels, z=z))
        else:
            epi.append(d.fill("epilogue_rdiv", offset=offs[e.arrays[0]], channels=p.output.channels, z=z))
    return "\n".join(epi) if epi else d.fill("epilogue_none")


@dataclass
class ComputeProgram:
    """Generated compute passes for an image network.

    sources : {shader file name: GLSL 4.30 compute source (or WGSL, Vulkan GLSL)}, in pass order;
    weights : the bytes of weights.bin (float32 little-endian, each pass's range aligned to 256 bytes);
    manifest : dict (passes, textures, weights, pad/crop, the scalar inputs' ``uniforms``; see
    :func:`write_compute_export`); spirv : {shader file name: SPIR-V words as bytes} of a Vulkan
    program read back from an export that holds them (empty otherwise: the generator writes source).
    """

    sources: dict[str, str]
    weights: bytes
    manifest: dict
    spirv: dict[str, bytes] = field(default_factory=dict)

    @property
    def pad_multiple(self) -> int:
        return int(self.manifest["pad"]["multiple"])

    @property
    def precision(self) -> str:
        return str(self.manifest["precision"])


def _image_shape(shape: list[int]) -> list[int]:
    """A (1, C, H, W) shape whose elements, row-major, are those of ``shape`` in order."""
    if len(shape) > 4:
        return [1, math.prod(shape[:-2]), shape[-2], shape[-1]]
    if shape and shape[0] == 1:
        return shape + [1] * (4 - len(shape))
    return [1] + shape + [1] * (3 - len(shape))


def _pad_multiple(table: ImageOps) -> int:
    required = math.lcm(*table.denominators)
    meta = table.metadata_multiple
    if table.static:
        return 1
    if meta is None:
        return required
    if meta % required:
        raise NeuralaoError(
            f"metadata pad_multiple {meta} is not a multiple of {required}, which the graph needs"
        )
    return meta


def _conv_block(block: tuple[int, int, int], layers: int) -> tuple[int, int, int]:
    """(texels x, texels y, output layers) per invocation of a conv pass: the layer count is the
    largest divisor of ``layers`` not above the requested one (every invocation fills whole layers)."""
    bx, by, bl = (int(v) for v in block)
    if bx < 1 or by < 1 or bl < 1 or bx * by * bl > MAX_BLOCK_ACCUMULATORS:
        raise NeuralaoError(
            f"conv block {list(block)} must be positive with at most {MAX_BLOCK_ACCUMULATORS} accumulators"
        )
    return bx, by, max(d for d in range(1, min(bl, layers) + 1) if layers % d == 0)


# Two-image ops an epilogue can apply (templates binop_<op>) and the pass kinds a crop folds into: those
# whose body reads no out_size (the crop makes the output the raw size).
_FUSED_BINOPS = ("Add", "Sub", "Mul", "Div", "Max", "Min")
_CROP_INTO = (*CONV_KINDS, "binary", "elementwise", "pointwise")


# How a dense conv reads an input part (fields["reads"], one per part; absent: all "texel"): mode ->
# (what the conv sees, the template of its size from the source's). "pool2", "up2" and "reflect" are
# passes fused into the conv (:func:`_fuse_read`): templates conv_setup_<mode> and conv_read_<mode>.
CONV_READS: dict[str, tuple[str, str]] = {
    "texel": ("the texture itself", "size_decl"),
    "pool2": ("AveragePool 2x2 stride 2 of the texture", "size_halved"),
    "up2": ("Resize x2 linear half_pixel of the texture", "size_doubled"),
    "reflect": ("the network's input reflect-padded, as the pad pass would (u_flip_y)", "size_padded"),
}


def _readers(table: ImageOps, t: Texture) -> list[Pass]:
    return [q for q in table.passes if any(i.ident == t.ident for i in q.inputs)]


def _drop(table: ImageOps, gone: Pass, texture: Texture) -> None:
    table.passes.remove(gone)
    table.textures = [t for t in table.textures if t.ident != texture.ident]


def _fuse_binary(table: ImageOps, b: Pass) -> str | None:
    """Fold binary pass ``b`` into the conv producing one operand when b alone reads that output and
    the other operand exists before the conv runs: the conv's epilogue applies the op (form "binary")."""
    if b.fields["op"] not in _FUSED_BINOPS:
        return None
    index = {p.output.ident: k for k, p in enumerate(table.passes)}
    for k in (0, 1):
        t, other = b.inputs[k], b.inputs[1 - k]
        p = table.passes[index[t.ident]] if t.ident in index else None
        if p is None or p.kind not in CONV_KINDS or b.fields["fetch"][k] != "full" or t.ident == other.ident:
            continue
        if _readers(table, t) != [b] or index.get(other.ident, -1) > index[t.ident]:
            continue
        p.inputs.append(other)
        p.epilogue.append(
            Epilogue(form="binary", side=(len(p.inputs) - 1, b.fields["fetch"][1 - k], b.fields["op"], k))
        )
        p.epilogue += b.epilogue
        p.params.update(b.params)
        p.ops += b.ops
        p.nodes += b.nodes
        p.output = b.output
        _drop(table, b, t)
        return f"{' + '.join(b.ops)} into the conv producing its operand {t.ident}"
    return None


def _doubled(big: Texture, small: Texture) -> bool:
    """``big`` is exactly twice ``small`` on both axes, whatever the input size."""
    return all(
        b.scale == 2 * a.scale and b.offset == 2 * a.offset
        for b, a in ((big.height, small.height), (big.width, small.width))
    )


def _conv_read(q: Pass) -> str | None:
    """The :data:`CONV_READS` mode in which a conv can read the output of pass ``q`` straight from q's
    input, or None. Only the exact ops the read templates implement: AveragePool 2x2 stride 2 without
    pads on an input twice its output (every window whole, so ceil_mode and count_include_pad change
    nothing); Resize linear half_pixel to exactly twice its input (scale 2, given or from sizes)."""
    f, x = q.fields, q.inputs[0] if q.inputs else None
    if q.epilogue or x is None:
        return None
    if q.kind == "pool_avg":
        window = (f["kernel"], f["strides"], f["dilations"], tuple(f["pads"]))
        if window == ((2, 2), (2, 2), (1, 1), (0, 0, 0, 0)) and _doubled(x, q.output):
            return "pool2"
    if q.kind == "resize_linear" and f["coord"] == "half_pixel" and _doubled(q.output, x):
        if all(s in (("literal", glsl_float(2.0)), ("ratio", "")) for s in f["scales"]):
            return "up2"
    return None


def _reads_in_place(r: Pass, t: Texture) -> bool:
    """Conv pass ``r`` convolves texture ``t`` (as one of its parts, read texel by texel) and reads it
    nowhere else; one texel of one layer per invocation (the gpu preset's conv)."""
    if r.kind != "conv" or _blocked(r):
        return False
    parts = _conv_parts(r)
    reads = r.fields.get("reads", ["texel"] * len(parts))
    here = [k for k, u in enumerate(parts) if u.ident == t.ident]
    others = r.inputs[len(parts) :]
    return bool(here) and all(reads[k] == "texel" for k in here) and all(u.ident != t.ident for u in others)


def _group_reads_at_texel(r: Pass, t: Texture) -> bool:
    """Pointwise group ``r`` reads texture ``t`` only at its own texel (full or channel fetches)."""
    if r.kind != "pointwise" or "reflected" in r.fields or t.ident not in [u.ident for u in r.inputs]:
        return False
    return all(h in ("full", "channel") for m in _members(r) for h in _reads(m, t))


def _fuse_read(table: ImageOps, q: Pass, multiple: int, groups: bool = False) -> str | None:
    """Fold pass ``q`` (a pool, a resize, the pad pass) into the convs that read its output (all of its
    readers must be): each reads q's input through the average, the bilinear sample or the reflection
    (fields["reads"]; the pad's ``multiple`` in fields["pad_multiple"]). ``groups``: the pad's readers
    may also be pointwise groups (once no group changes any more: a group's members name the padded
    texture)."""
    # the pad's guard (lanes past the last channel zeroed) the reflect read repeats; nothing else
    pad_plain = q.kind == "pad" and all(e.form == "guard" for e in q.epilogue)
    mode = ("reflect" if pad_plain else None) if q.kind == "pad" else _conv_read(q)
    t = q.output
    readers = _readers(table, t)
    if mode is None or not readers:
        return None
    if not all(
        _reads_in_place(r, t) or (groups and mode == "reflect" and _group_reads_at_texel(r, t))
        for r in readers
    ):
        return None
    for r in readers:
        if r.kind == "pointwise":  # its members' texel of t, read reflected from q's input
            k = [u.ident for u in r.inputs].index(t.ident)
            r.inputs[k] = q.inputs[0]
            r.fields["reads"] = ["texel"] * len(r.inputs)
            r.fields["reads"][k] = "reflect"
            r.fields["reflected"] = t.ident
            r.fields["pad_multiple"] = multiple
            r.ops[:0] = q.ops
            r.nodes[:0] = q.nodes
            continue
        reads = r.fields.setdefault("reads", ["texel"] * len(_conv_parts(r)))
        for k, u in enumerate(_conv_parts(r)):
            if u.ident == t.ident:
                r.inputs[k] = q.inputs[0]
                reads[k] = mode
        r.ops[:0] = q.ops
        r.nodes[:0] = q.nodes
        if mode == "reflect":
            r.fields["pad_multiple"] = multiple
    _drop(table, q, t)
    return f"{' + '.join(q.ops)} into the conv(s) reading {t.ident} (read from {q.inputs[0].ident})"


def _fuse_crop(table: ImageOps, c: Pass) -> str | None:
    """Fold crop pass ``c`` into the pass producing its input when c alone reads it: that pass writes
    the raw-size output (row-flipped by u_flip_y) instead of the padded texture."""
    t = c.inputs[0]
    p = next((q for q in table.passes if q.output.ident == t.ident), None)
    if p is None or p.kind not in _CROP_INTO or p.fields.get("flip_store") or _readers(table, t) != [c]:
        return None
    p.fields["flip_store"] = True
    p.output = c.output
    p.ops.append("Crop")
    _drop(table, c, t)
    return f"Crop into the {p.kind} pass producing {t.ident}"


# A pass inlined into its readers may add at most this many vec4 operations (a 1x1 conv's mat4 tap
# counting 4) to each texel a reader computes (all its layers): the producers of a network's input
# assembly (masks, depth ratios, the radius channel) qualify, a wide 1x1 conv does not. A 3x3 conv from
# 8 to 8 channels is 144 per texel.
POINTWISE_INLINE_COST = 64


def _pointwise(p: Pass) -> bool:
    """Each output texel of ``p`` depends only on its inputs' texels at the same position (or on 1x1
    inputs): an elementwise or two-image pass, a 1x1 stride-1 conv reading texels in place, or a
    pointwise group (kind "pointwise") of them."""
    f = p.fields
    if p.output.base != "padded" and not f.get("flip_store"):  # raw: only as the crop fused into p
        return False
    if p.kind in ("pointwise", "elementwise", "binary"):
        return True
    return (
        p.kind == "conv"
        and f["kernel"] == (1, 1)
        and f["strides"] == (1, 1)
        and not any(f["pads"])
        and not _blocked(p)
        and set(f.get("reads", ["texel"])) == {"texel"}
    )


def _members(p: Pass) -> list[Pass]:
    return p.fields["members"] if p.kind == "pointwise" else [p]


def _reads(m: Pass, t: Texture) -> list[str]:
    """How member ``m`` reads texture ``t``: full | channel | pixel | scalar, one entry per read."""
    if m.kind == "binary":
        how = [h for u, h in zip(m.inputs, m.fields["fetch"], strict=True) if u.ident == t.ident]
    else:
        how = [
            "full"
            for u in (m.inputs[:1] if m.kind == "elementwise" else _conv_parts(m))
            if u.ident == t.ident
        ]
    return how + [
        e.side[1] for e in m.epilogue if e.form == "binary" and m.inputs[e.side[0]].ident == t.ident
    ]


def _cost(p: Pass) -> int:
    """vec4 operations per texel of all of ``p``'s output layers (see :data:`POINTWISE_INLINE_COST`)."""
    return sum(m.output.layers * (4 * m.fields["in_layers"] if m.kind == "conv" else 1) for m in _members(p))


def _inline_pointwise(table: ImageOps, p: Pass, order: dict[int, int]) -> str | None:
    """Compute pointwise pass ``p`` inside each of its readers when all of them are pointwise passes of
    its size that read it texel by texel: every reader becomes a pointwise group holding p's members
    (recomputed per reader, so no texture, dispatch or barrier is left for p). ``order``: id(pass) ->
    position in the graph, which orders a group's members."""
    t = p.output
    readers = _readers(table, t)
    if not _pointwise(p) or p.fields.get("flip_store") or not readers:
        return None
    for r in readers:  # a full or channel fetch reads t at the reader's texel (t is its size)
        if not _pointwise(r) or any(h not in ("full", "channel") for m in _members(r) for h in _reads(m, t)):
            return None
        if _cost(p) * r.output.layers > POINTWISE_INLINE_COST:
            return None
    for r in readers:
        members = {id(m): m for m in _members(p) + _members(r)}
        kept = sorted(members.values(), key=lambda m: order[id(m)])
        made = {m.output.ident for m in kept}
        inputs = list({u.ident: u for m in kept for u in m.inputs if u.ident not in made}.values())
        group = Pass(r.index, "pointwise", [op for m in kept for op in m.ops], inputs, r.output)
        group.nodes = [n for m in kept for n in m.nodes]
        group.fields = {"members": kept, "flip_store": r.fields.get("flip_store", False)}
        if r.kind != "pointwise":
            r.fields.pop("flip_store", None)
        table.passes[table.passes.index(r)] = group
        table.producer[r.output.ident] = group
    _drop(table, p, t)
    return f"{' + '.join(p.ops)} computed in the pass(es) reading {t.ident}"


def _group_params(p: Pass) -> None:
    """A pointwise group's parameters: each member's arrays, renamed m<k>_<name>."""
    p.params = {f"m{k}_{n}": a for k, m in enumerate(p.fields["members"]) for n, a in m.params.items()}


def _fuse_into_conv(table: ImageOps, q: Pass, multiple: int) -> str | None:
    """One of the fusions that fold pass ``q`` into a conv's reads or a pass's epilogue or store."""
    if q.kind == "binary":
        return _fuse_binary(table, q)
    if q.kind == "crop":
        return _fuse_crop(table, q)
    if q.kind in ("pool_avg", "resize_linear", "pad"):
        return _fuse_read(table, q, multiple)
    return None


def _fuse(table: ImageOps, multiple: int) -> list[str]:
    """The gpu preset's fusions, until none applies; passes renumbered. Returns what was fused. The
    fusions into a conv's reads and epilogue come first; then pointwise passes are computed in their
    readers (where one is left, the others again); last, the pad into the groups and convs reading it."""
    made: list[str] = []
    order = {id(q): k for k, q in enumerate(table.passes)}
    for inline in (False, True):
        while True:
            step = next((s for q in list(table.passes) if (s := _fuse_into_conv(table, q, multiple))), None)
            if step is None and inline:
                step = next(
                    (s for q in list(table.passes) if (s := _inline_pointwise(table, q, order))), None
                )
            if step is None:
                break
            made.append(step)
    pad = next((q for q in table.passes if q.kind == "pad"), None)
    step = pad and _fuse_read(table, pad, multiple, groups=True)
    if step:
        made.append(step)
    for k, q in enumerate(table.passes):
        q.index = k
        if q.kind == "pointwise":
            _group_params(q)
    return made


def generate_compute(
    model: onnx.ModelProto,
    precision: str = "fp32",
    kind: str = "unet",
    local_size: tuple[int, int] | None = None,
    conv_block: tuple[int, int, int] | None = None,
    dialect: str = "glsl430",
    preset: str = "gpu",
    fuse: bool | None = None,
) -> ComputeProgram:
    """One GLSL 4.30 compute shader per layer or fused group, from an image graph (1, C, H, W) -> outputs.
    ``dialect="wgsl"`` writes the same passes in WGSL (WebGPU; see :func:`_wgsl_manifest`),
    ``dialect="vulkan"`` in Vulkan GLSL for SPIR-V (see :func:`_vulkan_manifest`).

    Storage: every tensor is a 2-D array texture, 4 channels per texel (channel c in layer c // 4,
    lane c % 4), RGBA32F (``precision="fp32"``) or RGBA16F (``"fp16"``: storage only, arithmetic
    stays fp32); the raw input and the cropped outputs are RGBA32F. Fusions: Conv + bias + batch
    norm (folded into the weights) + activations; a Concat feeding only Convs is read in place by
    each of them; activations / batch norm after any other pass join its epilogue.
    H and W may be symbolic: sizes are ``Hp * num/den + offset`` of the padded input, which is the
    input reflect-padded (bottom/right) to ``pad_multiple`` (metadata "pad_multiple", checked
    against what the graph needs) by the generated pad pass; crop passes cut outputs back to H x W.
    Beside the image, graph inputs of one element ((1, 1, 1, 1), (1,) or ()) are scalars: each is a
    ``uniform float`` that a "uniform" pass writes to a 1x1 one-channel RGBA32F texture (manifest
    ``uniforms``: ONNX input, declared shape, meaning, GLSL name, location, pass).
    preset : a name of :data:`PRESETS` ("gpu", the default: small invocations, many workgroups, cheap
    passes fused; "cpu": llvmpipe's large blocks, no fusion); ``local_size``, ``conv_block`` and
    ``fuse`` override its fields. conv_block : (texels x, texels y, output layers) that one invocation
    of a (dense) conv pass computes; (1, 1, 1) is one texel of one layer. The manifest's ``dispatch``
    states the groups, ``occupancy`` the workgroups and threads of each pass at 1920x1080.
    """
    if precision not in ("fp32", "fp16"):
        raise NeuralaoError(f"precision must be fp32 or fp16, got {precision!r}")
    if preset not in PRESETS:
        raise NeuralaoError(f"preset must be one of {sorted(PRESETS)}, got {preset!r}")
    chosen = PRESETS[preset]
    local_size = tuple(local_size or chosen.local_size)
    conv_block = tuple(conv_block or chosen.conv_block)
    fuse = chosen.fuse if fuse is None else bool(fuse)
    if dialect not in COMPUTE_DIALECTS:
        raise NeuralaoError(f"compute dialect must be one of {sorted(COMPUTE_DIALECTS)}, got {dialect!r}")
    d = COMPUTE_DIALECTS[dialect]
    graph = read_graph(model, max_inputs=1 + MAX_SCALAR_INPUTS)
    table = ImageOps(graph, metadata_pad_multiple(graph.metadata))
    table.run()
    outputs, shapes = [], {}
    for name in graph.outputs:
        v = table.env[name]
        table.label = f"graph output {name!r}"
        if isinstance(v, ConcatValue):
            v = table.materialise(v)
        if isinstance(v, View):  # read back as a (1, C, H, W) texture in the same element order
            shapes[name] = v.shape
            table.node = onnx.helper.make_node("Identity", [], [], name=f"output {name}")
            v = table.image(table.reshape_view(v, _image_shape(v.shape), 1), "output")
        if not isinstance(v, Texture):
            raise NeuralaoError(f"graph output {name!r} is a constant, not an image")
        # Same size rule as the padded tensor, but of the raw input: H * num/den + offset (exact
        # for outputs at input resolution; static outputs keep their size).
        crop = table.new_texture(v.channels, v.height, v.width, base="raw", onnx_name=name)
        table.add_pass(Pass(0, "crop", ["Crop"], [v], crop))
        outputs.append((name, v, crop))
    for p in table.passes:
        if p.kind in CONV_KINDS:
            _pack_conv(p)
        if p.kind == "conv":
            p.fields["block"] = _conv_block(conv_block, p.output.layers)
    multiple = _pad_multiple(table)
    fused = _fuse(table, multiple) if fuse else []
    _mark_input_derived(table)
    if multiple > 1 and table.global_reads:
        raise NeuralaoError(
            f"{table.global_reads[0]}: a global pool over a dynamic size needs pad_multiple 1 (the padding "
            f"would enter it), the graph needs {multiple}; give the input a static size"
        )
    # Parameters: one float32 blob, each pass's range aligned for glBindBufferRange.
    blob = bytearray()
    ranges: dict[int, tuple[int, int]] = {}
    for p in table.passes:
        if not p.params:
            continue
        blob.extend(b"\0" * ((-len(blob)) % PARAM_ALIGN))
        data = np.concatenate([a.reshape(-1) for a in p.params.values()]).astype("<f4").tobytes()
        ranges[p.index] = (len(blob), len(data))
        blob.extend(data)
    if len(blob) > MAX_PARAM_BYTES:
        raise NeuralaoError(f"parameters need {len(blob)} bytes, over the SSBO limit {MAX_PARAM_BYTES}")
    sources = {}
    for p in table.passes:
        try:
            sources[f"{p.name}{d.extension}"] = _write_compute_pass(p, precision, local_size, d)
        except KeyError as e:  # a template the dialect lacks: that pass kind is not written in it yet
            raise NeuralaoError(
                f"{d.name}: pass {p.name} ({' + '.join(p.ops)}, nodes {', '.join(p.nodes) or '-'}) "
                f"cannot be written: {e.args[0]}"
            ) from None
    manifest = _compute_manifest(
        table, graph, outputs, ranges, bytes(blob), precision, kind, multiple, local_size
    )
    read_by = [p.name for p in table.passes if "reflect" in p.fields.get("reads", ())]
    if read_by:  # the convs that read the input reflect-padded, in place of the pad pass
        manifest["pad"]["read_by"] = read_by
        zeroed_by = "the passes reading the input zero them"
        manifest["input"]["unused_lanes"] = _unused_lanes(table.input_texture.channels, zeroed_by)
    for entry in manifest["outputs"]:
        if entry["onnx_name"] in shapes:
            entry["shape"] = shapes[entry["onnx_name"]]
    manifest["memory"] = memory_section(manifest)
    manifest["arithmetic"] = {
        "precision": precision,
        "declarations": d.fill(f"arithmetic_{precision}"),
        "fp32_declarations": d.fill("arithmetic_fp32"),
        "fallback": "each pass starts with the declarations (after its version line); GLSL and Vulkan GLSL "
        "pick fp32 in the preprocessor where the compiler has no half type; a WebGPU device without "
        "shader-f16 runs the WGSL with fp32_declarations in their place",
    }
    manifest["preset"] = {
        "name": preset,
        "local_size": list(local_size),
        "conv_block": list(conv_block),
        "fuse": fuse,
        "purpose": chosen.purpose,
        "fused": fused,
        "dispatches": len(manifest["passes"]),
    }
    _occupancy(manifest)
    if d.name == "wgsl":
        _wgsl_manifest(manifest, d)
    elif d.name == "vulkan":
        _vulkan_manifest(manifest, d)
    return ComputeProgram(sources, bytes(blob), manifest)


def _occupancy(manifest: dict) -> None:
    """Each pass's workgroups and threads (invocations) at :data:`OCCUPANCY_FRAME` (``occupancy``),
    from the textures' sizes there (the network's internal size for a U-Net that declares one)."""
    try:
        sizes = texture_sizes(manifest, *OCCUPANCY_FRAME)
    except NeuralaoError:
        return  # a program that cannot run at that frame size (a fixed input size)
    frame = "x".join(map(str, OCCUPANCY_FRAME))
    for entry in manifest["passes"]:
        (lx, ly, _), (bx, by, bl) = entry["local_size"], entry["block"]
        tw, th = sizes[entry["output"]["texture"]]
        groups = [
            -(-tw // (lx * bx)),
            -(-th // (ly * by)),
            manifest["textures"][entry["output"]["texture"]]["layers"] // bl,
        ]
        workgroups = groups[0] * groups[1] * groups[2]
        entry["occupancy"] = {
            "frame": frame,
            "groups": groups,
            "workgroups": workgroups,
            "threads": workgroups * lx * ly,
        }


def _wgsl_manifest(manifest: dict, d: Dialect) -> None:
    """Restate the GLSL manifest for the WGSL sources: file names, bind-group slots, WebGPU types.
    Textures, sizes, dispatch and weights.bin are the same (256-byte ranges suit WebGPU's
    minStorageBufferOffsetAlignment)."""
    manifest["format"] = d.compute_format
    manifest.pop("glsl", None)
    manifest["wgsl"] = "WebGPU compute, one bind group (group 0) per pass"
    manifest["storage"]["type"] = "texture 2d-array, 4 channels per texel (rgba32float / rgba16float)"
    manifest["barrier"] = "none needed: WebGPU orders the dispatches of one command encoder"
    for entry in manifest["passes"]:
        n = len(entry["inputs"])
        slots = d.compute_slots(n)
        entry["shader"] = entry["name"] + d.extension
        for inp in entry["inputs"]:
            inp["as"] = "texture_2d_array<f32> (textureLoad), sampleType unfilterable-float"
        fmt = {"rgba32f": "rgba32float", "rgba16f": "rgba16float"}[entry["output"]["format"]]
        entry["output"].update(
            binding=slots["output"], format=fmt, **{"as": f"texture_storage_2d_array<{fmt}, write>"}
        )
        if "params" in entry:
            entry["params"]["binding"] = slots["params"]
            entry["params"]["as"] = (
                "var<storage, read> prm: array<vec4<f32>>, bound at the range's offset and size"
            )
        for name, u in entry.get("uniforms", {}).items():
            u.pop("location", None)
            u["binding"] = slots["uniform"]
            u["as"] = (
                f"var<uniform> {name}: {'i32' if name == 'u_flip_y' else 'f32'} (a 16-byte uniform buffer)"
            )
    for u in manifest["uniforms"]:
        u["shader"] = u["pass"] + d.extension
        u.pop("location", None)
        u["wgsl_name"] = u.pop("glsl_name")
        u["binding"] = next(
            p["uniforms"][u["wgsl_name"]]["binding"] for p in manifest["passes"] if p["name"] == u["pass"]
        )
        u["set_with"] = "queue.writeBuffer of one f32 into the pass's uniform buffer before its dispatch"


# Vulkan descriptor kinds of the manifest's ``bindings``: the Vulkan descriptor type and Godot
# RenderingDevice's uniform type of each.
VULKAN_KINDS = {
    "sampled_image": "VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE (Godot: UNIFORM_TYPE_TEXTURE): texture2DArray, "
    "texelFetch only, no sampler",
    "storage_image": "VK_DESCRIPTOR_TYPE_STORAGE_IMAGE (Godot: UNIFORM_TYPE_IMAGE): image2DArray writeonly",
    "storage_buffer": "VK_DESCRIPTOR_TYPE_STORAGE_BUFFER (Godot: UNIFORM_TYPE_STORAGE_BUFFER): std430 "
    "readonly buffer { vec4 prm[]; }, the pass's range of weights.bin",
    "uniform_buffer": "VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER (Godot: UNIFORM_TYPE_UNIFORM_BUFFER): the pass's "
    "std140 uniform block PassUniforms",
}
VULKAN_FORMATS = {"RGBA32F": "VK_FORMAT_R32G32B32A32_SFLOAT", "RGBA16F": "VK_FORMAT_R16G16B16A16_SFLOAT"}
# A pass's uniform buffer: one vec4's worth (as the WGSL export's), the block's one member at offset 0.
UNIFORM_BLOCK_BYTES = 16


def _vulkan_manifest(manifest: dict, d: Dialect) -> None:
    """Restate the GLSL manifest for the Vulkan GLSL sources: descriptor set 0, each resource at its own
    binding (inputs 0..n-1, output n, params n + 1, uniform block n + 2), per pass a ``bindings`` list
    (set, binding, kind, resource: what a descriptor set layout and its writes need) and the
    ``uniform_block`` (std140, member offsets). Textures, sizes, dispatch and weights.bin are the same.
    The SPIR-V files are the writer's (:func:`neuralao.export.glsl.files.write_compute_export`)."""
    manifest["format"] = d.compute_format
    manifest["glsl"] = (
        "450 compute for Vulkan (GL_EXT_samplerless_texture_functions), SPIR-V by glslangValidator -V"
    )
    manifest["storage"]["type"] = "VkImage 2D array (view type 2D_ARRAY), 4 channels per texel"
    manifest["vulkan"] = {
        "descriptor_set": 0,
        "bindings": "per pass: inputs 0..n-1, output n, params n + 1, uniform block n + 2 (if any)",
        "kinds": VULKAN_KINDS,
        "formats": VULKAN_FORMATS,
        "image_layout": "VK_IMAGE_LAYOUT_GENERAL for every texture (storage writes and sampled reads)",
        "image_usage": "SAMPLED | STORAGE (+ TRANSFER_DST for the input you upload, TRANSFER_SRC for "
        "outputs you read back)",
        "uniforms": "a pass's scalar (u_flip_y, a scalar graph input) is the one member of a std140 uniform "
        f"block at offset 0, in a {UNIFORM_BLOCK_BYTES}-byte uniform buffer: a uniform buffer needs no "
        "optional feature on any API (WebGPU has no push constants) and keeps one binding model with the "
        "WGSL export",
    }
    manifest["barrier"] = (
        "vkCmdPipelineBarrier after each dispatch: COMPUTE_SHADER -> COMPUTE_SHADER, SHADER_WRITE -> "
        "SHADER_READ (images stay in GENERAL)"
    )
    for entry in manifest["passes"]:
        n = len(entry["inputs"])
        slots = d.compute_slots(n)
        bindings = []
        for inp in entry["inputs"]:
            inp.update(set=0, kind="sampled_image", **{"as": "texture2DArray (texelFetch, no sampler)"})
            bindings.append({"binding": inp["binding"], "kind": "sampled_image", "resource": inp["texture"]})
        out = entry["output"]
        out.update(
            set=0,
            binding=slots["output"],
            kind="storage_image",
            **{"as": f"image2DArray writeonly, {out['format']}, layered"},
        )
        bindings.append({"binding": out["binding"], "kind": "storage_image", "resource": out["texture"]})
        if "params" in entry:
            prm = entry["params"]
            prm.update(
                set=0,
                binding=slots["params"],
                kind="storage_buffer",
                **{"as": "std430 readonly buffer { vec4 prm[]; }, bound at the range's offset and size"},
            )
            bindings.append(
                {
                    "binding": prm["binding"],
                    "kind": "storage_buffer",
                    "resource": f"weights.bin bytes {prm['offset']} .. {prm['offset'] + prm['bytes']}",
                }
            )
        if "uniforms" in entry:
            members = []
            for name, u in entry["uniforms"].items():
                kind = "int" if name == "u_flip_y" else "float"
                u.pop("location", None)
                u.update(set=0, binding=slots["uniform"], block="PassUniforms", offset=0, type=kind)
                members.append({"name": name, "type": kind, "offset": 0, "bytes": 4})
            entry["uniform_block"] = {
                "set": 0,
                "binding": slots["uniform"],
                "kind": "uniform_buffer",
                "name": "PassUniforms",
                "layout": "std140",
                "bytes": UNIFORM_BLOCK_BYTES,
                "members": members,
            }
            bindings.append(
                {"binding": slots["uniform"], "kind": "uniform_buffer", "resource": "PassUniforms"}
            )
        entry["bindings"] = [{"set": 0, **b} for b in bindings]
    for u in manifest["uniforms"]:
        u.pop("location", None)
        p = next(p for p in manifest["passes"] if p["name"] == u["pass"])
        u.update(set=0, binding=p["uniform_block"]["binding"], block="PassUniforms", offset=0)
        u["set_with"] = (
            "the value as a float32 at offset 0 of the pass's uniform buffer (std140 block PassUniforms, "
            f"{UNIFORM_BLOCK_BYTES} bytes) before its dispatch"
        )


def _unused_lanes(channels: int, zeroed_by: str = "the pad pass zeroes them") -> str:
    """What the input texture's lanes past the last channel hold: anything; ``zeroed_by`` says who
    zeroes them (the pad pass, or the convs reading the input in its place)."""
    if channels % 4 == 0:
        return "none"
    return (
        f"layer {channels // 4} lanes {channels % 4}..3 (channels {channels}..{4 * ceil4(channels) - 1}): "
        f"any value, NaN included; {zeroed_by}"
    )


def _input_meaning(vi: onnx.ValueInfoProto, metadata: dict[str, str]) -> str:
    """What a graph input means: its doc_string, else metadata "<name>_description", "<name>_input",
    "input_<name>" or "<name>" (the first present)."""
    keys = (f"{vi.name}_description", f"{vi.name}_input", f"input_{vi.name}", vi.name)
    return vi.doc_string or next((metadata[k] for k in keys if k in metadata), "")


def _uniform_entry(vi: onnx.ValueInfoProto, p: Pass, metadata: dict[str, str]) -> dict:
    """Manifest entry of a scalar graph input: the uniform an engine sets before the pass runs."""
    return {
        "onnx_input": vi.name,
        "declared_shape": [int(d) for d in shape_dims(vi)],
        "meaning": _input_meaning(vi, metadata),
        "glsl_name": p.fields["uniform"],
        "type": "float",
        "location": p.fields["location"],
        "pass": p.name,
        "shader": f"{p.name}.comp",
        "texture": p.output.ident,
        "set_with": "glUseProgram(the pass's program); glUniform1f(location, value) before its dispatch",
    }


def _compute_manifest(table, graph, outputs, ranges, blob, precision, kind, multiple, local_size) -> dict:
    internal = "RGBA16F" if precision == "fp16" else "RGBA32F"
    textures = {}
    fp32 = {p.output.ident for p in table.passes if _fp32_output(p)}
    for t in table.textures:
        raw = t.base == "raw"
        fmt = "RGBA32F" if raw or t.ident in fp32 else internal
        textures[t.ident] = {
            "channels": t.channels,
            "layers": t.layers,
            "format": fmt,
            "height": t.height.to_json("H" if raw else "Hp"),
            "width": t.width.to_json("W" if raw else "Wp"),
            "onnx_tensor": t.onnx_name,
        }
        log2 = math.log2(t.height.scale) if t.height.scale > 0 else None
        if log2 is not None and log2 == int(log2) and t.height.scale == t.width.scale:
            textures[t.ident]["scale_log2"] = int(log2)
    passes = []
    for p in table.passes:
        offs = p.param_offsets()
        block = p.fields["block"] if p.kind == "conv" else (1, 1, 1)
        entry = {
            "name": p.name,
            "shader": f"{p.name}.comp",
            "kind": p.kind,
            "ops": p.ops,
            "onnx_nodes": p.nodes,
            "inputs": [
                {"texture": t.ident, "binding": i, "as": "sampler2DArray (texelFetch)"}
                for i, t in enumerate(p.inputs)
            ],
            "output": {
                "texture": p.output.ident,
                "binding": 0,
                "as": "image2DArray writeonly, layered",
                "format": textures[p.output.ident]["format"].lower(),
                "fp16_format": "rgba32f" if _fp32_output(p) else "rgba16f",
            },
            "local_size": [local_size[0], local_size[1], 1],
            "block": list(block),
            "dispatch": {
                "size_of": p.output.ident,
                "groups": [
                    f"ceil(width({p.output.ident}) / {local_size[0] * block[0]})",
                    f"ceil(height({p.output.ident}) / {local_size[1] * block[1]})",
                    f"layers({p.output.ident}) / {block[2]} = {p.output.layers // block[2]}",
                ],
            },
        }
        if p.index in ranges:
            off, size = ranges[p.index]
            entry["params"] = {
                "buffer": "weights.bin",
                "binding": 0,
                "offset": off,
                "bytes": size,
                "as": "std430 readonly buffer { vec4 prm[]; } via glBindBufferRange",
                "arrays": {
                    n: {"offset_vec4": offs[n], "vec4s": int(a.shape[0])} for n, a in p.params.items()
                },
            }
            if p.kind == "conv_depthwise":
                entry["params"]["layout"] = (
                    "weight: vec4 per (layer, ky, kx), lane r = W[4*layer + r, 0, ky, kx]; "
                    "bias: vec4 per layer"
                )
            elif p.kind in CONV_KINDS:
                entry["params"]["layout"] = (
                    "weight: mat4 per (out_layer, ky, kx, in_layer) = 4 vec4 columns; column c = input lane, "
                    "row r = output lane: W[4*out_layer + r, channel(in_layer, c), ky, kx]; "
                    "bias: vec4 per out_layer"
                    + (
                        "; ConvTranspose as a gather: W[m, c] = ONNX W[c, m] per group"
                        if p.kind == "conv_transpose"
                        else ""
                    )
                )
            if p.kind in CONV_KINDS:
                entry["conv"] = {k: list(v) if isinstance(v, tuple) else v for k, v in p.fields.items()}
                entry["folded_batch_norm"] = p.folded_bn
        if p.kind == "uniform":
            vi = next(v for v, q in table.uniforms if q is p)
            entry["uniforms"] = {
                p.fields["uniform"]: {
                    "location": p.fields["location"],
                    "type": "float",
                    "onnx_input": vi.name,
                    "value": f"graph input {vi.name!r} (glUniform1f)",
                }
            }
        if _flips(p):
            entry["uniforms"] = {
                "u_flip_y": {
                    "location": 0,
                    "value": "0: texture row 0 = tensor row 0 (top); "
                    "1: the texture is a bottom-up GL image (row 0 = bottom)",
                }
            }
        if p.kind.startswith("resize"):
            entry["resize"] = {
                "mode": p.fields["mode"],
                "coordinate_transformation_mode": p.fields["coord"],
                "nearest_mode": p.fields["nearest_mode"],
            }
            for key in ("cubic_coeff_a", "exclude_outside", "extrapolation", "widen"):
                if p.fields.get(key) is not None:
                    entry["resize"][key] = p.fields[key]
        passes.append(entry)
    return {
        "kind": kind,
        "format": "neuralao-glsl-compute",
        "format_version": FORMAT_VERSION,
        "glsl": "430 core compute",
        "precision": precision,
        "storage": {
            "type": "GL_TEXTURE_2D_ARRAY, 4 channels per texel",
            "internal_format": internal,
            "io_format": "RGBA32F",
            "channel": "layer = c // 4, lane = c % 4 (padding lanes hold finite junk, never read)",
            "rows": "texel (x, y) = tensor[..., y, x]: row 0 is the tensor's first (top) row",
            "arithmetic": "fp32"
            if precision == "fp32"
            else "dense conv products in fp16 where the compiler has a half type, summed in fp32 (GL, "
            "Vulkan: GL_EXT_shader_explicit_arithmetic_types_float16 or GL_AMD_gpu_shader_half_float, "
            "chosen by the preprocessor, else fp32; WGSL: enable f16, the device feature shader-f16); "
            "epilogues and other passes in fp32",
        },
        "input": {
            "onnx_name": table.image_input.name,
            "texture": table.input_texture.ident,
            "channels": table.input_texture.channels,
            "unused_lanes": _unused_lanes(table.input_texture.channels),
            "declared_shape": [str(v) for v in shape_dims(table.image_input)],
        },
        "uniforms": [_uniform_entry(vi, p, graph.metadata) for vi, p in table.uniforms],
        "outputs": [
            {"onnx_name": n, "texture": crop.ident, "channels": crop.channels} for n, _, crop in outputs
        ],
        "pad": {
            "multiple": multiple,
            "mode": "reflect",
            "side": "bottom,right",
            # the pad pass, or none where the convs reading the input pad it as they read (gpu preset)
            "pass": next((p.name for p in table.passes if p.kind == "pad"), None),
            "padded_size": "Hp = ceil(H / multiple) * multiple, Wp likewise; needs H, W >= multiple",
            "crop_passes": [p.name for p in table.passes if p.kind == "crop" or p.fields.get("flip_store")],
        },
        "static_input_size": list(table.input_dims) if table.static else None,
        "textures": textures,
        "weights": {
            "file": "weights.bin",
            "bytes": len(blob),
            "sha256": sha256_hex(blob),
            "dtype": "float32 little-endian",
            "range_alignment": PARAM_ALIGN,
        },
        "passes": passes,
        "barrier": "glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT | GL_SHADER_IMAGE_ACCESS_BARRIER_BIT) "
        "after each pass",
        "source_model_metadata": dict(graph.metadata),
    }
