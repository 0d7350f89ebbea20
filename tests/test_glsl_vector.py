"""The fragment (vector) target beyond the baked MLP: several inputs bound to named G-buffer textures,
Sub / Mul / Div, Concat, Sin / Cos. Single-node graphs built with onnx.helper; generated GLSL run on
Mesa against onnxruntime; shape and dtype before values; TOL.glsl_op_fp32 unless stated.
"""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import InputBinding, generate_vector_fragment, validate_glsl
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_vector_fragment

OPSET = 19
H, W = 6, 7


def _model(nodes, inputs: dict[str, int], out_width: int, inits=()) -> onnx.ModelProto:
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info(n, TensorProto.FLOAT, ["N", k]) for n, k in inputs.items()],
        [oh.make_tensor_value_info(nodes[-1].output[0], TensorProto.FLOAT, ["N", out_width])],
        [nh.from_array(np.asarray(v, np.float32), k) for k, v in inits],
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", OPSET)])
    onnx.checker.check_model(model)
    return model


def _textures(names, scale=1.0, seed=0):
    rng = np.random.default_rng(seed)
    tex = {n: (rng.uniform(-1, 1, size=(H, W, 4)) * scale).astype(np.float32) for n in names}
    mask = rng.random((H, W)) > 0.2
    tex[names[0]][..., 3] = mask
    return tex, mask


def _check(model, bindings, scale=1.0, tol=TOL.glsl_op_fp32, dialects=("glsl330", "es300")):
    names = list(dict.fromkeys(b.texture for b in bindings.values()))
    tex, mask = _textures(names, scale)
    feeds = {}
    for name, b in bindings.items():
        lanes = ["xyzw".index(c) for c in b.channels]
        feeds[name] = np.tile(tex[b.texture][..., lanes].reshape(-1, len(lanes)), (1, b.repeats))
    ref = run_onnxruntime(model.SerializeToString(), feeds)[0]
    shader = generate_vector_fragment(model, bindings, kind="test")
    for vert, frag in shader.sources.values():
        validate_glsl(vert, "vert")
        validate_glsl(frag, "frag")
    for d in dialects:
        got = run_vector_fragment(shader, tex, dialect=d)
        ref_img = ref.reshape(H, W, -1)
        got_img = got.reshape(H, W, -1) if got.ndim == 3 else got[..., None]
        assert ref.dtype == got.dtype == np.float32 and got_img.shape == ref_img.shape
        err = float(np.abs(got_img[mask] - ref_img[mask]).max())
        assert err <= tol, f"{d}: max abs err {err:.3g} > {tol}"
        assert np.all(got_img[~mask] == 1.0)
    return shader


ONE = {"x": InputBinding("gbuffer", "xyz")}


@pytest.mark.parametrize("op", ["Add", "Sub", "Mul", "Div"])
@pytest.mark.parametrize("const_first", [False, True])
def test_binary_by_constant(op, const_first):
    c = np.array([0.5, -2.0, 3.0], np.float32) if op != "Div" else np.array([0.5, -2.0, 3.0], np.float32)
    ins = ["c", "x"] if const_first else ["x", "c"]
    if op == "Div" and const_first:
        # c / x: keep x away from 0 so the quotient is O(1e2) at most and the tolerance means something
        node = oh.make_node("Add", ["x", "two"], ["x2"], name="shift")
        div = oh.make_node("Div", ["c", "x2"], ["y"], name="div")
        model = _model([node, div], {"x": 3}, 3, [("c", c), ("two", np.float32(2.0))])
    else:
        model = _model([oh.make_node(op, ins, ["y"], name="binop")], {"x": 3}, 3, [("c", c)])
    _check(model, ONE, scale=1.0)


@pytest.mark.parametrize("op", ["Add", "Sub", "Mul", "Div"])
def test_binary_between_inputs(op):
    bindings = {"a": InputBinding("position", "xyz"), "b": InputBinding("normal", "zyx")}
    nodes = [
        oh.make_node("Add", ["b", "three"], ["b3"], name="away_from_zero"),
        oh.make_node(op, ["a", "b3"], ["y"], name="binop"),
    ]
    _check(_model(nodes, {"a": 3, "b": 3}, 3, [("three", np.float32(3.0))]), bindings)


