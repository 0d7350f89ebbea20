"""Every op of the GLSL generator on single-node ONNX graphs: generated GLSL on Mesa vs onnxruntime.

Graphs are built with onnx.helper, inputs seeded; shape and dtype are compared before values, with
TOL.glsl_op_fp32 unless a case states its own tolerance and why. Every emitted shader also goes
through glslangValidator.
"""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from helpers import both_presets
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import generate_compute, generate_mlp_fragment, validate_glsl
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute, run_mlp_fragment

OPSET = 19
H, W, C = 7, 9, 5  # odd sizes: floors in pooling and resizing are exercised


def _model(nodes, inp, out, inits=(), in_shape=None, out_shape=None, opset=OPSET) -> onnx.ModelProto:
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info(inp, TensorProto.FLOAT, in_shape)],
        [oh.make_tensor_value_info(out, TensorProto.FLOAT, out_shape)],
        [nh.from_array(np.asarray(v), k) for k, v in inits],
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", opset)])
    onnx.checker.check_model(model)
    return model


def _image_model(node, inits=(), shape=(1, C, H, W)):
    return _model([node], node.input[0], node.output[0], inits, list(shape), ["n", "c", "h", "w"])


def _ort(model, x):
    return run_onnxruntime(model.SerializeToString(), {model.graph.input[0].name: x})[0]


def _validate_compute(program):
    for src in program.sources.values():
        validate_glsl(src, "comp")


def _check_image(model, x, tol=TOL.glsl_op_fp32, precision="fp32", relative=False):
    """Both presets' GLSL vs onnxruntime; returns the ``cpu`` preset's (unfused) program."""
    run = lambda program: run_compute(program, x)  # noqa: E731
    return both_presets(model, _ort(model, x), run, tol, relative, precision=precision)


def _x(shape=(1, C, H, W), seed=0, scale=1.0):
    return (np.random.default_rng(seed).normal(size=shape) * scale).astype(np.float32)


def _w(shape, seed=1, scale=0.3):
    return (np.random.default_rng(seed).normal(size=shape) * scale).astype(np.float32)


# ----------------------------------------------------------------------------- compute ops

CONV_CASES = {
    "3x3_pad1_bias": (dict(pads=[1, 1, 1, 1]), (6, C, 3, 3), True),
    "1x1_nobias": (dict(), (2, C, 1, 1), False),
    "3x3_valid_stride2": (dict(strides=[2, 2]), (4, C, 3, 3), True),
    "3x3_asym_pads_dil2": (dict(pads=[2, 1, 0, 2], dilations=[2, 2]), (3, C, 3, 3), True),
    "2x3_same_upper": (dict(auto_pad="SAME_UPPER"), (5, C, 2, 3), True),
    "kernel_shape_attr": (dict(kernel_shape=[3, 3], pads=[1, 1, 1, 1]), (9, C, 3, 3), False),
}


@pytest.mark.parametrize("case", sorted(CONV_CASES))
def test_conv(case):
    attrs, wshape, bias = CONV_CASES[case]
    inputs = ["x", "w"] + (["b"] if bias else [])
    inits = [("w", _w(wshape))] + ([("b", _w((wshape[0],), seed=2))] if bias else [])
    _check_image(_image_model(oh.make_node("Conv", inputs, ["y"], name="conv", **attrs), inits), _x())


def test_batch_normalization_standalone():
    rng = np.random.default_rng(3)
    inits = [
        ("s", rng.uniform(0.5, 2, C)),
        ("b", rng.normal(size=C)),
        ("m", rng.normal(size=C)),
        ("v", rng.uniform(0.1, 3, C)),
    ]
    inits = [(k, v.astype(np.float32)) for k, v in inits]
    node = oh.make_node("BatchNormalization", ["x", "s", "b", "m", "v"], ["y"], name="bn", epsilon=1e-3)
    program = _check_image(_image_model(node, inits), _x())
    assert [p["kind"] for p in program.manifest["passes"]] == ["pad", "elementwise", "crop"]


@pytest.mark.parametrize(
    "op,attrs,extra",
    [
        ("Relu", {}, []),
        ("LeakyRelu", {}, []),
        ("LeakyRelu", {"alpha": 0.2}, []),
        ("Sigmoid", {}, []),
        ("Tanh", {}, []),
        ("Clip", {}, [("lo", np.float32(-0.5)), ("hi", np.float32(0.7))]),
        ("Clip", {}, [("lo", np.float32(-0.25))]),
        ("Identity", {}, []),
    ],
)
def test_elementwise(op, attrs, extra):
    node = oh.make_node(op, ["x"] + [k for k, _ in extra], ["y"], name="act", **attrs)
    # x30: saturating tanh/sigmoid arguments (|x| up to ~100) must stay finite and exact.
    _check_image(_image_model(node, extra), _x(scale=30.0))


