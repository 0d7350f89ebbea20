"""The image target's ops beyond convolutions: space/depth rearrangements, normalisations, reductions,
softmax, Erf / Gelu / Mish and friends, variadic Sum / Mean / Min / Max, LRN, Lp pools, Dropout,
Reshape / Transpose of image tensors (channel shuffles, LayerNorm over channels), dense layers on a
flattened image, and weights built inside the graph.

Single-node (or small) graphs built with onnx.helper, seeded inputs, the generated GLSL run on Mesa
against onnxruntime: shape and dtype compared before values, TOL.glsl_op_fp32 unless a case says why
not. Images are small and odd-sized (1 x 6 x 5 x 7).
"""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from helpers import both_presets
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import generate_compute
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute_all

C, H, W = 6, 5, 7


def _model(nodes, inits=(), in_shape=(1, C, H, W), opset=19) -> onnx.ModelProto:
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, list(in_shape))],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, None)],
        [nh.from_array(np.asarray(v), k) for k, v in inits],
    )
    # no onnx.checker: it wants the output's shape, which differs per case (onnxruntime checks the model)
    return oh.make_model(graph, opset_imports=[oh.make_opsetid("", opset)])


def _x(shape=(1, C, H, W), seed=0, scale=1.0):
    return (np.random.default_rng(seed).normal(size=shape) * scale).astype(np.float32)


def _w(shape, seed=1, scale=1.0):
    return (np.random.default_rng(seed).normal(size=shape) * scale).astype(np.float32)


def _node(op, inputs=("x",), out="y", **attrs):
    name = f"my {op.lower()}" if out == "y" else f"{op.lower()} {out}"
    return oh.make_node(op, list(inputs), [out], name=name, **attrs)


def _check(model, x, tol=TOL.glsl_op_fp32):
    """Both presets' GLSL vs onnxruntime; the kinds of the ``cpu`` preset's (unfused) inner passes."""
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    program = both_presets(model, ref, lambda program: run_compute_all(program, x)["y"], tol)
    return [p["kind"] for p in program.manifest["passes"][1:-1]]


# ----------------------------------------------------------------------------- space <-> depth


@pytest.mark.parametrize("mode", ["DCR", "CRD"])
@pytest.mark.parametrize("dynamic", [False, True])
def test_depth_to_space(mode, dynamic):
    shape = (1, 8, "H", "W") if dynamic else (1, 8, 3, 5)
    assert _check(
        _model([_node("DepthToSpace", blocksize=2, mode=mode)], in_shape=shape), _x((1, 8, 3, 5))
    ) == ["gather"]


@pytest.mark.parametrize("dynamic", [False, True])
def test_space_to_depth(dynamic):
    shape = (1, 3, "H", "W") if dynamic else (1, 3, 6, 4)
    _check(_model([_node("SpaceToDepth", blocksize=2)], in_shape=shape), _x((1, 3, 6, 4)))


def test_space_to_depth_crd():
    """Opset 25's mode="CRD" (onnxruntime 1.32 does not know it): against the spec's reshape/transpose."""
    x = _x((1, 3, 6, 4))
    got = run_compute_all(
        generate_compute(
            _model([_node("SpaceToDepth", blocksize=2, mode="CRD")], in_shape=x.shape, opset=25)
        ),
        x,
    )["y"]
    want = x.reshape(1, 3, 3, 2, 2, 2).transpose(0, 1, 3, 5, 2, 4).reshape(1, 12, 3, 2)
    assert got.shape == want.shape and np.array_equal(got, want)


# ----------------------------------------------------------------------------- normalisation


def test_instance_normalization():
    inits = [("s", _w(C)), ("b", _w(C, 2))]
    kinds = _check(
        _model([_node("InstanceNormalization", ("x", "s", "b"), epsilon=1e-3)], inits), _x(scale=3.0)
    )
    assert kinds == ["moments", "normalize"]


@pytest.mark.parametrize("opset,per", [(18, "group"), (21, "channel")])
def test_group_normalization(opset, per):
    n = 3 if per == "group" else C
    inits = [("s", _w(n)), ("b", _w(n, 2))]
    _check(_model([_node("GroupNormalization", ("x", "s", "b"), num_groups=3)], inits, opset=opset), _x())


@pytest.mark.parametrize("axis,shape", [(1, (C, 1, 1)), (-3, (C, H, W))])
def test_layer_normalization_over_channels_and_image(axis, shape):
    """axis 1 with a per-channel scale; over C, H, W the scale may vary in space only if constant there:
    a (C, H, W) scale that does is refused, naming the reason."""
    inits = [("s", _w(shape)), ("b", _w(shape, 2))]
    model = _model([_node("LayerNormalization", ("x", "s", "b"), axis=axis)], inits)
    if shape == (C, 1, 1):
        _check(model, _x())
    else:
        with pytest.raises(NeuralaoError, match="my layernormalization.*varies over the image"):
            generate_compute(model)