def test_concat_unaligned_and_aligned_parts():
    # widths 3 + 5 + 4: lane copies across vec4 boundaries, then one whole-vec4 copy is impossible
    # (offset 8, width 4 -> aligned: a vec4 copy); a Gemm reads the result so every lane matters.
    bindings = {
        "a": InputBinding("t0", "xyz"),
        "b": InputBinding("t1", "xyzw", 1),
        "c": InputBinding("t0", "xyzw"),
    }
    rng = np.random.default_rng(3)
    nodes = [
        oh.make_node("MatMul", ["b", "m"], ["b5"], name="widen"),
        oh.make_node("Concat", ["a", "b5", "c"], ["cat"], name="cat", axis=1),
        oh.make_node("Gemm", ["cat", "w"], ["y"], name="gemm"),
    ]
    inits = [("m", rng.normal(size=(4, 5))), ("w", rng.normal(size=(12, 4)))]
    shader = _check(_model(nodes, {"a": 3, "b": 4, "c": 4}, 4, inits), bindings)
    assert [t["texture"] for t in shader.manifest["passes"][0]["inputs"]] == ["t0", "t1"]


def test_concat_output_directly():
    nodes = [oh.make_node("Concat", ["x", "x"], ["y"], name="cat", axis=-1)]
    _check(_model(nodes, {"x": 2}, 4), {"x": InputBinding("gbuffer", "xy")})


@pytest.mark.parametrize("op", ["Sin", "Cos"])
@pytest.mark.parametrize("scale", [1.0, 64.0])
def test_sin_cos(op, scale):
    # scale 64: arguments up to ~64*pi-sized values, the range of the field's highest octave.
    _check(_model([oh.make_node(op, ["x"], ["y"], name="trig")], {"x": 3}, 3), ONE, scale=scale)


def test_fourier_features_graph_runs_from_two_textures():
    """The field's shape: normalise, axis-aligned octave frequencies, sin/cos, concat, dense layers."""
    rng = np.random.default_rng(1)
    octaves = 5
    freqs = np.zeros((3, 3 * octaves), np.float32)
    for k in range(octaves):
        for a in range(3):
            freqs[a, 3 * k + a] = np.float32(np.pi * 2.0**k)
    nodes = [
        oh.make_node("Sub", ["p", "centre"], ["p0"], name="centre"),
        oh.make_node("Mul", ["p0", "inv"], ["pn"], name="scale"),
        oh.make_node("MatMul", ["pn", "freqs"], ["z"], name="freq"),
        oh.make_node("Sin", ["z"], ["s"], name="sin"),
        oh.make_node("Cos", ["z"], ["c"], name="cos"),
        oh.make_node("Concat", ["pn", "n", "s", "c"], ["f"], name="cat", axis=1),
        oh.make_node("Gemm", ["f", "w1", "b1"], ["h1"], name="l1"),
        oh.make_node("Tanh", ["h1"], ["a1"], name="t1"),
        oh.make_node("Gemm", ["a1", "w2", "b2"], ["y"], name="l2"),
    ]
    width = 6 + 6 * octaves
    inits = [
        ("centre", [0.1, -0.2, 0.3]),
        ("inv", [1.1, 0.9, 1.3]),
        ("freqs", freqs),
        ("w1", rng.normal(size=(width, 16)) * 0.3),
        ("b1", rng.normal(size=16)),
        ("w2", rng.normal(size=(16, 1))),
        ("b2", [0.5]),
    ]
    bindings = {"p": InputBinding("position", "xyz"), "n": InputBinding("normal", "xyz")}
    shader = _check(_model(nodes, {"p": 3, "n": 3}, 1, inits), bindings)
    assert shader.manifest["kind"] == "test"
    assert shader.manifest["network"]["bindings"]["n"] == {
        "texture": "normal",
        "channels": "xyz",
        "repeats": 1,
    }


def _error(fn, *needles):
    with pytest.raises(NeuralaoError) as e:
        fn()
    for n in needles:
        assert n in str(e.value), str(e.value)


