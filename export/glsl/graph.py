"""What every GLSL target shares: the ONNX graph as the lowering reads it, the op-table base that
dispatches nodes to handlers named after their op, and the small helpers (float literals, attribute
and shape reading) below everything else in the package."""

from __future__ import annotations

import hashlib
import inspect
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import onnx
from onnx import numpy_helper

from neuralao.runtime.foundation.errors import NeuralaoError

# Version of both export formats (fragment and compute manifests).
FORMAT_VERSION = 1

_ONNX_DOMAINS = ("", "ai.onnx")


# --------------------------------------------------------------------------- small helpers


def glsl_float(value: float) -> str:
    """A GLSL float literal that parses back to exactly ``np.float32(value)``."""
    f = np.float32(value)
    if not np.isfinite(f):
        raise NeuralaoError(f"non-finite constant {value!r} cannot be written to GLSL")
    a = abs(float(f))
    if a != 0.0 and (a >= 1e7 or a < 1e-4):
        s = np.format_float_scientific(f, unique=True, trim="0")
    else:
        s = np.format_float_positional(f, unique=True, trim="0")
    return f"({s})" if s.startswith("-") else s


def ceil4(n: int) -> int:
    return (int(n) + 3) // 4


def _node_label(node: onnx.NodeProto, index: int) -> str:
    return f"{node.op_type} node {node.name!r}" if node.name else f"{node.op_type} node #{index}"


def _attributes(node: onnx.NodeProto) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for a in node.attribute:
        v = onnx.helper.get_attribute_value(a)
        if isinstance(v, bytes):
            v = v.decode("utf-8", "replace")
        elif isinstance(v, onnx.TensorProto):
            v = numpy_helper.to_array(v)
        elif isinstance(v, list) and v and isinstance(v[0], bytes):
            v = [x.decode("utf-8", "replace") for x in v]
        out[a.name] = v
    return out


def shape_dims(vi: onnx.ValueInfoProto) -> list[int | str | None]:
    """Declared dims of a graph input: int (static), str (symbolic) or None (unknown)."""
    t = vi.type.tensor_type
    if not t.HasField("shape"):
        return []
    out: list[int | str | None] = []
    for d in t.shape.dim:
        if d.HasField("dim_value"):
            out.append(int(d.dim_value))
        elif d.HasField("dim_param"):
            out.append(str(d.dim_param))
        else:
            out.append(None)
    return out


# Here, not in files.py: both targets' manifests hash their parameters too.
def sha256_hex(data: bytes) -> str:
    """Hex SHA-256 of ``data`` (the manifests' file and weight hashes)."""
    return hashlib.sha256(data).hexdigest()


# --------------------------------------------------------------------------- graph reading + dispatch


@dataclass
class OnnxGraph:
    """What the lowering needs from a model: constants, the real inputs, outputs, fan-out."""

    model: onnx.ModelProto
    constants: dict[str, np.ndarray]
    input: onnx.ValueInfoProto
    outputs: list[str]
    consumers: dict[str, int]
    metadata: dict[str, str]
    inputs: list[onnx.ValueInfoProto] = field(default_factory=list)  # every real input (input = inputs[0])

    @property
    def nodes(self) -> list[onnx.NodeProto]:
        return list(self.model.graph.node)


def read_graph(model: onnx.ModelProto, max_inputs: int = 1) -> OnnxGraph:
    """The graph as the lowering sees it; ``max_inputs`` real (non-initializer) inputs at most."""
    if not isinstance(model, onnx.ModelProto):
        raise NeuralaoError(f"expected an onnx.ModelProto, got {type(model).__name__}")
    g = model.graph
    constants: dict[str, np.ndarray] = {}
    for init in g.initializer:
        try:
            constants[init.name] = numpy_helper.to_array(init)
        except Exception as e:  # external data missing, unsupported dtype
            raise NeuralaoError(f"cannot read initializer {init.name!r}: {e}") from None
    inputs = [i for i in g.input if i.name not in constants]
    if len(inputs) != 1 and (max_inputs == 1 or not 1 <= len(inputs) <= max_inputs):
        want = "exactly one graph input" if max_inputs == 1 else f"1 to {max_inputs} graph inputs"
        raise NeuralaoError(f"expected {want}, found {len(inputs)}: {[i.name for i in inputs]}")
    for vi in inputs:
        if vi.type.tensor_type.elem_type != onnx.TensorProto.FLOAT:
            raise NeuralaoError(f"graph input {vi.name!r} must be float32")
    consumers: dict[str, int] = {}
    for node in g.node:
        for name in node.input:
            if name:
                consumers[name] = consumers.get(name, 0) + 1
    outputs = [o.name for o in g.output]
    if not outputs:
        raise NeuralaoError("the graph has no output")
    metadata = {p.key: p.value for p in model.metadata_props}
    return OnnxGraph(model, constants, inputs[0], outputs, consumers, metadata, inputs)