POOL_CASES = [
    ("AveragePool", dict(kernel_shape=[2, 2], strides=[2, 2])),
    ("AveragePool", dict(kernel_shape=[3, 3], pads=[1, 1, 1, 1], count_include_pad=0)),
    ("AveragePool", dict(kernel_shape=[3, 2], pads=[1, 0, 1, 1], strides=[2, 1], count_include_pad=1)),
    ("MaxPool", dict(kernel_shape=[2, 2], strides=[2, 2])),
    ("MaxPool", dict(kernel_shape=[3, 3], strides=[2, 2], pads=[1, 1, 1, 1])),
    ("MaxPool", dict(kernel_shape=[2, 2], dilations=[2, 2])),
]


@pytest.mark.parametrize("op,attrs", POOL_CASES)
def test_pool(op, attrs):
    _check_image(_image_model(oh.make_node(op, ["x"], ["y"], name="pool", **attrs)), _x())


RESIZE_CASES = [
    # (mode, coordinate_transformation_mode, nearest_mode, scales or None, sizes or None)
    ("linear", "half_pixel", None, [1, 1, 2, 2], None),
    ("linear", "pytorch_half_pixel", None, [1, 1, 2, 1.5], None),
    ("linear", "align_corners", None, [1, 1, 2, 2], None),
    ("linear", "asymmetric", None, [1, 1, 0.5, 2], None),
    ("linear", "half_pixel_symmetric", None, [1, 1, 1.5, 2], None),
    ("linear", "half_pixel", None, None, [1, C, 5, 13]),
    ("linear", "align_corners", None, None, [1, C, 1, 4]),
    ("nearest", "asymmetric", "floor", [1, 1, 2, 2], None),
    ("nearest", "half_pixel", "round_prefer_floor", [1, 1, 2, 0.5], None),
    ("nearest", "align_corners", "round_prefer_ceil", [1, 1, 1.5, 2], None),
    ("nearest", "pytorch_half_pixel", "ceil", [1, 1, 0.5, 2], None),
    ("nearest", "half_pixel", "round_prefer_ceil", None, [1, C, 10, 4]),
]


@pytest.mark.parametrize("mode,coord,nearest,scales,sizes", RESIZE_CASES)
def test_resize(mode, coord, nearest, scales, sizes):
    attrs = {"mode": mode, "coordinate_transformation_mode": coord}
    if nearest:
        attrs["nearest_mode"] = nearest
    inits = [("scales", np.array(scales, np.float32))] if scales else [("sizes", np.array(sizes, np.int64))]
    inputs = ["x", "", "scales"] if scales else ["x", "", "", "sizes"]
    _check_image(_image_model(oh.make_node("Resize", inputs, ["y"], name="resize", **attrs), inits), _x())


def test_resize_symbolic_size_doubles():
    """Dynamic H, W: Resize x2 and AveragePool /2 keep exact symbolic sizes (pad multiple 2)."""
    nodes = [
        oh.make_node("AveragePool", ["x"], ["p"], name="pool", kernel_shape=[2, 2], strides=[2, 2]),
        oh.make_node("Resize", ["p", "", "s"], ["y"], name="up", mode="linear"),
    ]
    model = _model(
        nodes, "x", "y", [("s", np.array([1, 1, 2, 2], np.float32))], [1, C, "H", "W"], [1, C, "H", "W"]
    )
    program = generate_compute(model)
    assert program.pad_multiple == 2
    assert program.manifest["textures"]["t2"]["scale_log2"] == -1
    x = _x((1, C, 6, 10))
    got, ref = run_compute(program, x), _ort(model, x)
    assert got.shape == ref.shape and np.abs(got - ref).max() <= TOL.glsl_op_fp32


def test_concat_materialised():
    node = oh.make_node("Concat", ["x", "x"], ["y"], name="cat", axis=1)
    program = _check_image(_image_model(node), _x())
    assert "concat" in [p["kind"] for p in program.manifest["passes"]]


