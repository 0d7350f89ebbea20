"""Fuzz: random image graphs, random MLPs and random meshes through the whole pipeline.

Every case is a seeded numpy draw whose seed is the test id (``-k 'image_graph and 7]'`` replays one),
so CI is deterministic. What each case must end in:

* a one-line :class:`NeuralaoError` naming the op and node it failed on (unsupported ops and
  attribute values are drawn on purpose; a graph holding one must be rejected), or
* generated GLSL run on Mesa that matches onnxruntime: shape and dtype first, then every element
  within ``TOL.glsl_fuzz_bound`` times its first-order forward-error bound (built next to each graph,
  see :class:`_ImageGraph` and :func:`_random_mlp`), finite wherever onnxruntime is finite;
  never another exception type, never a NaN.

Meshes: degenerate, duplicated and flipped triangles at scales 1e-4..1e5 and offsets up to 1e6 give
a clean error or finite AO in [0, 1], unchanged (within Monte-Carlo noise) when the same mesh is
uniformly scaled and offset; the G-buffer of such a mesh is finite and consistent.

Sizes are small on purpose: each new GLSL program costs 0.2-3 s to compile on llvmpipe.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import onnx
import pytest
from helpers import mc_bound
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import generate_compute, generate_mlp_fragment
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute_all, run_mlp_fragment

OPSET = 19
U = 2.0**-24  # unit roundoff of float32


def _gamma(n: int) -> float:
    """Higham's gamma_n = n u / (1 - n u): relative error bound of an n-term float32 sum of products."""
    return n * U / (1 - n * U)


def _ort_all(model: onnx.ModelProto, x: np.ndarray) -> list[np.ndarray]:
    return run_onnxruntime(model.SerializeToString(), {model.graph.input[0].name: x})


def _assert_clean_error(err: NeuralaoError, culprit: onnx.NodeProto | None, nodes) -> None:
    """A one-line message naming the op and the node it failed on: the culprit drawn on purpose, or
    a node before it (e.g. a scale that is not exact on a symbolic size)."""
    msg = str(err)
    assert msg and "\n" not in msg
    stop = list(nodes).index(culprit) + 1 if culprit is not None else len(nodes)
    assert any(f"{n.op_type} node {n.name!r}" in msg for n in list(nodes)[:stop]), msg


def _assert_parity(got: np.ndarray, ref: np.ndarray, bound: np.ndarray, what: str) -> float:
    """Shape, dtype, finiteness, then |got - ref| <= TOL.glsl_fuzz_bound * bound; returns max ratio."""
    assert got.shape == ref.shape, f"{what}: shape {got.shape} != {ref.shape}"
    assert got.dtype == ref.dtype == np.float32, f"{what}: dtype {got.dtype} / {ref.dtype}"
    assert not np.isnan(got).any(), f"{what}: NaN in the GLSL output"
    finite = np.isfinite(ref)
    assert np.isfinite(got[finite]).all(), f"{what}: non-finite GLSL output where onnxruntime is finite"
    assert np.array_equal(got[~finite], ref[~finite]), f"{what}: infinities differ"
    assert np.isfinite(bound).all() and (bound >= 0).all()
    diff = np.abs(got[finite].astype(np.float64) - ref[finite])
    limit = TOL.glsl_fuzz_bound * bound[finite].astype(np.float64)
    bad = diff > limit
    assert not bad.any(), (
        f"{what}: {int(bad.sum())} elements off; worst |diff| {diff[bad].max():.3g} "
        f"with bound {limit[bad][np.argmax(diff[bad])]:.3g} (|ref| {np.abs(ref[finite][bad]).max():.3g})"
    )
    return float((diff / np.maximum(bound[finite], 1e-30)).max(initial=0.0))


# ================================================================================ 1. image graphs


@dataclass
class _T:
    """A tensor of the random graph: value name, bound name, static size (1, c, h, w)."""

    name: str
    bound: str
    c: int
    h: int
    w: int


@dataclass
class _ImageGraph:
    """A random graph and, alongside, the nodes that propagate its error bound (same names + 'e_')."""

    rng: np.random.Generator
    nodes: list = field(default_factory=list)
    inits: dict = field(default_factory=dict)
    bound_nodes: list = field(default_factory=list)
    culprit: onnx.NodeProto | None = None  # first node the generator must reject
    count: int = 0

    def fresh(self, prefix: str) -> str:
        self.count += 1
        return f"{prefix}{self.count}"

    def const(self, value, prefix="k") -> str:
        name = self.fresh(prefix)
        self.inits[name] = np.asarray(value)
        return name

    def node(self, op: str, inputs: list[str], output: str, reject: bool = False, **attrs) -> onnx.NodeProto:
        n = oh.make_node(op, inputs, [output], name=f"{op.lower()} {self.count}", **attrs)
        self.nodes.append(n)
        if reject and self.culprit is None:
            self.culprit = n
        return n

    def b(self, op: str, inputs: list[str], **attrs) -> str:
        """A bound-graph node; returns its output name."""
        out = self.fresh("e")
        self.bound_nodes.append(oh.make_node(op, inputs, [out], **attrs))
        return out

    def scalar(self, v: float) -> str:
        return self.const(np.float32(v), "s")

    def abs_of(self, t: _T) -> str:
        return self.b("Abs", [t.name])

    def add_scaled_abs(self, t: _T, factor: float) -> str:
        """bound(t) + factor * |t|"""
        return self.b("Add", [t.bound, self.b("Mul", [self.abs_of(t), self.scalar(factor)])])


