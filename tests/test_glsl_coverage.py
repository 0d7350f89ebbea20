"""Attribute coverage of the compute (image) target: every ONNX attribute value of a
supported op is implemented, or refused naming the op, the node and the attribute.

Single-node (or small) graphs built with onnx.helper, seeded inputs, generated GLSL run on Mesa against
onnxruntime; shape and dtype compared before values, TOL.glsl_op_fp32 unless a case says why not.
Images are small (1 x 3 x 9 x 11: odd sizes, so ceil / floor and odd SAME padding are exercised).
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
from neuralao.runtime.glsl_runner import run_compute

OPSET = 19
C, H, W = 3, 9, 11


def _model(nodes, inits=(), in_shape=(1, C, H, W), opset=OPSET, out="y") -> onnx.ModelProto:
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, list(in_shape))],
        [oh.make_tensor_value_info(out, TensorProto.FLOAT, ["n", "c", "h", "w"])],
        [nh.from_array(np.asarray(v), k) for k, v in inits],
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", opset)])
    onnx.checker.check_model(model)
    return model


def _x(shape=(1, C, H, W), seed=0, scale=1.0):
    return (np.random.default_rng(seed).normal(size=shape) * scale).astype(np.float32)


def _w(shape, seed=1, scale=0.3):
    return (np.random.default_rng(seed).normal(size=shape) * scale).astype(np.float32)


def _check(model, x, tol=TOL.glsl_op_fp32, reference=None):
    """GLSL of ``model`` under both presets vs onnxruntime on ``reference`` (default: the same model);
    returns the ``cpu`` preset's (unfused) program."""
    ref = run_onnxruntime((reference or model).SerializeToString(), {"x": x})[0]
    return both_presets(model, ref, lambda program: run_compute(program, x), tol)


def _kinds(program):
    return [(p["kind"], p["ops"]) for p in program.manifest["passes"][1:-1]]  # without pad and crop


def _node(op, inputs=("x",), **attrs):
    return oh.make_node(op, list(inputs), ["y"], name=f"my {op.lower()}", **attrs)


# ----------------------------------------------------------------------------- Conv / ConvTranspose

CONV_CASES = {
    "same_upper_stride2": (dict(auto_pad="SAME_UPPER", strides=[2, 2]), (4, C, 3, 3), 1),
    "same_lower_stride2_k2": (dict(auto_pad="SAME_LOWER", strides=[2, 2]), (4, C, 2, 2), 1),
    "valid_stride2": (dict(auto_pad="VALID", strides=[2, 2]), (2, C, 3, 3), 1),
    "depthwise": (dict(group=C, pads=[1, 1, 1, 1]), (C, 1, 3, 3), C),
    "depthwise_stride2_dil2": (
        dict(group=C, strides=[2, 2], dilations=[2, 2], pads=[2, 1, 2, 1]),
        (C, 1, 3, 3),
        C,
    ),
    "depthwise_multiplier2": (dict(group=C, pads=[1, 1, 1, 1]), (2 * C, 1, 3, 3), C),
    "group3_of_6": (dict(group=3, pads=[0, 1, 0, 1]), (6, 2, 1, 3), 3),
}


@pytest.mark.parametrize("case", sorted(CONV_CASES))
def test_conv(case):
    attrs, wshape, group = CONV_CASES[case]
    cin = wshape[1] * group
    inits = [("w", _w(wshape)), ("b", _w((wshape[0],), seed=2))]
    program = _check(
        _model([_node("Conv", ("x", "w", "b"), **attrs)], inits, (1, cin, H, W)), _x((1, cin, H, W))
    )
    kind = "conv_depthwise" if group == cin == wshape[0] else "conv"
    assert _kinds(program) == [(kind, ["Conv"])]


