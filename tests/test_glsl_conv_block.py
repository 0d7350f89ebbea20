"""Blocked conv passes of the GLSL image target: one invocation computes a block of texels x
output layers. Every block against onnxruntime on graphs built with onnx.helper: strides, dilations,
asymmetric pads, output layer counts the block does not divide, concatenated inputs, epilogues that
index per-layer parameters, and sizes that leave partial blocks at the right and bottom edges."""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import generate_compute
from neuralao.export.glsl.image import CONV_BLOCK, MAX_BLOCK_ACCUMULATORS
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute

H, W = 29, 37  # odd: partial blocks on both edges for every block size below
BLOCKS = [(1, 1, 1), CONV_BLOCK, (3, 2, 1), (2, 3, 4)]


def _w(shape, seed):
    return (np.random.default_rng(seed).normal(size=shape) * 0.3).astype(np.float32)


def _model(nodes, inits, cin, static=False):
    hw = [H, W] if static else ["h", "w"]  # a strided output of an odd dynamic size would be fractional
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, cin, *hw])],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, ["n", "c", "h2", "w2"])],
        [nh.from_array(v, k) for k, v in inits],
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", 19)])
    onnx.checker.check_model(model)
    return model


def _conv3x3(cin=6, cout=16):
    """3x3, pad 1, four output layers."""
    inits = [("w", _w((cout, cin, 3, 3), 1)), ("b", _w((cout,), 2))]
    return _model([oh.make_node("Conv", ["x", "w", "b"], ["y"], pads=[1, 1, 1, 1])], inits, cin), cin


def _strided(cin=5, cout=12):
    """Stride 2, dilation 2, asymmetric pads; three output layers (a block of 2 or 4 layers gets 1 or 3)."""
    inits = [("w", _w((cout, cin, 3, 3), 3)), ("b", _w((cout,), 4))]
    node = oh.make_node("Conv", ["x", "w", "b"], ["y"], strides=[2, 2], dilations=[2, 2], pads=[2, 1, 0, 3])
    return _model([node], inits, cin, static=True), cin


def _concat(cin=4):
    """Two branches concatenated into a 5x5 conv (read in place: two input loops) + BatchNorm + PRelu."""
    inits = [
        ("w1", _w((8, cin, 3, 3), 5)),
        ("w2", _w((3, cin, 1, 1), 6)),
        ("w3", _w((8, 11, 5, 3), 7)),
        ("b3", _w((8,), 8)),
        ("s", _w((8,), 9) + 1.0),
        ("m", _w((8,), 10)),
        ("v", np.abs(_w((8,), 11)) + 0.5),
        ("bb", _w((8,), 12)),
        ("slope", _w((8, 1, 1), 13)),
    ]
    nodes = [
        oh.make_node("Conv", ["x", "w1"], ["a"], pads=[1, 1, 1, 1]),
        oh.make_node("Relu", ["a"], ["ar"]),
        oh.make_node("Conv", ["x", "w2"], ["c"]),
        oh.make_node("Concat", ["ar", "c"], ["cat"], axis=1),
        oh.make_node("Conv", ["cat", "w3", "b3"], ["d"], pads=[2, 1, 2, 1]),
        oh.make_node("BatchNormalization", ["d", "s", "bb", "m", "v"], ["e"]),
        oh.make_node("PRelu", ["e", "slope"], ["y"]),
    ]
    return _model(nodes, inits, cin), cin


GRAPHS = {"conv3x3": _conv3x3, "strided_dilated": _strided, "concat_bn_prelu": _concat}


@pytest.mark.parametrize("graph", sorted(GRAPHS))
def test_blocks_match_onnxruntime(graph):
    model, cin = GRAPHS[graph]()
    x = np.random.default_rng(0).normal(size=(1, cin, H, W)).astype(np.float32)
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    outs = {}
    for block in BLOCKS:
        # fuse=False: only the (1, 1, 1) conv can read the input in place of the pad pass, and its guard
        # on the unused lanes lets the compiler drop the zero lanes' products (last-bit differences)
        program = generate_compute(model, conv_block=block, fuse=False)
        convs = [p for p in program.manifest["passes"] if p["kind"] == "conv"]
        assert convs
        for p in convs:
            layers = program.manifest["textures"][p["output"]["texture"]]["layers"]
            bx, by, bl = p["block"]
            assert (bx, by) == block[:2] and bl <= block[2] and layers % bl == 0, (p["block"], layers)
            assert (
                f"/ {8 * bx})" in p["dispatch"]["groups"][0] and f"/ {8 * by})" in p["dispatch"]["groups"][1]
            )
        got = run_compute(program, x)
        assert got.shape == ref.shape
        err = float(np.abs(got - ref).max())
        assert err <= TOL.glsl_op_fp32, f"block {block}: max abs err {err:.3g}"
        outs[block] = got
    # Every block adds the same products in the same order: the outputs agree to the last bit.
    for block, got in outs.items():
        np.testing.assert_array_equal(got, outs[BLOCKS[0]], err_msg=f"block {block}")


def test_block_layers_divide_the_output():
    from neuralao.export.glsl.image import _conv_block

    assert _conv_block((8, 4, 2), 3) == (8, 4, 1)
    assert _conv_block((2, 2, 4), 6) == (2, 2, 3)
    assert _conv_block((2, 2, 8), 2) == (2, 2, 2)
    with pytest.raises(NeuralaoError, match="conv block"):
        _conv_block((0, 4, 1), 4)
    with pytest.raises(NeuralaoError, match=f"at most {MAX_BLOCK_ACCUMULATORS}"):
        _conv_block((8, 8, 2), 4)
