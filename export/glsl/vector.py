"""The fragment target: per-pixel dense networks (N, K) -> (N, M<=4) as one fullscreen fragment pass,
weights in std140 uniform blocks. :class:`VectorOps` is the op table, the ``_write_*`` functions the
writer, :func:`generate_vector_fragment` the entry point."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import onnx

from neuralao.export.glsl.activations import Act, clip_bounds
from neuralao.export.glsl.dialects import DIALECTS, FRAGMENT_FILES, Dialect, get_dialect
from neuralao.export.glsl.graph import (
    FORMAT_VERSION,
    OnnxGraph,
    OpTable,
    ceil4,
    glsl_float,
    read_graph,
    sha256_hex,
    shape_dims,
)
from neuralao.export.glsl.templates import fill
from neuralao.runtime.foundation.errors import NeuralaoError

# Portable minimum GL_MAX_UNIFORM_BLOCK_SIZE (GL 3.3+, ES 3.0): every uniform block stays below it.
MAX_UNIFORM_BLOCK_BYTES = 16384
# Portable minimum GL_MAX_FRAGMENT_UNIFORM_BLOCKS (GL 3.3, ES 3.0).
MAX_FRAGMENT_UNIFORM_BLOCKS = 12
# Widest per-pixel activation vector the fragment target accepts (local vec4 arrays live in registers).
MAX_VECTOR_WIDTH = 1024


@dataclass
class VecValue:
    """A per-pixel activation vector, stored as the local array ``vec4 <ident>[ceil(width/4)]``."""

    ident: str
    width: int

    @property
    def n4(self) -> int:
        return ceil4(self.width)


@dataclass
class DenseOp:
    """dst = epilogue(weight @ src + bias). weight (out, in) float32, bias (out,) float32."""

    src: VecValue
    dst: VecValue
    weight: np.ndarray
    bias: np.ndarray
    epilogue: list[Act]
    nodes: list[str]
    chunks: list[tuple[int, int, str, str, int]] = field(
        default_factory=list
    )  # (j0, j1, weight, bias, block)


@dataclass
class MapOp:
    """dst = epilogue(src [binop other | binop const]) elementwise; const (width,) float32 or None.

    binop is one of + - * / (ONNX Add, Sub, Mul, Div); ``swapped``: the operand comes first
    (``const - src``), as the ONNX node wrote it."""

    src: VecValue
    dst: VecValue
    other: VecValue | None
    const: np.ndarray | None
    epilogue: list[Act]
    nodes: list[str]
    const_member: str = ""
    binop: str = "+"
    swapped: bool = False


@dataclass
class ConcatOp:
    """dst = the parts side by side along the feature axis (ONNX Concat, axis 1)."""

    parts: list[VecValue]
    dst: VecValue
    nodes: list[str]


@dataclass(frozen=True)
class InputBinding:
    """Where one graph input of the fragment target comes from: ``channels`` (a subset of "xyzw") of
    the RGBA32F texture ``texture``, repeated ``repeats`` times, so the input width is
    ``len(channels) * repeats``. The first texture's w channel is the mask.

    ``texture`` is a name for the host and the manifest only: the shader's sampler is generated from
    the texture unit (:func:`sampler_name`), so no user-chosen name reaches shader source."""

    texture: str
    channels: str = "xyz"
    repeats: int = 1

    def to_json(self) -> dict:
        return {"texture": self.texture, "channels": self.channels, "repeats": self.repeats}


def sampler_name(unit: int) -> str:
    """The GLSL sampler of input texture ``unit`` (units in order of the textures' first appearance)."""
    return f"u_tex{unit}"


def _comment_text(text: str) -> str:
    """``text`` safe inside a ``//`` comment: printable ASCII on one line, no backslash (a trailing one
    would continue the comment onto the next line)."""
    return "".join(c if " " <= c <= "~" and c != "\\" else "?" for c in text)


@dataclass
class UniformBlock:
    """One std140 uniform block of vec4 / mat4 arrays.

    members: (identifier, (n, 4) float32 rows of vec4s, layout words, GLSL type "vec4" | "mat4"); a
    mat4 is 4 consecutive vec4 rows (its columns)."""

    name: str
    binding: int
    members: list[tuple[str, np.ndarray, str, str]]

    @property
    def data(self) -> np.ndarray:
        if not self.members:
            return np.zeros(0, np.float32)
        return np.ascontiguousarray(
            np.concatenate([m[1].reshape(-1) for m in self.members]).astype(np.float32)
        )

    @property
    def nbytes(self) -> int:
        return int(sum(m[1].nbytes for m in self.members))


class VectorOps(OpTable):
    """ONNX -> per-pixel dense network (N, K) -> (N, M) for the fragment target."""

    OPS = (
        "Gemm",
        "MatMul",
        "Add",
        "Sub",
        "Mul",
        "Div",
        "Concat",
        "Relu",
        "LeakyRelu",
        "Sigmoid",
        "Tanh",
        "Sin",
        "Cos",
        "Clip",
        "Identity",
        "Constant",
    )
    target = "fragment (per-pixel MLP)"

    def __init__(self, graph: OnnxGraph, bindings: dict[str, InputBinding] | None = None):
        """``bindings``: graph input name -> texture channels. None: the baked-MLP layout (one input of
        3k floats, the object-space normal of texture "gbuffer" repeated k times)."""
        super().__init__(graph)
        self.ops: list[DenseOp | MapOp | ConcatOp] = []
        self.values: list[VecValue] = []
        self.producer: dict[str, DenseOp | MapOp | ConcatOp] = {}
        legacy = bindings is None
        if legacy:
            width = self._input_width(graph.input, "MLP", "(N, 3*k normals)")
            if width % 3:
                raise NeuralaoError(f"MLP input width {width} is not a multiple of 3 (xyz normals repeated)")
            bindings = {graph.input.name: InputBinding("gbuffer", "xyz", width // 3)}
        names = [vi.name for vi in graph.inputs]
        if sorted(names) != sorted(bindings):
            raise NeuralaoError(f"graph inputs {names} do not match the bound inputs {sorted(bindings)}")
        self.bindings = {name: bindings[name] for name in names}
        self.inputs: list[VecValue] = []
        for vi in graph.inputs:
            b = self.bindings[vi.name]
            if not b.channels or any(c not in "xyzw" for c in b.channels) or b.repeats < 1:
                raise NeuralaoError(f"input {vi.name!r}: bad binding {b}")
            width = self._input_width(vi, "input", f"(N, {len(b.channels) * b.repeats})")
            if width != len(b.channels) * b.repeats:
                raise NeuralaoError(
                    f"input {vi.name!r} has width {width}, its binding gives {len(b.channels)} x {b.repeats}"
                )
            value = self.new_value(width)
            self.inputs.append(value)
            self.env[vi.name] = value
        self.input = self.inputs[0]
        self.repeats = next(iter(self.bindings.values())).repeats
        self.textures = list(dict.fromkeys(b.texture for b in self.bindings.values()))

    @staticmethod
    def _input_width(vi: onnx.ValueInfoProto, what: str, layout: str) -> int:
        dims = shape_dims(vi)
        if len(dims) != 2:
            raise NeuralaoError(
                f"{what} {vi.name!r} must have rank 2 {layout}, got shape {dims or 'unknown'}"
            )
        width = dims[1]
        if not isinstance(width, int) or width <= 0:
            raise NeuralaoError(f"{what} {vi.name!r} needs a static positive width, got {width!r}")
        if width > MAX_VECTOR_WIDTH:
            raise NeuralaoError(
                f"{what} {vi.name!r}: width {width} exceeds the fragment limit {MAX_VECTOR_WIDTH}"
            )
        return int(width)

    def new_value(self, width: int) -> VecValue:
        if width > MAX_VECTOR_WIDTH:
            raise self.fail(f"vector width {width} exceeds the fragment limit {MAX_VECTOR_WIDTH}")
        v = VecValue(f"t{len(self.values)}", int(width))
        self.values.append(v)
        return v

    def vec(self, value: Any, what: str) -> VecValue:
        if not isinstance(value, VecValue):
            raise self.fail(f"input {what} must be a per-pixel tensor, not a constant")
        return value

    def _fusible_op(self, index: int, kind: type) -> Any:
        assert self.node is not None
        value = self.env.get(self.node.input[index])
        op = self.producer.get(value.ident) if isinstance(value, VecValue) else None
        if not (isinstance(op, kind) and self.fusible(index) and op.dst is value):
            return None
        # fusible() counts the readers still to come; one already emitted (Sin and Cos of one MatMul)
        # must keep seeing the unfused value.
        return None if any(_reads(o, value) for o in self.ops) else op

    def _dense(self, x: VecValue, weight: np.ndarray, bias: np.ndarray) -> VecValue:
        if not (np.all(np.isfinite(weight)) and np.all(np.isfinite(bias))):
            raise self.fail("weights contain non-finite values")
        dst = self.new_value(weight.shape[0])
        op = DenseOp(x, dst, weight.astype(np.float32), bias.astype(np.float32), [], [self.label])
        self.ops.append(op)
        self.producer[dst.ident] = op
        return dst

    def _vector_const(self, c: np.ndarray, width: int) -> np.ndarray:
        c = np.asarray(c, dtype=np.float64)
        if c.ndim == 2 and c.shape[0] == 1:
            c = c[0]
        if c.ndim > 1 or c.size not in (1, width):
            raise self.fail(
                f"constant of shape {list(c.shape)} does not broadcast to a per-pixel vector of {width}"
            )
        return np.broadcast_to(c.reshape(-1), (width,)).astype(np.float64)

    def _activation(self, x: Any, act: Act) -> VecValue:
        x = self.vec(x, "X")
        op = self._fusible_op(0, (DenseOp, MapOp))
        if op is not None:
            op.epilogue.append(act)
            op.nodes.append(self.label)
            return x
        dst = self.new_value(x.width)
        mop = MapOp(x, dst, None, None, [act], [self.label])
        self.ops.append(mop)
        self.producer[dst.ident] = mop
        return dst

    # -- handlers (named after the ONNX op; attributes with ONNX defaults)
    def Gemm(self, A, B, C=None, *, alpha=1.0, beta=1.0, transA=0, transB=0) -> VecValue:
        x = self.vec(A, "A")
        if transA:
            raise self.unsupported("transA", transA)  # the per-pixel batch axis cannot be transposed
        b = self.const(B, "B").astype(np.float64)
        if b.ndim != 2:
            raise self.fail(f"B must be a matrix, got shape {list(b.shape)}")
        w = (b.T if not transB else b) * float(alpha)  # (out, in)
        if w.shape[1] != x.width:
            raise self.fail(f"B of shape {list(b.shape)} (transB={transB}) does not take {x.width} inputs")
        bias = (
            np.zeros(w.shape[0])
            if C is None
            else float(beta) * self._vector_const(self.const(C, "C"), w.shape[0])
        )
        return self._dense(x, w, bias)

    def MatMul(self, A, B) -> VecValue:
        x = self.vec(A, "A")
        b = self.const(B, "B").astype(np.float64)
        if b.ndim != 2 or b.shape[0] != x.width:
            raise self.fail(f"B of shape {list(b.shape)} does not take {x.width} inputs")
        return self._dense(x, b.T, np.zeros(b.shape[1]))

    def Add(self, A, B) -> VecValue:
        return self._binary(A, B, "+")

    def Sub(self, A, B) -> VecValue:
        return self._binary(A, B, "-")

    def Mul(self, A, B) -> VecValue:
        return self._binary(A, B, "*")

    def Div(self, A, B) -> VecValue:
        return self._binary(A, B, "/")

    def _binary(self, A, B, binop: str) -> VecValue:
        """Elementwise A binop B, either operand a per-pixel vector, the other a vector or a constant
        that broadcasts to it (numpy rules on the feature axis). Kept as written (no reassociation,
        no division turned into a product), so GLSL rounds exactly as onnxruntime does."""
        if isinstance(A, np.ndarray) and isinstance(B, VecValue):
            A, B = B, A
            swapped = True
        else:
            swapped = False
        x = self.vec(A, "A")
        if isinstance(B, VecValue):
            if B.width != x.width:
                raise self.fail(f"cannot combine vectors of widths {x.width} and {B.width}")
            dst = self.new_value(x.width)
            op = MapOp(x, dst, B, None, [], [self.label], binop=binop, swapped=swapped)
        else:
            c = self._vector_const(B, x.width)
            dense = self._fusible_op(1 if swapped else 0, DenseOp) if binop == "+" else None
            if dense is not None and not dense.epilogue:
                dense.bias = (dense.bias.astype(np.float64) + c).astype(
                    np.float32
                )  # MatMul + Add -> one layer
                dense.nodes.append(self.label)
                return x
            dst = self.new_value(x.width)
            op = MapOp(x, dst, None, c.astype(np.float32), [], [self.label], binop=binop, swapped=swapped)
        self.ops.append(op)
        self.producer[dst.ident] = op
        return dst

    def Relu(self, X) -> VecValue:
        return self._activation(X, Act("Relu"))

    def LeakyRelu(self, X, *, alpha=0.01) -> VecValue:
        return self._activation(X, Act("LeakyRelu", {"alpha": float(alpha)}))

    def Sigmoid(self, X) -> VecValue:
        return self._activation(X, Act("Sigmoid"))

    def Tanh(self, X) -> VecValue:
        return self._activation(X, Act("Tanh"))

    def Sin(self, input) -> VecValue:  # noqa: A002
        return self._activation(input, Act("Sin"))

    def Cos(self, input) -> VecValue:  # noqa: A002
        return self._activation(input, Act("Cos"))

    def Concat(self, *inputs, axis) -> VecValue:
        if axis not in (1, -1):
            raise self.unsupported("axis", axis)  # axis 0 is the per-pixel batch
        parts = [self.vec(v, f"#{i}") for i, v in enumerate(inputs)]
        if not parts:
            raise self.fail("Concat without inputs")
        dst = self.new_value(sum(p.width for p in parts))
        op = ConcatOp(parts, dst, [self.label])
        self.ops.append(op)
        self.producer[dst.ident] = op
        return dst

    def Clip(self, input, min=None, max=None) -> VecValue:  # noqa: A002  (ONNX input names)
        lo = None if min is None else self.const(min, "min")
        hi = None if max is None else self.const(max, "max")
        return self._activation(input, Act("Clip", clip_bounds(lo, hi)))

    def Identity(self, input) -> Any:  # noqa: A002
        return input


@dataclass
class MLPShader:
    """A generated baked-MLP fragment pass.

    fragment_source / vertex_source : GLSL of ``dialect``; ``sources`` holds every dialect's pair by
    name ({"glsl330": (vert, frag), "es300": ..., "glsl430": ...}). uniform_blocks : list of
    (block name, binding, (n,) float32 std140 data). manifest : dict (see :func:`write_mlp_export`).
    """

    fragment_source: str
    vertex_source: str
    uniform_blocks: list[tuple[str, int, np.ndarray]]
    manifest: dict
    dialect: str = "glsl330"
    sources: dict[str, tuple[str, str]] = field(default_factory=dict)

    @property
    def output_width(self) -> int:
        return int(self.manifest["network"]["output_width"])


def _reads(op: DenseOp | MapOp | ConcatOp, value: VecValue) -> bool:
    if isinstance(op, ConcatOp):
        return any(p is value for p in op.parts)
    return op.src is value or getattr(op, "other", None) is value


def _fold_repeated_input(table: VectorOps) -> bool:
    """Fold W1 (out, 3k) to (out, 3): the shader feeds the same normal k times, so the k column
    blocks of the first layer multiply the same three numbers. Sums in float64 (the summation order
    differs from onnxruntime's by rounding only; the parity tests hold both paths to the same TOL)."""
    if (
        len(table.inputs) != 1
        or table.repeats < 2
        or table.bindings[table.graph.input.name].channels != "xyz"
    ):
        return False
    readers = [op for op in table.ops if _reads(op, table.input)]
    if len(readers) != 1 or not isinstance(readers[0], DenseOp):
        return False
    if any(table.env.get(o) is table.input for o in table.graph.outputs):
        return False
    op = readers[0]
    k = table.input.width // 3
    op.weight = op.weight.astype(np.float64).reshape(op.weight.shape[0], k, 3).sum(axis=1).astype(np.float32)
    table.input.width = 3
    return True


def _dense_tiles(op: DenseOp) -> tuple[np.ndarray, np.ndarray, int, int]:
    """W (out, in) as mat4 tiles and the bias as vec4s: tiles (out4 * in4 * 4, 4) float32, tile j * in4 + i
    holding W[4j .. 4j+3, 4i .. 4i+3] column-major (column c = the weights of input lane 4i + c), so
    ``tile * src[i]`` is that block's contribution to outputs 4j .. 4j+3; bias (out4, 4)."""
    out4, in4 = ceil4(op.weight.shape[0]), ceil4(op.weight.shape[1])
    w = np.zeros((out4 * 4, in4 * 4), np.float32)
    w[: op.weight.shape[0], : op.weight.shape[1]] = op.weight
    b = np.zeros(out4 * 4, np.float32)
    b[: op.bias.shape[0]] = op.bias
    tiles = w.reshape(out4, 4, in4, 4).transpose(0, 2, 3, 1)  # [j, i, column c (input lane), row r (output)]
    return tiles.reshape(-1, 4), b.reshape(-1, 4), out4, in4


def _assign_blocks(table: VectorOps) -> list[UniformBlock]:
    """Dense layers (mat4 tiles, in row chunks) and constant vectors, packed in order into std140 blocks
    of at most 16 KB each (a member never spans two blocks; members are global names in GLSL)."""
    members: list[tuple[str, np.ndarray, str, str]] = []  # (name, (n, 4) f32, layout, glsl type)
    tile_vec4s = 4
    for li, op in enumerate(table.ops):
        if isinstance(op, DenseOp):
            tiles, b, out4, in4 = _dense_tiles(op)
            rows4 = (MAX_UNIFORM_BLOCK_BYTES // 16) // (tile_vec4s * in4)  # output vec4s per weight chunk
            if rows4 < 1:
                raise NeuralaoError(
                    f"layer {li}: input width {op.weight.shape[1]} does not fit a 16 KB uniform block"
                )
            op.chunks = []
            for ci, j0 in enumerate(range(0, out4, rows4)):
                j1 = min(out4, j0 + rows4)
                wname = f"w{li}_{ci}"
                members.append(
                    (
                        wname,
                        tiles[j0 * in4 * 4 : j1 * in4 * 4],
                        f"mat4 tiles of W (out, in) rows {4 * j0}..{4 * j1 - 1}: "
                        f"tile (j - {j0}) * {in4} + i = "
                        f"W[4j..4j+3, 4i..4i+3] column-major (column c = input lane 4i + c)",
                        "mat4",
                    )
                )
                op.chunks.append((j0, j1, wname, f"b{li}", -1))
            members.append((f"b{li}", b, f"bias[0..{4 * out4 - 1}]", "vec4"))
        elif isinstance(op, MapOp) and op.const is not None:
            c = np.zeros(op.dst.n4 * 4, np.float32)
            c[: op.const.shape[0]] = op.const
            op.const_member = f"c{li}"
            members.append((op.const_member, c.reshape(-1, 4), "vector", "vec4"))
    blocks: list[UniformBlock] = []
    where: dict[str, int] = {}
    for m in members:
        nbytes = m[1].nbytes
        if not blocks or blocks[-1].nbytes + nbytes > MAX_UNIFORM_BLOCK_BYTES:
            blocks.append(UniformBlock(f"Weights{len(blocks)}", len(blocks), []))
        blocks[-1].members.append(m)
        where[m[0]] = blocks[-1].binding
    for op in table.ops:
        if isinstance(op, DenseOp):
            op.chunks = [(j0, j1, w, b, where[w]) for j0, j1, w, b, _ in op.chunks]
    if len(blocks) > MAX_FRAGMENT_UNIFORM_BLOCKS:
        raise NeuralaoError(
            f"the network needs {len(blocks)} uniform blocks; "
            f"the portable limit is {MAX_FRAGMENT_UNIFORM_BLOCKS}"
        )
    return blocks


def _concat_copies(op: ConcatOp) -> list[str]:
    """Component copies of a Concat: whole vec4s where source and destination lanes line up."""
    lanes = "xyzw"
    out, k = [], 0
    for part in op.parts:
        i = 0
        while i < part.width:
            if k % 4 == 0 and i % 4 == 0 and part.width - i >= 4:
                out.append(fill("vec_copy", dst=op.dst.ident, di=k // 4, src=part.ident, si=i // 4))
                i, k = i + 4, k + 4
                continue
            out.append(
                fill(
                    "lane_copy",
                    dst=op.dst.ident,
                    di=k // 4,
                    dl=lanes[k % 4],
                    src=part.ident,
                    si=i // 4,
                    sl=lanes[i % 4],
                )
            )
            i, k = i + 1, k + 1
    for k in range(op.dst.width, op.dst.n4 * 4):  # padding lanes are read by dot(): keep them 0
        out.append(fill("lane_zero", dst=op.dst.ident, di=k // 4, dl=lanes[k % 4]))
    return out


# Dense layers of at most this many mat4 tiles are written straight-line; larger ones loop over their
# output vec4s (the loop kept rolled, see the template). Measured on llvmpipe (LLVM 15): straight-line code
# compiles super-linearly in its length (a 100-tile layer took 61 s), while a rolled loop over rows with
# the products of one row written out compiles in about a second and runs at the same speed.
MAX_STRAIGHT_TILES = 32
# weights="auto" writes at most this many floats (padded tiles, biases, constants) as const arrays.
MAX_CONSTANT_WEIGHTS = 8192


def _dense_rows(op: DenseOp) -> list[str]:
    """A dense layer: per output vec4 j, act(bias[j] + sum_i tile[j, i] * src[i]) (mat4 x vec4 products).

    Small layers: one statement per output vec4, every index a constant (the arrays stay in registers).
    Large layers: a loop over the output vec4s of each chunk, its body the in4 products of one row."""
    in4 = op.src.n4
    rows = []
    straight = (op.dst.n4 * in4) <= MAX_STRAIGHT_TILES
    for j0, j1, wname, bname, _ in op.chunks:
        if straight:
            for j in range(j0, j1):
                terms = [
                    fill("mat_term", weight=wname, index=(j - j0) * in4 + i, src=op.src.ident, i=i)
                    for i in range(in4)
                ]
                value = fill("dense_acc", bias=bname, j=j, terms=" + ".join(terms))
                for act in op.epilogue:
                    value = act.expr(value)
                rows.append(fill("dense_row", dst=op.dst.ident, j=j, value=value))
            continue
        terms = [
            fill("mat_term", weight=wname, index=f"(j - {j0}) * {in4} + {i}", src=op.src.ident, i=i)
            for i in range(in4)
        ]
        value = fill("dense_acc", bias=bname, j="j", terms=" + ".join(terms))
        for act in op.epilogue:
            value = act.expr(value)
        rows.append(
            fill(
                "dense_loop",
                j_begin=j0,
                j_end=j1,
                row=fill("dense_row", dst=op.dst.ident, j="j", value=value),
            )
        )
    return rows


def _map_expr(op: MapOp, j: int) -> str:
    expr = fill("index_j", name=op.src.ident, j=j)
    operand = None
    if op.other is not None:
        operand = fill("index_j", name=op.other.ident, j=j)
    elif op.const is not None:
        operand = fill("index_j", name=op.const_member, j=j)
    if operand is not None:
        a, b = (operand, expr) if op.swapped else (expr, operand)
        expr = fill("binop", a=a, b=b, op=op.binop)
    for act in op.epilogue:
        expr = act.expr(expr)
    return expr


def _const_arrays(blocks: list[UniformBlock]) -> list[str]:
    """Every uniform-block member as a GLSL ``const`` array, each float written exactly (glsl_float)."""
    out = []
    for blk in blocks:
        for name, data, _, glsl_type in blk.members:
            per = 16 if glsl_type == "mat4" else 4
            flat = np.asarray(data, np.float32).reshape(-1)
            items = [
                fill("const_item", type=glsl_type, values=", ".join(glsl_float(v) for v in flat[k : k + per]))
                for k in range(0, flat.size, per)
            ]
            out.append(
                fill("const_array", type=glsl_type, name=name, count=len(items), items=", ".join(items))
            )
    return out


def _write_vector_fragment(
    table: VectorOps,
    blocks: list[UniformBlock],
    result: VecValue,
    d: Dialect,
    description: str,
    constant_weights: bool = False,
) -> str:
    """The writer for the fragment target: IR -> template fills."""
    block_text = []
    for blk in [] if constant_weights else blocks:
        members = "\n".join(
            fill("ubo_member", type=m[3], name=m[0], count=m[1].shape[0] // (4 if m[3] == "mat4" else 1))
            for m in blk.members
        )
        block_text.append(
            fill("ubo_block", layout=d.ubo_layout(blk.binding), block=blk.name, members=members)
        )
    samplers = "\n".join(d.sampler2d(sampler_name(unit), unit) for unit in range(len(table.textures)))
    fetches = "\n".join(
        fill("texel_fetch", index=unit, sampler=sampler_name(unit)) for unit in range(1, len(table.textures))
    )
    body = [fill("vec_decl", name=v.ident, count=v.n4) for v in table.values]
    for value, (_, b) in zip(table.inputs, table.bindings.items(), strict=True):
        g = f"g{table.textures.index(b.texture)}"
        lanes = [f"{g}.{c}" for c in b.channels]
        for i in range(value.n4):
            comps = [lanes[(4 * i + c) % len(lanes)] if 4 * i + c < value.width else "0.0" for c in range(4)]
            body.append(
                fill(
                    "input_tile", dst=value.ident, index=i, c0=comps[0], c1=comps[1], c2=comps[2], c3=comps[3]
                )
            )
    for op in table.ops:
        if isinstance(op, DenseOp):
            body.extend(_dense_rows(op))
        elif isinstance(op, ConcatOp):
            body.extend(_concat_copies(op))
        else:
            body.extend(
                fill("vec_map", dst=op.dst.ident, j=j, expr=_map_expr(op, j)) for j in range(op.dst.n4)
            )
    return fill(
        "vector_fragment",
        header=d.header(),
        description=_comment_text(description),
        weights=fill("weights_constant")
        if constant_weights
        else fill("weights_uniform", n_blocks=len(blocks), max_block_bytes=MAX_UNIFORM_BLOCK_BYTES),
        prelude=fill("prelude"),
        samplers=samplers,
        mask_sampler=sampler_name(0),
        fetches=fetches,
        blocks="\n".join(_const_arrays(blocks)) if constant_weights else "\n\n".join(block_text),
        body="\n".join(body),
        result=fill("index_0", name=result.ident),
    )


def _write_fullscreen_vertex(d: Dialect) -> str:
    return fill("fullscreen_vertex", header=d.header())


def generate_mlp_fragment(
    model: onnx.ModelProto, dialect: str = "glsl330", fold_repeated_input: bool = True, weights: str = "auto"
) -> MLPShader:
    """Baked-MLP fragment shader from an ONNX graph (N, 3k) -> (N, m<=4), k normals repeated.

    The shader reads the object-space normal (xyz) and a mask (w >= 0.5: foreground) from an
    RGBA32F G-buffer texture "gbuffer" (unit 0, sampler ``u_tex0``), feeds the normal k times (radius zero, as
    in Erra et al.), evaluates the network and writes its m outputs to ``o_result`` (location 0);
    background pixels get 1. ``fold_repeated_input`` folds the k column blocks of the first layer
    into one (out, 3) matrix (same function, k times fewer multiply-adds); False keeps the literal
    network. ``weights``: see :func:`generate_vector_fragment` (uniform blocks are <= 16384 bytes each).
    """
    return generate_vector_fragment(model, None, dialect, fold_repeated_input, weights=weights)


def generate_vector_fragment(
    model: onnx.ModelProto,
    bindings: dict[str, InputBinding] | None,
    dialect: str = "glsl330",
    fold_repeated_input: bool = True,
    kind: str = "mlp",
    description: str = "",
    weights: str = "auto",
) -> MLPShader:
    """Fragment shader of any per-pixel network (N, k_i) inputs -> (N, m<=4) in the vector op set.

    ``weights``: "uniform" (std140 uniform blocks, swappable without recompiling), "constant" (``const``
    arrays in the shader source: nothing to bind, and the compiler folds them into the code), or "auto":
    constant when every dense layer is straight-line and there are at most MAX_CONSTANT_WEIGHTS floats,
    else uniform. Measured on llvmpipe at 512x512, one run (bench/bench_fragment.py): constant / uniform
    speed-up MLP 16x8 6.0x, 32x16 7.1x, field 16x8 8.7x (straight-line); with looped layers MLP 64x32
    0.99x and field 32x16 1.6x, but there the folding moved a random test graph to 1.05e-5 from
    onnxruntime (over the 1e-5 gate), so auto keeps those in uniform blocks.

    ``bindings`` maps each graph input to channels of a named RGBA32F texture (unit = the texture's
    order of first appearance, sampler ``u_tex<unit>``: texture and ONNX names stay in the manifest,
    never in shader source); the first texture's w is the foreground mask (>= 0.5). None: the baked-MLP
    layout (see :func:`generate_mlp_fragment`). Background pixels get 1; the m outputs go to ``o_result``
    (location 0).
    """
    d = get_dialect(dialect)
    graph = read_graph(model, max_inputs=1 if bindings is None else 8)
    table = VectorOps(graph, bindings)
    table.run()
    out_name = graph.outputs[0]
    if len(graph.outputs) != 1:
        raise NeuralaoError(f"the per-pixel graph must have one output, found {len(graph.outputs)}")
    result = table.env[out_name]
    if not isinstance(result, VecValue):
        raise NeuralaoError(f"graph output {out_name!r} is a constant, not a per-pixel value")
    if result.width > 4:
        raise NeuralaoError(f"output width {result.width} > 4: a fragment pass writes one vec4 per pixel")
    input_width = table.input.width
    folded = _fold_repeated_input(table) if fold_repeated_input else False
    if not description and bindings is None:
        description = (
            "neuralao baked-MLP AO (Erra et al.): per pixel, the object-space normal fed "
            f"{table.repeats} times."
        )
    elif not description:  # inputs by position: their names stay in the manifest
        units = [
            f"#{i} = unit {table.textures.index(b.texture)}.{b.channels}"
            for i, b in enumerate(table.bindings.values())
        ]
        description = (
            f"neuralao per-pixel network ({kind}): inputs {', '.join(units)} "
            "(names: manifest network.bindings)"
        )
    blocks = _assign_blocks(table)
    if weights not in ("auto", "uniform", "constant"):
        raise NeuralaoError(f"weights must be auto, uniform or constant, got {weights!r}")
    n_weights = sum(int(b.data.size) for b in blocks)
    straight = all(op.dst.n4 * op.src.n4 <= MAX_STRAIGHT_TILES for op in table.ops if isinstance(op, DenseOp))
    constant = weights == "constant" or (weights == "auto" and straight and n_weights <= MAX_CONSTANT_WEIGHTS)
    sources = {
        name: (
            _write_fullscreen_vertex(dl),
            _write_vector_fragment(table, blocks, result, dl, description, constant),
        )
        for name, dl in DIALECTS.items()
    }
    manifest = _mlp_manifest(table, blocks, graph, result, input_width, folded)
    if bindings is not None:
        manifest["kind"] = kind
    ubos = [(b.name, b.binding, b.data) for b in blocks]
    if constant:
        manifest["weights"] = "constant: const arrays in the shader source (members as in constant_arrays)"
        manifest["constant_arrays"] = [m for b in manifest["uniform_blocks"] for m in b["members"]]
        manifest["constant_bytes"] = manifest["uniform_bytes"]
        manifest["uniform_blocks"], manifest["uniform_bytes"] = [], 0
        manifest["passes"][0]["uniform_blocks"] = []
        for layer in manifest["network"]["layers"]:
            layer.pop("blocks", None)  # no block holds them: they are the constant_arrays
        ubos = []
    else:
        manifest["weights"] = "uniform: std140 uniform blocks (uniform_blocks), one .bin file each"
    return MLPShader(sources[d.name][1], sources[d.name][0], ubos, manifest, d.name, sources)


def _mlp_manifest(
    table: VectorOps,
    blocks: list[UniformBlock],
    graph: OnnxGraph,
    result: VecValue,
    input_width: int,
    folded: bool,
) -> dict:
    layers = []
    for op in table.ops:
        if isinstance(op, DenseOp):
            layers.append(
                {
                    "type": "dense",
                    "in": int(op.weight.shape[1]),
                    "out": int(op.weight.shape[0]),
                    "epilogue": [a.op for a in op.epilogue],
                    "onnx_nodes": op.nodes,
                    "blocks": [c[4] for c in op.chunks],
                }
            )
        elif isinstance(op, ConcatOp):
            layers.append({"type": "concat", "widths": [p.width for p in op.parts], "onnx_nodes": op.nodes})
        else:
            operand = "vector" if op.other else ("constant" if op.const is not None else None)
            layers.append(
                {
                    "type": "map",
                    "width": op.dst.width,
                    "binop": op.binop if operand else None,
                    "operand": operand,
                    "operand_first": op.swapped,
                    "epilogue": [a.op for a in op.epilogue],
                    "onnx_nodes": op.nodes,
                }
            )
    ubo = []
    for b in blocks:
        offset, members = 0, []
        for name, arr, layout, glsl_type in b.members:
            members.append(
                {
                    "name": name,
                    "type": f"{glsl_type}[{arr.shape[0] // (4 if glsl_type == 'mat4' else 1)}]",
                    "offset": offset,
                    "vec4s": int(arr.shape[0]),
                    "layout": layout,
                }
            )
            offset += int(arr.nbytes)
        ubo.append(
            {
                "name": b.name,
                "binding": b.binding,
                "bytes": b.nbytes,
                "file": f"mlp_block{b.binding}.bin",
                "sha256": sha256_hex(b.data.tobytes()),
                "members": members,
            }
        )
    param_bytes = int(sum(op.weight.size + op.bias.size for op in table.ops if isinstance(op, DenseOp)) * 4)
    return {
        "kind": "mlp",
        "format": "neuralao-glsl-fragment",
        "format_version": FORMAT_VERSION,
        "dialects": {name: {"vertex": v, "fragment": f} for name, (v, f) in FRAGMENT_FILES.items()},
        "passes": [
            {
                "name": "mlp",
                "type": "fullscreen_triangle",
                "draw": "glDrawArrays(GL_TRIANGLES, 0, 3) with an empty VAO, viewport = G-buffer size",
                "inputs": [
                    {"texture": t, "sampler": sampler_name(unit), "unit": unit, "fetch": "texelFetch"}
                    for unit, t in enumerate(table.textures)
                ],
                "outputs": [{"texture": "ao", "location": 0}],
                "uniform_blocks": [b["name"] for b in ubo],
                "uniforms": {
                    "u_loop_guard": "int, leave at its default 0 "
                    "(keeps the large layers' loops rolled; see the shader)"
                },
            }
        ],
        "textures": {
            **_input_textures(table),
            "ao": {
                "format": "R32F (RGBA32F when output_width > 1)",
                "size": "screen",
                "channels": "network output (raw, not clamped); background 1.0",
            },
        },
        "uniform_blocks": ubo,
        "uniform_block_rule": f"std140, vec4 / mat4 arrays, every block <= {MAX_UNIFORM_BLOCK_BYTES} bytes "
        "(the portable GL_MAX_UNIFORM_BLOCK_SIZE); glsl330/es300 bind with "
        "glUniformBlockBinding(name -> binding)",
        "uniform_bytes": int(sum(b.nbytes for b in blocks)),
        "parameter_bytes_fp32": param_bytes,
        "network": {
            "onnx_input": graph.input.name,
            "onnx_output": graph.outputs[0],
            "input_width": input_width,
            "repeats": input_width // 3,
            "bindings": {name: b.to_json() for name, b in table.bindings.items()},
            "fold_repeated_input": folded,
            "output_width": result.width,
            "layers": layers,
        },
        "activations": "tanh(x) = sign(x)(1-e)/(1+e), e = exp(-2|x|); sigmoid via exp(-|x|): overflow-free",
        "es300_note": "rendering to R32F/RGBA32F on GLES needs EXT_color_buffer_float",
        "source_model_metadata": dict(graph.metadata),
    }


def _input_textures(table: VectorOps) -> dict:
    if list(table.bindings.values()) == [InputBinding("gbuffer", "xyz", table.repeats)]:
        return {
            "gbuffer": {
                "format": "RGBA32F",
                "size": "screen",
                "channels": "xyz object-space normal as stored (not renormalised), w mask: >= 0.5 foreground",
            }
        }
    out = {}
    for unit, t in enumerate(table.textures):
        uses = [
            f"{b.channels} -> ONNX input {n!r}" + (f" (x{b.repeats})" if b.repeats > 1 else "")
            for n, b in table.bindings.items()
            if b.texture == t
        ]
        if unit == 0:
            uses.append("w: mask, >= 0.5 foreground")
        out[t] = {"format": "RGBA32F", "size": "screen", "channels": "; ".join(uses)}
    return out