CONV_TRANSPOSE_CASES = {
    "stride2_pads_outpad": (dict(strides=[2, 2], pads=[1, 1, 1, 1], output_padding=[1, 1]), (C, 4, 3, 3), 1),
    "stride_2x3_asym_pads": (dict(strides=[2, 3], pads=[0, 1, 1, 0]), (C, 2, 2, 3), 1),
    "dilation2": (dict(dilations=[2, 2]), (C, 2, 3, 3), 1),
    "group3": (dict(group=3, strides=[2, 2]), (C, 2, 3, 3), 3),
    "same_upper": (dict(auto_pad="SAME_UPPER", strides=[2, 2]), (C, 2, 4, 3), 1),
    "same_lower": (dict(auto_pad="SAME_LOWER", strides=[2, 2]), (C, 2, 4, 3), 1),
    "valid": (dict(auto_pad="VALID", strides=[2, 1]), (C, 2, 3, 3), 1),
    "output_shape": (dict(strides=[2, 2], output_shape=[18, 21]), (C, 2, 3, 3), 1),
}


@pytest.mark.parametrize("case", sorted(CONV_TRANSPOSE_CASES))
def test_conv_transpose(case):
    attrs, wshape, group = CONV_TRANSPOSE_CASES[case]
    inits = [("w", _w(wshape)), ("b", _w((wshape[1] * group,), seed=2))]
    program = _check(_model([_node("ConvTranspose", ("x", "w", "b"), **attrs)], inits), _x())
    assert _kinds(program) == [("conv_transpose", ["ConvTranspose"])]


def test_conv_batchnorm_and_arithmetic_fold():
    """Conv -> BatchNormalization -> Mul -> Add fold into the conv weights; the activation is an epilogue."""
    rng = np.random.default_rng(4)
    inits = [
        ("w", _w((C, 1, 3, 3))),
        ("s", rng.uniform(0.5, 2, C).astype(np.float32)),
        ("bb", _w((C,), 5)),
        ("m", _w((C,), 6)),
        ("v", rng.uniform(0.1, 3, C).astype(np.float32)),
        ("k", _w((C, 1, 1), 7)),
        ("c", np.float32(0.25)),
    ]
    nodes = [
        oh.make_node("Conv", ["x", "w"], ["a"], name="dw", group=C, pads=[1, 1, 1, 1]),
        oh.make_node("BatchNormalization", ["a", "s", "bb", "m", "v"], ["b"], name="bn"),
        oh.make_node("Mul", ["b", "k"], ["d"], name="mul"),
        oh.make_node("Add", ["c", "d"], ["e"], name="add"),
        oh.make_node("Elu", ["e"], ["y"], name="elu"),
    ]
    program = _check(_model(nodes, inits), _x())
    assert _kinds(program) == [("conv_depthwise", ["Conv", "BatchNormalization", "Mul", "Add", "Elu"])]


# ----------------------------------------------------------------------------- pooling

POOL_CASES = [
    ("AveragePool", dict(kernel_shape=[3, 3], strides=[2, 2], pads=[1, 1, 1, 1], ceil_mode=1)),
    (
        "AveragePool",
        dict(kernel_shape=[3, 3], strides=[2, 2], pads=[1, 1, 1, 1], ceil_mode=1, count_include_pad=1),
    ),
    ("AveragePool", dict(kernel_shape=[2, 2], strides=[3, 3], ceil_mode=1, count_include_pad=1)),
    ("AveragePool", dict(kernel_shape=[2, 3], dilations=[2, 2], pads=[1, 2, 1, 0], count_include_pad=1)),
    ("AveragePool", dict(kernel_shape=[2, 2], dilations=[3, 2], strides=[2, 1])),
    ("AveragePool", dict(kernel_shape=[3, 3], strides=[2, 2], auto_pad="SAME_UPPER", count_include_pad=1)),
    ("AveragePool", dict(kernel_shape=[2, 2], strides=[2, 2], auto_pad="SAME_LOWER")),
    ("AveragePool", dict(kernel_shape=[3, 2], strides=[2, 2], auto_pad="VALID", ceil_mode=1)),
    ("MaxPool", dict(kernel_shape=[3, 3], strides=[2, 2], ceil_mode=1)),
    ("MaxPool", dict(kernel_shape=[2, 2], strides=[2, 2], auto_pad="SAME_LOWER")),
    ("MaxPool", dict(kernel_shape=[3, 3], strides=[2, 2], pads=[1, 1, 1, 1], ceil_mode=1, storage_order=1)),
]