class OpTable:
    """Base of the op tables: dispatch ONNX nodes to handlers named after their op type.

    A handler's positional parameters are the node's inputs (constants arrive as numpy arrays, graph
    tensors as the table's value type, absent optional inputs as None); its keyword-only parameters
    are the ONNX attributes with their ONNX defaults.
    """

    OPS: tuple[str, ...] = ()
    target = "GLSL"

    def __init__(self, graph: OnnxGraph):
        self.graph = graph
        self.env: dict[str, Any] = dict(graph.constants)
        self.label = ""
        self.node: onnx.NodeProto | None = None

    # -- errors naming the op and the node
    def fail(self, message: str) -> NeuralaoError:
        return NeuralaoError(f"{self.label}: {message}")

    def unsupported(self, attribute: str, value: Any) -> NeuralaoError:
        return self.fail(f"unsupported attribute value {attribute}={value!r} for the {self.target} target")

    def const(self, value: Any, what: str) -> np.ndarray:
        if not isinstance(value, np.ndarray):
            raise self.fail(f"input {what} must be a constant (initializer or Constant node)")
        return value

    def fusible(self, index: int) -> bool:
        """Input ``index`` of the current node has no other reader and is not a graph output.

        Counts the readers still to come (this node included) over every name bound to the same
        value: in-place fusion and Identity bind several names to one value."""
        assert self.node is not None
        value = self.env.get(self.node.input[index])
        names = [n for n, v in self.env.items() if v is value]
        readers = sum(self.remaining.get(n, 0) + (n in self.graph.outputs) for n in names)
        return readers == 1

    def run(self) -> None:
        self.remaining = dict(self.graph.consumers)
        for index, node in enumerate(self.graph.nodes):
            self.dispatch(node, index)
            for name in node.input:
                if name:
                    self.remaining[name] -= 1
        for name in self.graph.outputs:
            if name not in self.env:
                raise NeuralaoError(f"graph output {name!r} is not produced by any node")

    def dispatch(self, node: onnx.NodeProto, index: int) -> None:
        self.node, self.label = node, _node_label(node, index)
        if node.domain not in _ONNX_DOMAINS or node.op_type not in self.OPS:
            domain = f" (domain {node.domain!r})" if node.domain not in _ONNX_DOMAINS else ""
            raise NeuralaoError(
                f"unsupported op {node.op_type!r}{domain} ({self.label}) for the {self.target} target"
            )
        handler = getattr(self, node.op_type)
        params = inspect.signature(handler).parameters.values()
        positional = [p for p in params if p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD]
        variadic = any(p.kind is inspect.Parameter.VAR_POSITIONAL for p in params)
        keywords = {p.name: p for p in params if p.kind is inspect.Parameter.KEYWORD_ONLY}
        attrs = _attributes(node)
        for name, value in attrs.items():
            if name not in keywords:
                raise self.unsupported(name, value)
        for name, p in keywords.items():
            if p.default is inspect.Parameter.empty and name not in attrs:
                raise self.fail(f"required attribute {name!r} is missing")
        if not variadic and len(node.input) > len(positional):
            raise self.fail(f"{len(node.input)} inputs given, this op takes at most {len(positional)}")
        args = []
        for name in node.input:
            if not name:
                args.append(None)
            elif name in self.env:
                args.append(self.env[name])
            else:
                raise self.fail(
                    f"input {name!r} is not produced before this node (graph not topologically sorted?)"
                )
        try:
            result = handler(*args, **attrs)
        except NeuralaoError:
            raise
        except (ValueError, TypeError, IndexError) as e:
            raise self.fail(str(e)) from None
        results = result if isinstance(result, tuple) else (result,)
        if any(node.output[len(results) :]):
            raise self.fail(
                f"only the first {len(results)} output(s) are supported, the node has {len(node.output)}"
            )
        for name, value in zip(node.output, results, strict=False):
            if name:
                self.env[name] = value

    # -- ops every table shares
    def Constant(
        self,
        *,
        value: np.ndarray | None = None,
        value_float: float | None = None,
        value_floats: list[float] | None = None,
        value_int: int | None = None,
        value_ints: list[int] | None = None,
    ) -> np.ndarray:
        for v, dt in (
            (value, None),
            (value_float, np.float32),
            (value_floats, np.float32),
            (value_int, np.int64),
            (value_ints, np.int64),
        ):
            if v is not None:
                return np.asarray(v, dtype=dt)
        raise self.fail("Constant without a value")