def test_layer_norm_over_channels_as_torch_writes_it():
    """x.permute(0, 2, 3, 1) -> nn.LayerNorm(C) -> permute back: the transposes cost no pass."""
    nodes = [
        _node("Transpose", out="a", perm=[0, 2, 3, 1]),
        _node("LayerNormalization", ("a", "s", "b"), out="c"),
        oh.make_node("Transpose", ["c"], ["y"], name="back", perm=[0, 3, 1, 2]),
    ]
    assert _check(_model(nodes, [("s", _w(C)), ("b", _w(C, 2))]), _x()) == ["moments", "normalize"]


def test_group_norm_as_torch_writes_it():
    """nn.GroupNorm(3, C) under torch.onnx.export: Reshape to (1, G, -1), InstanceNormalization with unit
    scale, Reshape back to Shape(x), Mul and Add per channel."""
    nodes = [
        _node("Reshape", ("x", "g"), out="a"),
        _node("InstanceNormalization", ("a", "one", "zero"), out="b"),
        _node("Shape", out="s"),
        _node("Reshape", ("b", "s"), out="c"),
        _node("Mul", ("c", "w"), out="d"),
        _node("Add", ("d", "bias")),
    ]
    inits = [
        ("g", np.array([0, 3, -1])),
        ("one", np.ones(3, np.float32)),
        ("zero", np.zeros(3, np.float32)),
        ("w", _w((C, 1, 1))),
        ("bias", _w((C, 1, 1), 2)),
    ]
    assert _check(_model(nodes, inits), _x()) == ["moments", "normalize"]


# ----------------------------------------------------------------------------- reductions and softmax

REDUCE_OPS = ["ReduceMean", "ReduceMax", "ReduceSum", "ReduceL2", "ReduceMin", "ReduceL1", "ReduceSumSquare"]


@pytest.mark.parametrize("op", REDUCE_OPS)
@pytest.mark.parametrize("axes,keepdims", [([2, 3], 1), ([1], 1), ([1, 2, 3], 0)])
def test_reduce(op, axes, keepdims):
    model = _model([_node(op, ("x", "a"), keepdims=keepdims)], [("a", np.array(axes))])
    # sums of 210 magnitudes reach ~170: float32 summation order differs from onnxruntime's by a few ulp
    tol = TOL.glsl_op_fp32 * (10 if axes == [1, 2, 3] else 1)
    assert _check(model, _x(), tol) == ["reduce"]


def test_reduce_attribute_axes_and_grouped_channels():
    """Opset 13 (axes attribute) over H and W, and a mean over channel groups of a (1, 2, 3, H, W) view."""
    _check(_model([_node("ReduceMean", axes=[2, 3])], opset=13), _x())
    nodes = [
        _node("Reshape", ("x", "s"), out="a"),
        _node("ReduceMean", ("a", "ax"), out="b"),
        _node("Reshape", ("b", "t")),
    ]
    inits = [("s", np.array([1, 2, 3, H, W])), ("ax", np.array([2])), ("t", np.array([1, 2, H, W]))]
    _check(_model(nodes, inits), _x())


@pytest.mark.parametrize("op", ["Softmax", "LogSoftmax"])
def test_softmax_over_channels(op):
    _check(_model([_node(op, axis=1)]), _x(scale=4.0))


def test_softmax_over_space_is_refused():
    with pytest.raises(NeuralaoError, match="my softmax.*over channels only"):
        generate_compute(_model([_node("Softmax", axis=-1)]))


def test_softmax_after_dense_layer_opset11():
    """Flatten -> Gemm -> Softmax (opset 11: softmax over the flattened tail): logits of shape (1, 10)."""
    nodes = [
        _node("Flatten", out="f"),
        _node("Gemm", ("f", "w", "c"), out="g", transB=1),
        _node("Softmax", ("g",)),
    ]
    inits = [("w", _w((10, C * H * W), scale=0.1)), ("c", _w(10, 2))]
    assert _check(_model(nodes, inits, opset=11), _x()) == ["conv", "softmax"]


# ----------------------------------------------------------------------------- elementwise


@pytest.mark.parametrize(
    "op,attrs,scale",
    [
        ("Erf", {}, 2.0),
        ("Gelu", {}, 3.0),
        ("Gelu", {"approximate": "tanh"}, 3.0),
        ("Mish", {}, 6.0),
        ("Abs", {}, 1.0),
        ("Neg", {}, 1.0),
        ("Sign", {}, 1.0),
        ("Softsign", {}, 3.0),
        ("Exp", {}, 2.0),
        ("Floor", {}, 3.0),
        ("Ceil", {}, 3.0),
    ],
)
def test_activation(op, attrs, scale):
    # values near +-3 grow to 20 under Exp: 1e-5 absolute is 5e-7 relative there
    tol = TOL.glsl_op_fp32 * (3 if op == "Exp" else 1)
    assert _check(_model([_node(op, **attrs)], opset=20), _x(scale=scale), tol) == ["elementwise"]