def test_refusals_name_op_node_and_attribute():
    cat = _model([oh.make_node("Concat", ["x", "x"], ["y"], name="batchcat", axis=0)], {"x": 3}, 3)
    _error(lambda: generate_vector_fragment(cat, ONE), "Concat", "batchcat", "axis")
    m = _model([oh.make_node("Sin", ["x"], ["y"], name="s")], {"x": 3}, 3)
    _error(lambda: generate_vector_fragment(m, {"x": InputBinding("gbuffer", "xy")}), "width 3", "2 x 1")
    _error(lambda: generate_vector_fragment(m, {"other": InputBinding("gbuffer")}), "do not match")
    _error(lambda: generate_vector_fragment(m, {"x": InputBinding("gbuffer", "xq")}), "bad binding")
    _error(lambda: run_vector_fragment(generate_vector_fragment(m, ONE), {}), "not given")


def test_activation_not_fused_into_a_value_already_read():
    """Sin reads MatMul's output first; Cos, the last reader, must not fuse into the MatMul (that would
    turn what Sin already read into cos(z))."""
    rng = np.random.default_rng(5)
    nodes = [
        oh.make_node("MatMul", ["x", "m"], ["z"], name="mm"),
        oh.make_node("Sin", ["z"], ["s"], name="sin"),
        oh.make_node("Cos", ["z"], ["c"], name="cos"),
        oh.make_node("Add", ["s", "c"], ["y"], name="sum"),
    ]
    _check(_model(nodes, {"x": 3}, 4, [("m", rng.normal(size=(3, 4)) * 3)]), ONE)


def test_image_target_does_not_fuse_into_a_value_already_read():
    """The same rule in the compute target: AveragePool reads the Conv output first, then Relu (its
    last reader) must get a pass of its own instead of fusing into the Conv."""
    from neuralao.export.glsl import generate_compute
    from neuralao.runtime.glsl_runner import run_compute

    rng = np.random.default_rng(6)
    nodes = [
        oh.make_node("Conv", ["x", "w"], ["y"], name="conv", pads=[1, 1, 1, 1]),
        oh.make_node("AveragePool", ["y"], ["a"], name="pool", kernel_shape=[1, 1]),
        oh.make_node("Relu", ["y"], ["r"], name="relu"),
        oh.make_node("Concat", ["a", "r"], ["out"], name="cat", axis=1),
    ]
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 2, 5, 6])],
        [oh.make_tensor_value_info("out", TensorProto.FLOAT, [1, 6, 5, 6])],
        [nh.from_array(rng.normal(size=(3, 2, 3, 3)).astype(np.float32), "w")],
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", OPSET)])
    x = rng.normal(size=(1, 2, 5, 6)).astype(np.float32)
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    got = run_compute(generate_compute(model), x)
    assert got.shape == ref.shape and got.dtype == ref.dtype
    assert float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32


@pytest.mark.parametrize("weights", ["uniform", "constant"])
def test_weights_as_uniform_blocks_or_constants_run_from_disk(weights, tmp_path):
    """Both weight placements match onnxruntime, from the files on disk; constants need no blocks."""
    from neuralao.export.glsl import write_mlp_export

    rng = np.random.default_rng(7)
    nodes = [
        oh.make_node("Gemm", ["x", "w1", "b1"], ["h"], name="l1"),
        oh.make_node("Tanh", ["h"], ["t"], name="t"),
        oh.make_node("Gemm", ["t", "w2", "b2"], ["y"], name="l2"),
    ]
    inits = [
        ("w1", rng.normal(size=(3, 12))),
        ("b1", rng.normal(size=12)),
        ("w2", rng.normal(size=(12, 2))),
        ("b2", rng.normal(size=2)),
    ]
    model = _model(nodes, {"x": 3}, 2, inits)
    shader = generate_vector_fragment(model, ONE, kind="test", weights=weights)
    assert (shader.manifest["uniform_blocks"] == []) == (weights == "constant")
    assert shader.manifest["weights"].startswith(weights)
    assert ("const mat4 " in shader.fragment_source) == (weights == "constant")
    write_mlp_export(shader, tmp_path / "e")
    tex, mask = _textures(["gbuffer"])
    ref = run_onnxruntime(model.SerializeToString(), {"x": tex["gbuffer"][..., :3].reshape(-1, 3)})[0]
    for d in ("glsl330", "es300"):
        got = run_vector_fragment(tmp_path / "e", tex, dialect=d)
        assert float(np.abs(got[mask] - ref.reshape(H, W, 2)[mask]).max()) <= TOL.glsl_op_fp32
    with pytest.raises(NeuralaoError, match="weights must be"):
        generate_vector_fragment(model, ONE, weights="bogus")