@pytest.mark.parametrize("op,attrs", POOL_CASES)
def test_pool(op, attrs):
    _check(_model([_node(op, **attrs)]), _x())


@pytest.mark.parametrize("op", ["GlobalAveragePool", "GlobalMaxPool"])
def test_global_pool(op):
    program = _check(_model([_node(op)]), _x(scale=3.0))
    assert program.manifest["textures"][program.manifest["outputs"][0]["texture"]]["height"]["offset"] == 1


def _same_pads(n, k, s, d, upper):
    """The ONNX spec's auto_pad SAME padding (begin, end), written out independently of export/glsl/."""
    total = max(0, (-(-n // s) - 1) * s + (k - 1) * d + 1 - n)
    small, big = total // 2, total - total // 2
    return (small, big) if upper else (big, small)


@pytest.mark.parametrize(
    "op,attrs",
    [
        ("Conv", dict(auto_pad="SAME_UPPER", strides=[3, 2], dilations=[2, 1], kernel_shape=[3, 2])),
        ("Conv", dict(auto_pad="SAME_LOWER", strides=[2, 2], dilations=[2, 3], kernel_shape=[2, 3])),
        ("MaxPool", dict(auto_pad="SAME_UPPER", strides=[2, 3], dilations=[2, 1], kernel_shape=[3, 3])),
        ("AveragePool", dict(auto_pad="SAME_LOWER", strides=[2, 2], dilations=[2, 2], kernel_shape=[2, 3])),
    ],
)
def test_same_with_dilations(op, attrs):
    """onnxruntime refuses (Conv) or mis-sizes (pools) SAME with dilations, so the reference is the same
    op with the spec's SAME padding given explicitly."""
    (kh, kw), (sy, sx), (dy, dx) = attrs["kernel_shape"], attrs["strides"], attrs["dilations"]
    upper = attrs["auto_pad"] == "SAME_UPPER"
    (t, b), (left, r) = _same_pads(H, kh, sy, dy, upper), _same_pads(W, kw, sx, dx, upper)
    explicit = {**attrs, "auto_pad": "NOTSET", "pads": [t, left, b, r]}
    inputs, inits = (("x", "w"), [("w", _w((2, C, kh, kw)))]) if op == "Conv" else (("x",), [])
    model = _model([_node(op, inputs, **attrs)], inits)
    _check(model, _x(), reference=_model([_node(op, inputs, **explicit)], inits))


def test_symbolic_sizes_same_ceil_and_transpose():
    """Dynamic H, W: SAME stride-2 conv, a ceil_mode pool and a stride-2 ConvTranspose keep exact sizes."""
    nodes = [
        oh.make_node("Conv", ["x", "w"], ["a"], name="conv", auto_pad="SAME_UPPER", strides=[2, 2]),
        oh.make_node(
            "AveragePool",
            ["a"],
            ["b"],
            name="pool",
            kernel_shape=[3, 3],
            strides=[2, 2],
            pads=[1, 1, 1, 1],
            ceil_mode=1,
            count_include_pad=1,
        ),
        oh.make_node(
            "ConvTranspose",
            ["b", "t"],
            ["y"],
            name="up",
            strides=[2, 2],
            output_padding=[1, 1],
            pads=[1, 1, 1, 1],
        ),
    ]
    model = _model(nodes, [("w", _w((4, C, 3, 3))), ("t", _w((4, 2, 3, 3), 3))], (1, C, "H", "W"))
    program = _check(model, _x((1, C, 8, 12)))
    assert program.pad_multiple == 4
    _check(model, _x((1, C, 12, 16), seed=5))


# ----------------------------------------------------------------------------- activations and arithmetic


@pytest.mark.parametrize(
    "op,attrs,scale",
    [
        ("Elu", {}, 30.0),
        ("Elu", {"alpha": 0.5}, 3.0),
        ("Softplus", {}, 30.0),  # |x| to ~100: max(x, 0) + log(1 + exp(-|x|)) must not overflow
        ("HardSigmoid", {}, 3.0),
        ("HardSigmoid", {"alpha": 0.5, "beta": 0.1}, 3.0),
        ("HardSwish", {}, 6.0),  # both kinks (x = -3, 3) and the linear tail
        ("Sin", {}, 3.0),
        ("Cos", {}, 3.0),
    ],
)
def test_activation(op, attrs, scale):
    program = _check(_model([_node(op, **attrs)]), _x(scale=scale))
    assert _kinds(program) == [("elementwise", [op])]


@pytest.mark.parametrize("shape", [(C, 1, 1), (1, C, 1, 1), (1,)])
def test_prelu(shape):
    _check(_model([_node("PRelu", ("x", "s"))], [("s", _w(shape, scale=1.0))]), _x())


ARITH_CONSTANTS = {
    "scalar": np.float32(0.7),
    "per_channel": _w((C, 1, 1), 9, 1.0) + 2.0,
    "per_channel_4d": _w((1, C, 1, 1), 10, 1.0) - 2.0,
}


@pytest.mark.parametrize("op", ["Add", "Sub", "Mul", "Div"])
@pytest.mark.parametrize("const", sorted(ARITH_CONSTANTS))
@pytest.mark.parametrize("first", [False, True])
def test_arithmetic_with_constant(op, const, first):
    inputs = ("c", "x") if first else ("x", "c")
    # constant / x: inputs kept away from 0 (|x| >= 0.5) so the quotient stays O(10)
    x = _x() if not (first and op == "Div") else (np.sign(_x()) * (0.5 + np.abs(_x()))).astype(np.float32)
    _check(_model([_node(op, inputs)], [("c", ARITH_CONSTANTS[const])]), x)


@pytest.mark.parametrize("op", ["Add", "Sub", "Mul", "Div"])
def test_arithmetic_two_images(op):
    """Residual-style: op(conv(x), sigmoid(x) + 0.5), two image tensors of equal shape, then Relu fused."""
    nodes = [
        oh.make_node("Conv", ["x", "w"], ["a"], name="conv", pads=[1, 1, 1, 1]),
        oh.make_node("Sigmoid", ["x"], ["s"], name="sig"),
        oh.make_node("Add", ["s", "half"], ["b"], name="shift"),
        oh.make_node(op, ["a", "b"], ["r"], name=f"my {op}"),
        oh.make_node("Relu", ["r"], ["y"], name="relu"),
    ]
    program = _check(_model(nodes, [("w", _w((C, C, 3, 3))), ("half", np.float32(0.5))]), _x())
    assert ("binary", [op, "Relu"]) in _kinds(program)


def test_residual_add_of_input():
    nodes = [
        oh.make_node("Conv", ["x", "w"], ["a"], name="conv", pads=[1, 1, 1, 1]),
        oh.make_node("Add", ["x", "a"], ["y"], name="residual"),
    ]
    _check(_model(nodes, [("w", _w((C, C, 3, 3)))]), _x())


def test_broadcast_squeeze_excitation_and_one_channel():
    """x * sigmoid(GlobalAveragePool(x)) (1x1 broadcast) / (1-channel conv + 2) (channel broadcast)."""
    nodes = [
        oh.make_node("GlobalAveragePool", ["x"], ["g"], name="gap"),
        oh.make_node("Sigmoid", ["g"], ["s"], name="sig"),
        oh.make_node("Mul", ["x", "s"], ["m"], name="excite"),
        oh.make_node("Conv", ["x", "w", "b"], ["one"], name="conv1", pads=[1, 1, 1, 1]),
        oh.make_node("Div", ["m", "one"], ["y"], name="div"),
    ]
    inits = [("w", _w((1, C, 3, 3), scale=0.1)), ("b", np.full(1, 2.0, np.float32))]
    _check(_model(nodes, inits), _x())


def test_constant_folding():
    nodes = [
        oh.make_node("Add", ["c1", "c2"], ["c"], name="fold"),
        oh.make_node("Mul", ["x", "c"], ["y"], name="mul"),
    ]
    _check(_model(nodes, [("c1", _w((C, 1, 1))), ("c2", np.float32(1.5))]), _x())


# ----------------------------------------------------------------------------- Pad


@pytest.mark.parametrize(
    "mode,pads,value",
    [
        ("constant", [0, 0, 1, 2, 0, 0, 3, 0], 0.5),
        ("constant", [0, 0, -1, 2, 0, 0, 1, -3], None),  # negative pads crop
        ("reflect", [0, 0, 2, 3, 0, 0, 1, 4], None),
        ("edge", [0, 0, 3, 1, 0, 0, 2, 2], None),
        ("wrap", [0, 0, 2, 3, 0, 0, 4, 1], None),
    ],
)
def test_pad(mode, pads, value):
    inputs, inits = ["x", "p"], [("p", np.array(pads, np.int64))]
    if value is not None:
        inputs.append("v")
        inits.append(("v", np.array(value, np.float32)))
    program = _check(_model([_node("Pad", inputs, mode=mode)], inits), _x())
    assert _kinds(program) == [("spatial_pad", ["Pad"])]


def test_pad_axes_input_and_opset2_attributes():
    inits = [("p", np.array([1, 2, 2, 0], np.int64)), ("a", np.array([2, -1], np.int64))]
    _check(_model([_node("Pad", ("x", "p", "", "a"), mode="reflect")], inits), _x())
    _check(_model([_node("Pad", pads=[0, 0, 2, 1, 0, 0, 0, 3], value=-1.5)], opset=10), _x())


# ----------------------------------------------------------------------------- Resize / Upsample

RESIZE_CASES = [
    # attributes, scales or None, sizes or None
    (dict(mode="cubic"), [1, 1, 2, 2], None),
    (
        dict(mode="cubic", cubic_coeff_a=-0.5, coordinate_transformation_mode="asymmetric"),
        [1, 1, 1.5, 0.5],
        None,
    ),
    (dict(mode="cubic", exclude_outside=1), [1, 1, 2, 1.5], None),
    (dict(mode="cubic", coordinate_transformation_mode="align_corners"), None, [1, C, 5, 14]),
    (dict(mode="cubic", coordinate_transformation_mode="pytorch_half_pixel"), [1, 1, 0.5, 2], None),
    (dict(mode="cubic", coordinate_transformation_mode="half_pixel_symmetric"), [1, 1, 1.5, 2], None),
    (dict(mode="linear", antialias=1), [1, 1, 0.5, 0.5], None),
    (dict(mode="linear", antialias=1, exclude_outside=1), None, [1, C, 4, 3]),
    (dict(mode="cubic", antialias=1), [1, 1, 0.5, 0.75], None),
    (dict(mode="cubic", antialias=1, exclude_outside=1, cubic_coeff_a=-0.5), [1, 1, 0.4, 0.6], None),
    (dict(mode="linear", antialias=1), [1, 1, 2, 1.5], None),  # upscaling: plain bilinear
    (dict(mode="linear", keep_aspect_ratio_policy="not_larger", axes=[2, 3]), None, [6, 30]),
    (dict(mode="nearest", keep_aspect_ratio_policy="not_smaller", axes=[2, 3]), None, [6, 30]),
    (dict(mode="cubic", keep_aspect_ratio_policy="not_larger", axes=[3, 2]), None, [20, 27]),
]


@pytest.mark.parametrize("attrs,scales,sizes", RESIZE_CASES)
def test_resize(attrs, scales, sizes):
    inits = [("s", np.array(scales, np.float32))] if scales else [("s", np.array(sizes, np.int64))]
    inputs = ["x", "", "s"] if scales else ["x", "", "", "s"]
    _check(_model([_node("Resize", inputs, **attrs)], inits), _x())


@pytest.mark.parametrize(
    "mode,roi,sizes,extrapolation",
    [
        ("linear", [0.1, 0.2, 0.8, 0.9], [7, 8], 0.0),
        ("nearest", [-0.2, 0.1, 1.1, 0.7], [8, 6], -2.0),  # part of the crop box lies outside
        ("cubic", [0.0, -0.1, 0.6, 1.0], [5, 13], 1.5),
    ],
)
def test_resize_tf_crop_and_resize(mode, roi, sizes, extrapolation):
    attrs = dict(
        mode=mode,
        coordinate_transformation_mode="tf_crop_and_resize",
        extrapolation_value=extrapolation,
        axes=[2, 3],
    )
    inits = [("r", np.array(roi, np.float32)), ("s", np.array(sizes, np.int64))]
    _check(_model([_node("Resize", ("x", "r", "", "s"), **attrs)], inits), _x())


@pytest.mark.parametrize(
    "mode,scales,opset",
    [
        ("nearest", [1.0, 1.0, 2.0, 3.0], 9),
        ("linear", [1.0, 1.0, 2.0, 1.5], 9),
        ("nearest", [1.0, 1.0, 3.0, 2.0], 8),
        ("linear", [1.0, 1.0, 1.5, 2.0], 7),
        ("nearest", [1.0, 1.0, 1.0, 1.5], 7),
    ],
)
def test_upsample(mode, scales, opset):
    if opset == 9:
        model = _model(
            [_node("Upsample", ("x", "s"), mode=mode)], [("s", np.array(scales, np.float32))], opset=9
        )
    else:
        model = _model([_node("Upsample", mode=mode, scales=scales)], opset=opset)
    _check(model, _x())


# -------------------------------------------------------------------------- refusals name op, node, attribute


def _error(model, *needles):
    with pytest.raises(NeuralaoError) as e:
        generate_compute(model)
    msg = str(e.value)
    assert "\n" not in msg
    for n in needles:
        assert n in msg, msg


def test_refused_attribute_values():
    _error(_model([_node("Concat", ("x", "x"), axis=3)]), "Concat", "my concat", "axis=3")
    # Clip-6 bounds as attributes (opset 11 made them inputs)
    _error(_model([_node("Clip", min=-1.0, max=1.0)], opset=6), "Clip", "my clip", "attribute value max=1.0")
    model = _model([_node("Upsample", mode="linear", scales=[1.0, 1.0, 2.0, 0.5])], opset=8)
    _error(model, "Upsample", "my upsample", "scales")
    _error(
        _model(
            [_node("Resize", ("x", "", "", "s"), mode="linear", antialias=1)],
            [("s", np.array([1, C, 4, 4]))],
            (1, C, "H", "W"),
        ),
        "Resize",
        "my resize",
        "antialias",
    )
    _error(
        _model([_node("Pad", ("x", "p"))], [("p", np.array([0, 1, 0, 0, 0, 0, 0, 0]))]),
        "Pad",
        "my pad",
        "pads",
    )
    _error(_model([_node("Mul", ("x", "c"))], [("c", _w((H, W)))]), "Mul", "my mul", "B", "broadcast")


def test_refused_global_pool_on_padded_dynamic_input():
    nodes = [
        oh.make_node("AveragePool", ["x"], ["a"], name="half", kernel_shape=[2, 2], strides=[2, 2]),
        oh.make_node("GlobalAveragePool", ["a"], ["y"], name="gap"),
    ]
    _error(_model(nodes, in_shape=(1, C, "H", "W")), "GlobalAveragePool", "gap", "pad_multiple")


# ------------------------------------------------------------------------ constant folding (shape arithmetic)


def _const(name, value):
    return oh.make_node("Constant", [], [name], name=f"const {name}", value=nh.from_array(np.asarray(value)))


def test_pad_with_pads_computed_as_torch_writes_them():
    """torch.onnx.export of F.pad(x, (1, 2, 3, 0), mode="reflect") (and Conv2d(padding_mode="reflect")):
    the pads come from ConstantOfShape, Concat, Reshape, Slice, Transpose, Reshape and Cast."""
    nodes = [
        _const("lrtb", np.array([1, 2, 3, 0], np.int64)),
        _const("n4", np.array([4], np.int64)),
        oh.make_node(
            "ConstantOfShape", ["n4"], ["zeros"], name="zeros", value=nh.from_array(np.zeros(1, np.int64))
        ),
        oh.make_node("Concat", ["lrtb", "zeros"], ["p8"], name="cat", axis=0),
        _const("s2", np.array([-1, 2], np.int64)),
        oh.make_node("Reshape", ["p8", "s2"], ["p42"], name="pairs"),
        _const("st", np.array([-1], np.int64)),
        _const("en", np.array([-(2**63) + 1], np.int64)),
        _const("ax", np.array([0], np.int64)),
        _const("sp", np.array([-1], np.int64)),
        oh.make_node("Slice", ["p42", "st", "en", "ax", "sp"], ["rev"], name="reverse"),
        oh.make_node("Transpose", ["rev"], ["t"], name="transpose", perm=[1, 0]),
        _const("flat", np.array([-1], np.int64)),
        oh.make_node("Reshape", ["t", "flat"], ["pf"], name="flatten"),
        oh.make_node("Cast", ["pf"], ["pads"], name="cast", to=TensorProto.INT64),
        oh.make_node("Pad", ["x", "pads"], ["y"], name="pad", mode="reflect"),
    ]
    program = _check(_model(nodes), _x())
    assert _kinds(program) == [("spatial_pad", ["Pad"])]


def test_resize_to_a_static_shape_read_with_shape_gather_unsqueeze():
    """F.interpolate(pooled, size=x.shape[2:]) on a static input: Shape, Gather, Unsqueeze, Squeeze,
    Concat."""
    nodes = [
        oh.make_node("AveragePool", ["x"], ["a"], name="pool", kernel_shape=[2, 2], strides=[2, 2]),
        oh.make_node("Shape", ["x"], ["shp"], name="shape"),
        _const("i2", np.array(2, np.int64)),
        _const("i3", np.array([3], np.int64)),
        _const("z", np.array([0], np.int64)),
        oh.make_node("Gather", ["shp", "i2"], ["h"], name="gather h"),
        oh.make_node("Gather", ["shp", "i3"], ["w1"], name="gather w"),
        oh.make_node("Squeeze", ["w1", "z"], ["w"], name="squeeze"),
        oh.make_node("Unsqueeze", ["h", "z"], ["h1"], name="unsqueeze h"),
        oh.make_node("Unsqueeze", ["w", "z"], ["w2"], name="unsqueeze w"),
        oh.make_node("Shape", ["a"], ["nc"], name="shape nc", end=2),
        oh.make_node("Concat", ["nc", "h1", "w2"], ["sizes"], name="sizes", axis=0),
        oh.make_node("Resize", ["a", "", "", "sizes"], ["y"], name="resize", mode="linear"),
    ]
    program = _check(_model(nodes), _x())
    assert [k for k, _ in _kinds(program)] == ["pool_avg", "resize_linear"]


def test_folded_ops_refuse_dynamic_shapes():
    """Reshape / Transpose of an image need its size (static views); Shape of a dynamic size cannot fold."""
    dynamic = (1, C, "H", "W")
    _error(
        _model([_node("Reshape", ("x", "s"))], [("s", np.array([1, -1], np.int64))], dynamic),
        "Reshape",
        "my reshape",
        "static image size",
    )
    _error(
        _model([_node("Transpose", perm=[0, 1, 3, 2])], in_shape=dynamic),
        "Transpose",
        "my transpose",
        "static",
    )
    _error(
        _model([_node("Slice", ("x", "s", "e"))], [("s", np.array([0])), ("e", np.array([1]))]),
        "Slice",
        "my slice",
        "constants only",
    )
    nodes = [
        oh.make_node("Shape", ["x"], ["s"], name="shape"),
        oh.make_node("Resize", ["x", "", "", "s"], ["y"], name="resize"),
    ]
    _error(_model(nodes, in_shape=(1, C, "H", "W")), "Shape", "shape", "dynamic size")
    big = [
        oh.make_node("ConstantOfShape", ["n"], ["z"], name="big"),
        oh.make_node("Add", ["x", "z"], ["y"], name="add"),
    ]
    _error(_model(big, [("n", np.array([1 << 40], np.int64))]), "ConstantOfShape", "big", "exceeds")