@pytest.mark.parametrize(
    "op,exponent",
    [
        ("Sqrt", None),
        ("Log", None),
        ("Reciprocal", None),
        ("Pow", 0.5),
        ("Pow", 2.0),
        ("Pow", 3.0),
        ("Pow", -1.0),
        ("Pow", 1.7),
    ],
)
def test_positive_domain_ops(op, exponent):
    """On |x| + 0.5 (5 channels: the guarded padding lanes exist); Pow with a constant exponent."""
    nodes = [_node("Abs", out="a"), _node("Add", ("a", "half"), out="b")]
    nodes.append(_node(op, ("b", "e") if exponent is not None else ("b",)))
    inits = [("half", np.float32(0.5))] + ([("e", np.float32(exponent))] if exponent is not None else [])
    _check(_model(nodes, inits, in_shape=(1, 5, H, W)), _x((1, 5, H, W)))


@pytest.mark.parametrize("op", ["Sum", "Mean", "Max", "Min"])
def test_variadic(op):
    nodes = [_node("Relu", out="a"), _node("Sigmoid", out="b"), _node(op, ("x", "a", "b"))]
    _check(_model(nodes), _x())


def test_variadic_with_constant_and_one_input():
    _check(_model([_node("Sum", ("x", "c"))], [("c", _w((C, 1, 1)))]), _x())
    _check(_model([_node("Max", ("x", "c"))], [("c", np.float32(0.2))]), _x())
    _check(_model([_node("Mean", ("x",))]), _x())


def test_dropout_at_inference():
    assert _check(_model([_node("Dropout", ("x", "r"))], [("r", np.float32(0.3))]), _x()) == []
    with pytest.raises(NeuralaoError, match="my dropout.*training_mode"):
        generate_compute(
            _model([_node("Dropout", ("x", "r", "t"))], [("r", np.float32(0.3)), ("t", np.array(True))])
        )


# ----------------------------------------------------------------------------- LRN and Lp pools


@pytest.mark.parametrize("size", [3, 5])
def test_lrn(size):
    assert _check(_model([_node("LRN", size=size, alpha=0.1, beta=0.75, bias=2.0)]), _x(scale=2.0)) == ["lrn"]


@pytest.mark.parametrize(
    "attrs",
    [
        dict(kernel_shape=[2, 2], strides=[2, 2]),
        dict(kernel_shape=[3, 3], pads=[1, 1, 1, 1], p=3),
        dict(kernel_shape=[3, 2], strides=[2, 1], p=1, auto_pad="SAME_UPPER"),
    ],
)
def test_lp_pool(attrs):
    assert _check(_model([_node("LpPool", **attrs)]), _x()) == ["pool_lp"]


def test_global_lp_pool():
    _check(_model([_node("GlobalLpPool", p=3)]), _x())


# ----------------------------------------------------------------------------- views and constants


def test_channel_shuffle():
    """ShuffleNet's Reshape (1, g, C/g, H, W) -> Transpose (0, 2, 1, 3, 4) -> Reshape: one gather pass."""
    nodes = [
        _node("Reshape", ("x", "s1"), out="a"),
        _node("Transpose", ("a",), out="b", perm=[0, 2, 1, 3, 4]),
        _node("Reshape", ("b", "s2")),
    ]
    inits = [("s1", np.array([1, 2, 3, H, W])), ("s2", np.array([1, C, H, W]))]
    assert _check(_model(nodes, inits), _x()) == ["gather"]


def test_weights_from_constant_of_shape_beyond_64k_elements():
    """onnx's light models build every weight with ConstantOfShape: 300 x 6 x 7 x 7 = 88,200 elements."""
    fill = nh.from_array(np.array([0.01], np.float32))
    nodes = [
        _node("ConstantOfShape", ("s",), out="w", value=fill),
        _node("Conv", ("x", "w"), pads=[3, 3, 3, 3]),
    ]
    _check(_model(nodes, [("s", np.array([300, C, 7, 7]))]), _x())


def test_expand_tile_range_fold():
    """Per-channel constants built with Range, Expand and Tile, then applied to the image."""
    nodes = [
        _node("Range", ("r0", "r1", "r2"), out="r"),
        _node("Reshape", ("r", "s"), out="a"),
        _node("Expand", ("a", "e"), out="b"),
        _node("Tile", ("b", "t"), out="c"),
        _node("Mul", ("x", "c")),
    ]
    inits = [
        ("r0", np.float32(0.5)),
        ("r1", np.float32(2.0)),
        ("r2", np.float32(0.5)),
        ("s", np.array([3, 1, 1])),
        ("e", np.array([3, 1, 1])),
        ("t", np.array([2, 1, 1])),
    ]
    _check(_model(nodes, inits), _x())


def test_refusals_name_op_node_and_reason():
    _msg = "my reshape.*cuts across"
    with pytest.raises(NeuralaoError, match=_msg):
        generate_compute(_model([_node("Reshape", ("x", "s"))], [("s", np.array([1, 15, 14]))]))
    with pytest.raises(NeuralaoError, match="my gemm.*flattened image"):
        generate_compute(_model([_node("Gemm", ("x", "w"))], [("w", _w((W, 3)))]))