def test_concat_fused_into_conv_and_bn_folded():
    """Conv(Concat(relu(x), x)) + BatchNormalization + LeakyRelu: two fused passes, BN folded."""
    rng = np.random.default_rng(4)
    inits = [
        ("w", _w((6, 2 * C, 3, 3))),
        ("b", _w((6,), seed=5)),
        ("s", rng.uniform(0.5, 2, 6).astype(np.float32)),
        ("bb", rng.normal(size=6).astype(np.float32)),
        ("m", rng.normal(size=6).astype(np.float32)),
        ("v", rng.uniform(0.1, 3, 6).astype(np.float32)),
    ]
    nodes = [
        oh.make_node("Relu", ["x"], ["r"], name="relu"),
        oh.make_node("Concat", ["r", "x"], ["c"], name="cat", axis=1),
        oh.make_node("Conv", ["c", "w", "b"], ["y0"], name="conv", pads=[1, 1, 1, 1]),
        oh.make_node("BatchNormalization", ["y0", "s", "bb", "m", "v"], ["y1"], name="bn"),
        oh.make_node("LeakyRelu", ["y1"], ["y"], name="lrelu", alpha=0.1),
    ]
    model = _model(nodes, "x", "y", inits, [1, C, H, W], [1, 6, H, W])
    program = _check_image(model, _x())
    kinds = [(p["kind"], p["ops"]) for p in program.manifest["passes"]]
    assert kinds[1:3] == [
        ("elementwise", ["Relu"]),
        ("conv", ["Concat", "Conv", "BatchNormalization", "LeakyRelu"]),
    ]
    assert program.manifest["passes"][2]["folded_batch_norm"] is True


def test_fp16_storage():
    node = oh.make_node("Conv", ["x", "w"], ["y"], name="conv", pads=[1, 1, 1, 1])
    # relative above 1: fp16 storage rounds |y| ~ 4 to 2^-9, so only |err| / max(1, |y|) is scale-free.
    x = _x()
    _check_image(_image_model(node, [("w", _w((4, C, 3, 3)))]), x, TOL.parity_fp16, "fp16", relative=True)


# ----------------------------------------------------------------------------- fragment (per-pixel) ops


def _normals(k_scale=1.0, h=6, w=5, seed=0):
    rng = np.random.default_rng(seed)
    n = (rng.normal(size=(h, w, 3)) * k_scale).astype(np.float32)
    mask = rng.random((h, w)) > 0.2
    return n, mask


def _check_vector(model, scale=1.0, tol=TOL.glsl_op_fp32, dialects=("glsl330",)):
    k = model.graph.input[0].type.tensor_type.shape.dim[1].dim_value // 3
    n, mask = _normals(scale)
    ref = _ort(model, np.tile(n.reshape(-1, 3), (1, k)))
    for fold in (True, False):
        shader = generate_mlp_fragment(model, fold_repeated_input=fold)
        for vert, frag in shader.sources.values():
            validate_glsl(vert, "vert")
            validate_glsl(frag, "frag")
        for d in dialects:
            got = run_mlp_fragment(shader, n, mask, dialect=d)
            ref_img = ref.reshape(n.shape[0], n.shape[1], -1)
            got_img = got.reshape(ref_img.shape)
            assert ref.dtype == got.dtype == np.float32 and got_img.shape == ref_img.shape
            err = float(np.abs(got_img[mask] - ref_img[mask]).max())
            assert err <= tol, f"{d} fold={fold}: max abs err {err:.3g} > {tol}"
            assert np.all(got_img[~mask] == 1.0)


def _vector_model(node, k, out_width, inits=()):
    return _model([node], node.input[0], node.output[0], inits, ["N", 3 * k], ["N", out_width])


@pytest.mark.parametrize(
    "attrs,b_shape,c_shape",
    [
        (dict(transB=1), (4, 6), (4,)),
        (dict(), (6, 3), (1, 3)),
        (dict(alpha=0.5, beta=-2.0, transB=1), (2, 6), (1,)),
        (dict(alpha=1.5), (6, 4), None),
    ],
)
def test_gemm(attrs, b_shape, c_shape):
    inits = [("B", _w(b_shape))] + ([("C", _w(c_shape, seed=7))] if c_shape else [])
    node = oh.make_node("Gemm", ["n", "B"] + (["C"] if c_shape else []), ["y"], name="gemm", **attrs)
    out = b_shape[0] if attrs.get("transB") else b_shape[1]
    _check_vector(_vector_model(node, 2, out, inits))


def test_matmul_and_add_const():
    m1 = _vector_model(oh.make_node("MatMul", ["n", "B"], ["y"], name="mm"), 2, 3, [("B", _w((6, 3)))])
    _check_vector(m1)
    m2 = _vector_model(oh.make_node("Add", ["n", "c"], ["y"], name="add"), 1, 3, [("c", _w((3,)))])
    _check_vector(m2)
    m3 = _vector_model(oh.make_node("Add", ["n", "n"], ["y"], name="add2"), 1, 3)
    _check_vector(m3)


@pytest.mark.parametrize(
    "op,attrs,extra",
    [
        ("Relu", {}, []),
        ("LeakyRelu", {"alpha": 0.3}, []),
        ("Sigmoid", {}, []),
        ("Tanh", {}, []),
        ("Clip", {}, [("lo", np.float32(-1.0)), ("hi", np.float32(2.0))]),
        ("Identity", {}, []),
    ],
)
def test_vector_elementwise(op, attrs, extra):
    node = oh.make_node(op, ["n"] + [k for k, _ in extra], ["y"], name="act", **attrs)
    # x50 normals: arguments up to ~200, far into saturation; the ES variant runs on Mesa too.
    _check_vector(_vector_model(node, 1, 3, extra), scale=50.0, dialects=("glsl330", "es300"))