def _conv_size(n: int, k: int, s: int, d: int, pad: int) -> int:
    return (n + pad - d * (k - 1) - 1) // s + 1


def _ceil_pool_size(n: int, k: int, s: int, d: int, pad_begin: int, pad_end: int) -> int:
    """ceil_mode=1: the last window is dropped when it would start in the trailing padding."""
    q = -(-(n + pad_begin + pad_end - d * (k - 1) - 1) // s)
    return q if q * s >= n + pad_begin else q + 1


def _weights(rng: np.random.Generator, shape) -> np.ndarray:
    # Mostly moderate, sometimes huge: with inputs up to 1e3 the activations then see 1e3..1e4+.
    scale = rng.choice([0.05, 0.3, 1.0, 10.0, 100.0])
    return (rng.normal(size=shape) * scale).astype(np.float32)


def _op_conv(g: _ImageGraph, x: _T) -> _T | None:
    rng = g.rng
    kh, kw = (int(v) for v in rng.integers(1, 5, 2))
    sy, sx = (int(v) for v in rng.integers(1, 4, 2)) if rng.random() < 0.4 else (1, 1)
    dy, dx = (int(v) for v in rng.integers(1, 3, 2)) if rng.random() < 0.3 else (1, 1)
    attrs: dict = {}
    group = 1
    auto = rng.choice(["NOTSET"] * 6 + ["SAME_UPPER", "SAME_LOWER", "VALID"])
    if auto in ("SAME_UPPER", "SAME_LOWER"):
        dy = dx = 1  # onnxruntime rejects dilated SAME convolutions
        if rng.random() < 0.8:
            sy = sx = 1  # SAME with strides: pads depend on the size (kept rarer than stride 1)
    if auto == "NOTSET":
        reach = (dy * (kh - 1) + 1, dx * (kw - 1) + 1)
        pads = [int(rng.integers(0, reach[i % 2])) for i in range(4)]  # top, left, bottom, right
        attrs["pads"] = pads
    else:
        attrs["auto_pad"] = str(auto)
        if auto == "VALID":
            pads = [0, 0, 0, 0]
        else:
            th, tw = dy * (kh - 1), dx * (kw - 1)
            # Output ceil(n / s); pads split as ONNX says (only needed for the sizes here).
            oh_, ow_ = -(-x.h // sy), -(-x.w // sx)
            th = max(0, (oh_ - 1) * sy + th + 1 - x.h)
            tw = max(0, (ow_ - 1) * sx + tw + 1 - x.w)
            pads = [th // 2, tw // 2, th - th // 2, tw - tw // 2]
    if (sy, sx) != (1, 1):
        attrs["strides"] = [sy, sx]
    if (dy, dx) != (1, 1):
        attrs["dilations"] = [dy, dx]
    if rng.random() < 0.5:
        attrs["kernel_shape"] = [kh, kw]
    cout = int(rng.integers(1, 9))
    if rng.random() < 0.08 and x.c % 2 == 0 and cout % 2 == 0:
        group = 2  # grouped: a block-diagonal dense conv in GLSL
        attrs["group"] = 2
    h = _conv_size(x.h, kh, sy, dy, pads[0] + pads[2])
    w = _conv_size(x.w, kw, sx, dx, pads[1] + pads[3])
    if h < 1 or w < 1:
        return None
    wt = _weights(rng, (cout, x.c // group, kh, kw))
    inputs = [x.name, g.const(wt, "w")]
    bias = rng.random() < 0.7
    b = _weights(rng, (cout,)) if bias else np.zeros(cout, np.float32)
    if bias:
        inputs.append(g.const(b, "b"))
    out = g.fresh("v")
    g.node("Conv", inputs, out, **attrs)
    # |GLSL - ort| <= |W| * bound(x) + 2 gamma_n (|W| |x| + |b|), n = taps + bias (each side's rounding).
    n = (x.c // group) * kh * kw + 1
    src = g.add_scaled_abs(x, 2 * _gamma(n))
    e = g.b("Conv", [src, g.const(np.abs(wt), "aw"), g.const(2 * _gamma(n) * np.abs(b), "ab")], **attrs)
    return _T(out, e, cout, h, w)


def _op_batchnorm(g: _ImageGraph, x: _T) -> _T:
    rng = g.rng
    c = x.c
    gamma = (rng.normal(size=c) * rng.choice([0.5, 5.0])).astype(np.float32)
    beta = (rng.normal(size=c) * rng.choice([0.1, 10.0])).astype(np.float32)
    mean = (rng.normal(size=c) * rng.choice([0.1, 10.0])).astype(np.float32)
    var = rng.uniform(1e-3, 4.0, c).astype(np.float32)
    eps = float(rng.choice([1e-5, 1e-3]))
    out = g.fresh("v")
    names = [g.const(a, "bn") for a in (gamma, beta, mean, var)]
    g.node("BatchNormalization", [x.name, *names], out, epsilon=eps)
    s = np.abs(gamma.astype(np.float64) / np.sqrt(var.astype(np.float64) + eps))
    # y = s (x - mean) + beta, folded into the conv weights in GLSL: the constant terms are rounded
    # inside a sum of up to 64 terms there (gamma_64 covers every conv drawn here).
    shape = (1, c, 1, 1)
    src = g.add_scaled_abs(x, 2 * _gamma(64))
    k = 2 * _gamma(64) * (s * np.abs(mean) + np.abs(beta) + np.abs(beta - s * mean))
    e = g.b(
        "Add",
        [
            g.b("Mul", [src, g.const(s.reshape(shape).astype(np.float32))]),
            g.const(k.reshape(shape).astype(np.float32)),
        ],
    )
    return _T(out, e, c, x.h, x.w)


def _op_activation(g: _ImageGraph, x: _T) -> _T:
    rng = g.rng
    op = str(rng.choice(["Relu", "LeakyRelu", "Sigmoid", "Tanh", "Clip", "Identity"]))
    out = g.fresh("v")
    inputs, attrs = [x.name], {}
    if op == "LeakyRelu":
        attrs["alpha"] = float(rng.choice([0.01, 0.2, -0.5, 1.5]))
    if op == "Clip":
        lo, hi = sorted(rng.normal(size=2) * rng.choice([1.0, 100.0]))
        which = rng.integers(0, 3)
        inputs += [g.const(np.float32(lo), "lo") if which != 2 else "", g.const(np.float32(hi), "hi")]
        if which == 1:
            inputs = inputs[:2]  # min only
    g.node(op, inputs, out, **attrs)
    if op in ("Relu", "Clip", "Identity"):  # 1-Lipschitz and exact
        e = x.bound
    elif op == "LeakyRelu":  # alpha x rounds once on each side
        a = abs(attrs["alpha"])
        e = g.b("Mul", [g.add_scaled_abs(x, 2 * U), g.scalar(max(1.0, a))])
    else:
        # Slope at the point of the interval [|x| - bound, |x| + bound] nearest 0, plus the two
        # libraries' exp/tanh rounding (absolute, outputs are at most 1 in magnitude).
        near = g.b("Relu", [g.b("Sub", [g.abs_of(x), x.bound])])
        if op == "Tanh":
            t = g.b("Tanh", [near])
            slope = g.b("Sub", [g.scalar(1.0), g.b("Mul", [t, t])])
        else:
            s = g.b("Sigmoid", [near])
            slope = g.b("Mul", [s, g.b("Sub", [g.scalar(1.0), s])])
        e = g.b("Add", [g.b("Mul", [x.bound, slope]), g.scalar(64 * U)])
    return _T(out, e, x.c, x.h, x.w)


def _op_pool(g: _ImageGraph, x: _T) -> _T | None:
    rng = g.rng
    op = str(rng.choice(["AveragePool", "MaxPool"]))
    kh, kw = (int(v) for v in rng.integers(1, 4, 2))
    sy, sx = (int(v) for v in rng.integers(1, 4, 2))
    dy, dx = (int(v) for v in rng.integers(1, 3, 2)) if op == "MaxPool" and rng.random() < 0.3 else (1, 1)
    pads = [
        int(rng.integers(0, kh)),
        int(rng.integers(0, kw)),
        int(rng.integers(0, kh)),
        int(rng.integers(0, kw)),
    ]
    attrs = {"kernel_shape": [kh, kw], "strides": [sy, sx], "pads": pads}
    if (dy, dx) != (1, 1):
        attrs["dilations"] = [dy, dx]
    if op == "AveragePool":
        attrs["count_include_pad"] = int(rng.integers(0, 2))
    if rng.random() < 0.06:
        attrs["ceil_mode"] = 1
        h = _ceil_pool_size(x.h, kh, sy, dy, pads[0], pads[2])
        w = _ceil_pool_size(x.w, kw, sx, dx, pads[1], pads[3])
    else:
        h = _conv_size(x.h, kh, sy, dy, pads[0] + pads[2])
        w = _conv_size(x.w, kw, sx, dx, pads[1] + pads[3])
    if h < 1 or w < 1:
        return None
    out = g.fresh("v")
    g.node(op, [x.name], out, **attrs)
    if op == "MaxPool":  # |max a - max b| <= max |a - b|
        e = g.b("MaxPool", [x.bound], **attrs)
    else:  # a positive-weight mean: mean of the bounds plus the sum's and the division's rounding
        e = g.b("AveragePool", [g.add_scaled_abs(x, 2 * _gamma(kh * kw + 1))], **attrs)
    return _T(out, e, x.c, h, w)


COORDS = ("half_pixel", "pytorch_half_pixel", "align_corners", "asymmetric", "half_pixel_symmetric")
NEAREST = ("round_prefer_floor", "round_prefer_ceil", "floor", "ceil")


def _nearest_ties(g: _ImageGraph, x: _T, resize_inputs: list[str], attrs: dict) -> str:
    """Bound term for nearest-mode ties: 2 max|x| (per channel) where a row's or a column's source
    coordinate lies within 1e-4 of a rounding boundary (an integer for floor / ceil, a half for the
    round modes), else 0.

    There the op is discontinuous and float32 decides the pixel: ONNX's formula with a float32 scale
    (e.g. x / fl(8/7) = 3.4999998 for an exact 3.5) and onnxruntime's own arithmetic (which returns
    the exact-rational pixel for ``sizes`` but not always) legitimately disagree. Coordinates come
    from a linear Resize of an index ramp with the same inputs (it returns the clamped coordinate).
    """
    ones = g.b("ConstantOfShape", [g.b("Shape", [x.name])], value=nh.from_array(np.ones(1, np.float32)))
    near = []
    for axis in (2, 3):
        ramp = g.b("Sub", [g.b("CumSum", [ones, g.const(np.int64(axis), "ax")]), g.scalar(1.0)])
        lin = {**attrs, "mode": "linear"}
        lin.pop("nearest_mode", None)
        c = g.b("Resize", [ramp, *resize_inputs], **lin)
        frac = g.b("Sub", [c, g.b("Floor", [c])])
        if attrs.get("nearest_mode") in ("floor", "ceil"):
            dist = g.b("Min", [frac, g.b("Sub", [g.scalar(1.0), frac])])
        else:
            dist = g.b("Abs", [g.b("Sub", [frac, g.scalar(0.5)])])
        near.append(g.b("Cast", [g.b("Less", [dist, g.scalar(1e-4)])], to=TensorProto.FLOAT))
    gmax = g.b("GlobalMaxPool", [g.abs_of(x)])
    return g.b("Mul", [g.b("Max", near), g.b("Mul", [gmax, g.scalar(2.0)])])


def _op_resize(g: _ImageGraph, x: _T) -> _T | None:
    rng = g.rng
    mode = str(
        rng.choice(
            ["linear", "linear", "nearest", "nearest", "cubic"]
            if rng.random() < 0.1
            else ["linear", "nearest"]
        )
    )
    attrs = {"mode": mode, "coordinate_transformation_mode": str(rng.choice(COORDS))}
    if mode == "nearest":
        attrs["nearest_mode"] = str(rng.choice(NEAREST))
    if rng.random() < 0.5:
        sc = [float(rng.choice([0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 0.6])) for _ in range(2)]
        h, w = (int(np.float32(n) * np.float32(s)) for n, s in ((x.h, sc[0]), (x.w, sc[1])))
        inputs = [x.name, "", g.const(np.array([1, 1, *sc], np.float32), "sc")]
    else:
        h, w = (int(v) for v in rng.integers(1, 14, 2))
        inputs = [x.name, "", "", g.const(np.array([1, x.c, h, w], np.int64), "sz")]
    if h < 1 or w < 1:
        return None
    out = g.fresh("v")
    if mode == "cubic":  # cubic itself is supported (tests/test_glsl_coverage.py); resizing C is not
        inputs = [x.name, "", "", g.const(np.array([1, x.c + 1, max(h, 1), max(w, 1)], np.int64), "sz")]
    g.node("Resize", inputs, out, reject=mode == "cubic", **attrs)
    if mode == "cubic":
        return _T(out, x.bound, x.c, h, w)  # never evaluated: the generator rejects it
    propagated = g.b("Resize", [x.bound, *inputs[1:]], **attrs)
    if mode == "nearest":
        e = g.b("Add", [propagated, _nearest_ties(g, x, inputs[1:], attrs)])
    else:
        # Blend weights are computed in float32 on both sides from coordinates of size <= L (a few
        # ulps of L each): a weight error delta moves the result by <= delta * 2 max |x| (per channel).
        big = max(x.h, x.w, h, w) + 1
        gmax = g.b("GlobalMaxPool", [g.abs_of(x)])
        e = g.b(
            "Add",
            [
                g.b(
                    "Add",
                    [
                        propagated,
                        g.b(
                            "Mul",
                            [g.b("Resize", [g.abs_of(x), *inputs[1:]], **attrs), g.scalar(2 * _gamma(8))],
                        ),
                    ],
                ),
                g.b("Mul", [gmax, g.scalar(2 * 2 * 16 * U * big)]),
            ],
        )
    return _T(out, e, x.c, h, w)


def _op_concat(g: _ImageGraph, x: _T, pool: list[_T]) -> _T:
    rng = g.rng
    same = [t for t in pool if (t.h, t.w) == (x.h, x.w)]
    other = same[int(rng.integers(0, len(same)))]
    parts = [x, other] if rng.random() < 0.7 else [other, x, x]
    reject = rng.random() < 0.06
    out = g.fresh("v")
    if reject and all(p.c == x.c for p in parts):
        g.node("Concat", [p.name for p in parts], out, reject=True, axis=2)
        return _T(out, x.bound, x.c, x.h * len(parts), x.w)
    g.node("Concat", [p.name for p in parts], out, axis=int(rng.choice([1, -3])))
    return _T(out, g.b("Concat", [p.bound for p in parts], axis=1), sum(p.c for p in parts), x.h, x.w)


def _op_unsupported(g: _ImageGraph, x: _T) -> _T:
    """Ops outside the compute table: a clean error."""
    op = str(
        g.rng.choice(["Round", "Hardmax", "Tan", "Atan"])
    )  # outside the table (Log, Erf, Softmax, Exp joined it)
    out = g.fresh("v")
    g.node(op, [x.name], out, reject=True)
    return _T(out, x.bound, x.c, x.h, x.w)


def _random_image_graph(seed: int):
    """(model, bound_model, x, culprit): a chain of 2-6 random ops over a small random input.

    bound_model has the same input; its outputs are the error bounds of the model's outputs.
    """
    rng = np.random.default_rng(seed)
    g = _ImageGraph(rng)
    c, h, w = int(rng.integers(1, 7)), int(rng.integers(3, 14)), int(rng.integers(3, 14))
    scale = float(rng.choice([1.0, 30.0, 1000.0]))
    x = (rng.normal(size=(1, c, h, w)) * scale).astype(np.float32)
    inp = _T("x", "", c, h, w)
    inp.bound = g.b("Mul", ["x", g.scalar(0.0)])  # the input reaches both sides exactly
    cur, pool = inp, [inp]
    n_ops = int(rng.integers(2, 7))
    while len(pool) <= n_ops:
        r = rng.random()
        if r < 0.3:
            nxt = _op_conv(g, cur)
        elif r < 0.4:
            nxt = _op_batchnorm(g, cur)
        elif r < 0.62:
            nxt = _op_activation(g, cur)
        elif r < 0.74:
            nxt = _op_pool(g, cur)
        elif r < 0.86:
            nxt = _op_resize(g, cur)
        elif r < 0.98:
            nxt = _op_concat(g, cur, pool)
        else:
            nxt = _op_unsupported(g, cur)
        if nxt is not None and nxt.c * nxt.h * nxt.w <= 4096:
            cur = nxt
            pool.append(cur)
    outputs = [cur]
    if rng.random() < 0.3:  # an intermediate as a second output: it must not receive later fusions
        extra = pool[int(rng.integers(1, len(pool) - 1))] if len(pool) > 2 else None
        if extra is not None and extra is not cur:
            outputs.append(extra)
    symbolic = rng.random() < 0.3
    dims = [1, c, "H", "W"] if symbolic else [1, c, h, w]
    value_info = [oh.make_tensor_value_info(inp.name, TensorProto.FLOAT, dims)]
    outs = [oh.make_tensor_value_info(t.name, TensorProto.FLOAT, [None] * 4) for t in outputs]
    inits = [nh.from_array(v, k) for k, v in g.inits.items()]
    used = {i for n in g.nodes for i in n.input}
    model = oh.make_model(
        oh.make_graph(g.nodes, f"fuzz{seed}", value_info, outs, [i for i in inits if i.name in used]),
        opset_imports=[oh.make_opsetid("", OPSET)],
    )
    bound_outs = [oh.make_tensor_value_info(t.bound, TensorProto.FLOAT, [None] * 4) for t in outputs]
    bound = oh.make_model(
        oh.make_graph(g.nodes + g.bound_nodes, f"bound{seed}", value_info, bound_outs, inits),
        opset_imports=[oh.make_opsetid("", OPSET)],
    )
    return model, bound, x, g.culprit, symbolic


IMAGE_SEEDS = range(48)


def _check_image_case(seed: int) -> float | None:
    """One random image graph: clean error (returns None) or parity (returns max |diff| / bound)."""
    model, bound_model, x, culprit, symbolic = _random_image_graph(seed)
    onnx.checker.check_model(model, full_check=True)
    try:
        program = generate_compute(model)
    except NeuralaoError as e:
        _assert_clean_error(e, culprit, model.graph.node)
        return None
    assert culprit is None, f"generate_compute accepted {culprit.op_type} node {culprit.name!r}"
    if symbolic:
        # A symbolic graph is exact for inputs that are a multiple of its pad multiple (otherwise it
        # reflect-pads by design): grow the input to the next multiple.
        m = program.pad_multiple
        hh, ww = -(-x.shape[2] // m) * m, -(-x.shape[3] // m) * m
        x = (
            np.random.default_rng(seed).normal(size=(1, x.shape[1], hh, ww)).astype(np.float32)
            * np.abs(x).max()
        )
    refs = _ort_all(model, x)
    bounds = _ort_all(bound_model, x)
    got = run_compute_all(program, x)
    assert list(got) == [o.name for o in model.graph.output]
    ratios = [
        _assert_parity(g, ref, np.broadcast_to(bound, ref.shape), f"seed {seed} output {name!r}")
        for (name, g), ref, bound in zip(got.items(), refs, bounds, strict=True)
    ]
    return max(ratios)


@pytest.mark.parametrize("seed", IMAGE_SEEDS)
def test_random_image_graph_glsl_parity_or_clean_error(seed):
    _check_image_case(seed)


# ================================================================================ 2. per-pixel MLPs


def _act_bound(op: str, x: np.ndarray, d: np.ndarray, alpha: float = 0.0) -> np.ndarray:
    """Bound on |GLSL - ort| after an activation, from the bound d on its input x (float64)."""
    if op in ("Relu", "Clip", None):
        return d
    if op == "LeakyRelu":
        return max(1.0, abs(alpha)) * (d + 2 * U * np.abs(x))
    near = np.maximum(np.abs(x) - d, 0.0)  # the slope's largest value is where |x| is least
    slope = 1.0 - np.tanh(near) ** 2 if op == "Tanh" else np.exp(-near) / (1.0 + np.exp(-near)) ** 2
    return d * slope + 64 * U


def _act_value(op: str | None, x: np.ndarray, alpha: float, lo: float | None, hi: float | None) -> np.ndarray:
    if op == "Relu":
        return np.maximum(x, 0.0)
    if op == "LeakyRelu":
        return np.where(x >= 0, x, alpha * x)
    if op == "Tanh":
        return np.tanh(x)
    if op == "Sigmoid":
        return 0.5 * (1.0 + np.tanh(0.5 * x))
    if op == "Clip":
        return np.clip(x, -np.inf if lo is None else lo, np.inf if hi is None else hi)
    return x


def _random_mlp(seed: int, n: np.ndarray):
    """(model, culprit, ref64 fn): a random dense chain (N, 3k) -> (N, m <= 4) and, for the normals
    n (N, 3) float64, its float64 value and the bound on |GLSL - ort| of every output element."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, 5))
    nodes, inits, culprit = [], {}, None
    x = np.tile(n, (1, k))  # float64 reference values, (N, 3k)
    d = np.zeros_like(x)
    name, width = "n", 3 * k
    layers = int(rng.integers(1, 4))

    def const(v, prefix):
        key = f"{prefix}{len(inits)}"
        inits[key] = np.asarray(v)
        return key

    def add(op, inputs, reject=False, **attrs):
        nonlocal culprit
        out = f"h{len(nodes)}"
        node = oh.make_node(op, inputs, [out], name=f"{op.lower()} #{len(nodes)}", **attrs)
        nodes.append(node)
        if reject and culprit is None:
            culprit = node
        return out

    for li in range(layers):
        out_w = int(rng.integers(1, 5)) if li == layers - 1 else int(rng.integers(1, 25))
        wscale = float(rng.choice([0.1, 1.0, 10.0, 100.0]))
        w = (rng.normal(size=(out_w, width)) * wscale).astype(np.float32)  # (out, in)
        b = (rng.normal(size=out_w) * wscale).astype(np.float32)
        w64, b64 = w.astype(np.float64), b.astype(np.float64)
        if rng.random() < 0.5:
            trans_b = int(rng.integers(0, 2))
            alpha, beta = float(rng.choice([1.0, 0.5, -2.0])), float(rng.choice([1.0, 0.25]))
            bmat = w if trans_b else w.T.copy()
            c_shape = [(out_w,), (1, out_w), (1,)][int(rng.integers(0, 3))]
            if c_shape == (1,):
                b = b[:1]
                b64 = np.full(out_w, float(b[0]))
            reject = rng.random() < 0.05
            extra = {"transA": 1} if reject else {}
            name = add(
                "Gemm",
                [name, const(bmat, "B"), const(b.reshape(c_shape), "C")],
                reject,
                alpha=alpha,
                beta=beta,
                transB=trans_b,
                **extra,
            )
            w64, b64 = w64 * alpha, b64 * beta
        else:
            name = add("MatMul", [name, const(w.T.copy(), "B")])
            if rng.random() < 0.7:
                c = const(b, "C")
                name = add("Add", [c, name] if rng.random() < 0.3 else [name, c])
            else:
                b64 = np.zeros(out_w)
        y = x @ w64.T + b64
        d = d @ np.abs(w64).T + 2 * _gamma(width + 3) * (np.abs(x) @ np.abs(w64).T + np.abs(b64))
        x, width = y, out_w
        op = rng.choice(["Tanh", "Sigmoid", "Relu", "LeakyRelu", "Clip", "none"])
        op = None if op == "none" else str(op)
        alpha, lo, hi = float(rng.choice([0.01, 0.3, -1.5])), None, None
        if op is not None:
            inputs, attrs = [name], {}
            if op == "LeakyRelu":
                attrs["alpha"] = alpha
            if op == "Clip":
                lo, hi = sorted(float(v) for v in rng.normal(size=2) * wscale)
                inputs += [const(np.float32(lo), "lo"), const(np.float32(hi), "hi")]
                lo, hi = float(np.float32(lo)), float(np.float32(hi))
            name = add(op, inputs, **attrs)
            d = _act_bound(op, x, d, alpha)
            x = _act_value(op, x, alpha, lo, hi)
        if rng.random() < 0.05:
            name = add("Softmax", [name], reject=True)
    graph = oh.make_graph(
        nodes,
        f"mlp{seed}",
        [oh.make_tensor_value_info("n", TensorProto.FLOAT, ["N", 3 * k])],
        [oh.make_tensor_value_info(name, TensorProto.FLOAT, ["N", width])],
        [nh.from_array(v, key) for key, v in inits.items()],
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", OPSET)])
    return model, culprit, k, x, d


MLP_SEEDS = range(16)
DIALECTS = ("glsl330", "es300", "glsl430")


@pytest.mark.parametrize("seed", MLP_SEEDS)
def test_random_mlp_fragment_parity_or_clean_error(seed):
    rng = np.random.default_rng(1000 + seed)
    normals = rng.normal(size=(100, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals.astype(np.float32).astype(np.float64)  # exactly what both sides read
    model, culprit, k, _, _ = _random_mlp(seed, normals)
    onnx.checker.check_model(model, full_check=True)
    try:
        shader = generate_mlp_fragment(model, dialect=DIALECTS[seed % 3], fold_repeated_input=seed % 2 == 0)
    except NeuralaoError as e:
        _assert_clean_error(e, culprit, model.graph.node)
        return
    assert culprit is None, f"generate_mlp_fragment accepted {culprit.op_type} node {culprit.name!r}"
    m = shader.output_width
    for count in (0, 1, 100):
        n = normals[:count]
        _, _, _, value, bound = _random_mlp(seed, n)
        (ref,) = _ort_all(model, np.tile(n, (1, k)).astype(np.float32))
        assert ref.shape == (count, m) and np.isfinite(value).all()
        # One row of pixels, all foreground.
        got = run_mlp_fragment(shader, n.reshape(1, count, 3), np.ones((1, count), bool))
        assert got.shape == ((1, count) if m == 1 else (1, count, m))
        _assert_parity(got.reshape(count, m), ref, bound.astype(np.float32), f"seed {seed}, {count} normals")
    # Background pixels are exactly 1, whatever the network.
    mask = np.arange(10) % 3 != 0
    got = run_mlp_fragment(shader, normals[:10].reshape(2, 5, 3), mask.reshape(2, 5)).reshape(10, -1)
    assert np.all(got[~mask] == 1.0) and np.isfinite(got).all()


# ================================================================================ 3. random meshes


def _random_mesh(seed: int) -> tuple[np.ndarray, np.ndarray, str]:
    """(vertices (n, 3) float64, faces (m, 3) int64, kind): a small triangle soup with degenerate
    (repeated-index, collinear), duplicated and flipped faces; kind "ok", "degenerate" (only
    degenerate faces) or "bad" (a NaN vertex or an index out of range)."""
    rng = np.random.default_rng(seed)
    n_tri = int(rng.integers(1, 10))
    tris = rng.uniform(-1.0, 1.0, (n_tri, 3, 3))
    if rng.random() < 0.6:  # a floor under the soup, so some points are occluded
        tris = np.r_[
            tris,
            [[[-2, -2, -1.2], [2, -2, -1.2], [2, 2, -1.2]], [[-2, -2, -1.2], [2, 2, -1.2], [-2, 2, -1.2]]],
        ]
    verts = tris.reshape(-1, 3)
    faces = np.arange(len(verts)).reshape(-1, 3)
    extra = [faces[int(rng.integers(0, len(faces)))][::-1] for _ in range(int(rng.integers(0, 3)))]  # flipped
    extra += [faces[int(rng.integers(0, len(faces)))] for _ in range(int(rng.integers(0, 3)))]  # duplicates
    a, b = verts[0], verts[1]
    base = len(verts)
    verts = np.r_[verts, [a + 0.5 * (b - a), a + 2.0 * (b - a)]]  # collinear with a, b
    degenerate = [[0, 1, base], [0, 1, base + 1], [2, 2, 1], [0, 0, 0]]
    faces = np.r_[faces, np.array(extra, np.int64).reshape(-1, 3), degenerate]
    faces = faces[rng.permutation(len(faces))]
    kind = str(rng.choice(["ok"] * 8 + ["degenerate", "bad"]))
    if kind == "degenerate":
        faces = np.array(degenerate, np.int64)
    elif kind == "bad":
        if rng.random() < 0.5:
            verts[int(rng.integers(0, len(verts)))] = np.nan
        else:
            faces[int(rng.integers(0, len(faces))), int(rng.integers(0, 3))] = len(verts) + 3
    return verts, faces, kind


def _surface_points(scene, rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray]:
    """count random points (count, 3) float64 on the scene's faces and those faces' normals (count, 3),
    each turned to a random side (triangle soup has no inside)."""
    idx = rng.integers(0, len(scene.faces), count)
    bary = rng.dirichlet([1.0, 1.0, 1.0], count)
    pts = np.einsum("ij,ijk->ik", bary, scene.triangles[idx])
    return pts, scene.face_normals[idx] * rng.choice([-1.0, 1.0], (count, 1))


def _assert_ao(ao: np.ndarray, valid: np.ndarray, shape) -> None:
    assert ao.shape == valid.shape == shape and ao.dtype == np.float32 and valid.dtype == bool
    assert np.isfinite(ao).all() and ((ao >= 0) & (ao <= 1)).all()


MESH_SEEDS = range(20)
MESH_RAYS = 64


@pytest.mark.parametrize("seed", MESH_SEEDS)
def test_random_mesh_labels_and_gbuffer_finite_and_scale_invariant(seed):
    from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
    from neuralao.pipeline.geometry.camera import Camera, orbit
    from neuralao.pipeline.geometry.scene import scene_from_arrays
    from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings

    rng = np.random.default_rng(2000 + seed)
    verts, faces, kind = _random_mesh(seed)
    scale = float(10.0 ** rng.uniform(-4, 5))
    offset = rng.uniform(-1e6, 1e6, 3) * rng.random()
    if kind != "ok":
        # (Only the original arrays for "degenerate": at offset 1e6 float64 rounding turns the
        # collinear faces into genuine, if thin, triangles.)
        for v in (verts, verts * scale + offset) if kind == "bad" else (verts,):
            with pytest.raises(NeuralaoError, match="NaN|outside|degenerate"):
                scene_from_arrays(v, faces)
        return
    scene = scene_from_arrays(verts, faces)
    assert scene.dropped_faces >= 4 and np.isfinite(scene.face_normals).all()
    moved = scene.scaled(scale, offset)
    # The same arrays, transformed, pass validation too (float64 rounding at 1e6 may keep slivers
    # of the collinear faces, so their count can differ; every label below uses ``moved``).
    scene_from_arrays(verts * scale + offset, faces)

    settings = LabelSettings(rays=MESH_RAYS, kernel=str(rng.choice(["binary", "obscurance"])))
    lab, lab_moved = Labeller(scene, settings), Labeller(moved, settings)
    pts, normals = _surface_points(scene, rng, 40)
    ao, valid = lab.ao_at_points(pts, normals)
    ao_m, valid_m = lab_moved.ao_at_points(pts * scale + offset, normals)
    _assert_ao(ao, valid, (40,))
    _assert_ao(ao_m, valid_m, (40,))
    # Same seed, same rays up to float rounding: within MC noise of a difference of two estimates.
    p = ao.astype(np.float64)
    assert np.all(np.abs(ao_m - ao) <= mc_bound(p, MESH_RAYS / 2)), (scale, offset)

    # G-buffer at a tiny size, and labels of its pixels, for the mesh and its moved copy.
    cam = orbit(scene, 1, 11, 9, seed=seed)[0]
    pose = cam.pose.copy()
    pose[:3, 3] = pose[:3, 3] * scale + offset
    cam_m = Camera(pose, 11, 9, cam.yfov, cam.znear * scale, cam.zfar * scale)
    frames = []
    for sc, c in ((scene, cam), (moved, cam_m)):
        with GBufferRenderer(sc) as r:
            f = r.render(c)
        fg = f["mask"]
        assert np.array_equal(fg, f["tri_id"] >= 0) and f["tri_id"].max() < len(sc.faces)
        for key in ("depth", "position", "normal_obj", "normal_cam"):
            assert np.isfinite(f[key]).all(), key
        assert (f["depth"][fg] > 0).all() and (f["depth"][~fg] == 0).all()
        assert np.abs(np.linalg.norm(f["normal_cam"][fg], axis=-1) - 1).max(initial=0) < 1e-5
        frames.append(f)
    a, b = frames
    assert abs(int(a["mask"].sum()) - int(b["mask"].sum())) <= max(
        1, TOL.gbuffer_id_mismatch_frac * a["mask"].size
    )
    ao_f, valid_f = lab.label_frame(a)
    _assert_ao(ao_f, valid_f, a["mask"].shape)
    assert (ao_f[~a["mask"]] == 1).all()
    # The moved scene labels the same pixels (same triangle ids, moved pose) the same way.
    ao_fm, valid_fm = lab_moved.label_frame({**a, "pose": pose})
    _assert_ao(ao_fm, valid_fm, a["mask"].shape)
    fg = a["mask"]
    assert np.all(np.abs(ao_fm - ao_f)[fg] <= mc_bound(ao_f[fg].astype(np.float64), MESH_RAYS / 2))
    ao_b, valid_b = lab_moved.label_frame(b)
    _assert_ao(ao_b, valid_b, b["mask"].shape)