# ----------------------------------------------------------------------------- errors and names


def _error(fn, *needles):
    with pytest.raises(NeuralaoError) as e:
        fn()
    msg = str(e.value)
    for n in needles:
        assert n in msg, msg
    return msg


def test_unsupported_op_names_op_and_node():
    img = _image_model(oh.make_node("Softmax", ["x"], ["y"], name="my softmax"))
    _error(lambda: generate_compute(img), "Softmax", "my softmax")
    vec = _vector_model(
        oh.make_node("Conv", ["n", "w"], ["y"], name="vec conv"), 1, 3, [("w", _w((3, 3, 1)))]
    )
    _error(lambda: generate_mlp_fragment(vec), "Conv", "vec conv")


@pytest.mark.parametrize(
    "node,inits,needle",
    [
        (
            oh.make_node(
                "BatchNormalization", ["x", "s", "s", "s", "s"], ["y"], name="train", training_mode=1
            ),
            [("s", np.ones(C, np.float32))],
            "training_mode=1",
        ),
        (oh.make_node("Concat", ["x", "x"], ["y"], name="hcat", axis=2), [], "axis=2"),
    ],
)
def test_unsupported_attribute_value(node, inits, needle):
    _error(lambda: generate_compute(_image_model(node, inits)), node.op_type, node.name, needle)


def test_unsupported_gemm_transA():
    node = oh.make_node("Gemm", ["n", "B"], ["y"], name="ta", transA=1)
    _error(
        lambda: generate_mlp_fragment(_vector_model(node, 1, 3, [("B", _w((3, 3)))])), "Gemm", "ta", "transA"
    )


def test_bad_ranks_and_huge_shapes():
    relu = oh.make_node("Relu", ["x"], ["y"], name="r")
    _error(lambda: generate_compute(_image_model(relu, shape=(1, C, H))), "rank 4")
    _error(lambda: generate_compute(_image_model(relu, shape=(1, C, 100000, 8))), "100000")
    _error(lambda: generate_compute(_image_model(relu, shape=(1, 100000, 8, 8))), "100000")
    _error(lambda: generate_compute(_image_model(relu, shape=(2, C, 8, 8))), "batch 2")
    vrelu = oh.make_node("Relu", ["n"], ["y"], name="r")
    for shape, needle in (
        (["N", 3, 1], "rank 2"),
        (["N", 3 * 10**6], "3000000"),
        (["N", 4], "multiple of 3"),
    ):
        _error(lambda s=shape: generate_mlp_fragment(_model([vrelu], "n", "y", (), s, s)), needle)
    big = oh.make_node("Gemm", ["n", "B"], ["y"], name="wide", transB=1)
    _error(lambda: generate_mlp_fragment(_vector_model(big, 1, 5000, [("B", _w((5000, 3)))])), "5000")


HOSTILE = ['in "put" /x;', "conv;/ ü∑ 'q'", "w e\\i/ght*/", "out\nput ☃", "*/ #define x"]


def test_hostile_names_generate_and_run():
    """Names with spaces, quotes, slashes, semicolons, newlines and unicode never reach the GLSL."""
    i, n, w, mid, o = HOSTILE
    nodes = [
        oh.make_node("Conv", [i, w], [mid], name=n, pads=[1, 1, 1, 1]),
        oh.make_node("LeakyRelu", [mid], [o], name=n + " 2"),
    ]
    model = _model(nodes, i, o, [(w, _w((3, C, 3, 3)))], [1, C, "h ☃", "w;"], [1, 3, "h ☃", "w;"])
    program = _check_image(model, _x())
    text = "".join(program.sources.values())
    assert all(s not in text for s in HOSTILE + ["☃", "ü"])
    assert program.manifest["input"]["onnx_name"] == i and program.manifest["outputs"][0]["onnx_name"] == o

    vnodes = [
        oh.make_node("Gemm", [i, w], [mid], name=n, transB=1),
        oh.make_node("Tanh", [mid], [o], name=n + "2"),
    ]
    vmodel = _model(vnodes, i, o, [(w, _w((2, 6)))], ["N ü", 6], ["N ü", 2])
    _check_vector(vmodel, dialects=("glsl330", "es300"))
    shader = generate_mlp_fragment(vmodel)
    text = "".join(v + f for v, f in shader.sources.values())
    assert all(s not in text for s in HOSTILE + ["☃", "ü"])
