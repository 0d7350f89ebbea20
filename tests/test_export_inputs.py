"""User input to `neuralao glsl` and `neuralao parity` (ONNX built with onnx.helper, shaders run on Mesa,
references from onnxruntime): input names that sanitise alike or carry shader text, static batches,
bad ``--size`` and ``--out``, and error messages that name what the user can change.

Bad input is one line on stderr and exit 2, never a traceback.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
import pytest
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import generate_compute
from neuralao.export.onnx_glsl import parity
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.pipeline import cli
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_vector_fragment

OPSET = 17
HOSTILE = "; void main() { gl_FragColor = vec4(0.0); } //"


def _model(nodes, inputs, outputs, inits=()) -> onnx.ModelProto:
    arrays = [
        v if isinstance(v, np.ndarray) and v.dtype == np.int64 else np.asarray(v, np.float32)
        for _, v in inits
    ]
    graph = oh.make_graph(
        nodes, "user", inputs, outputs, [nh.from_array(a, k) for (k, _), a in zip(inits, arrays, strict=True)]
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", OPSET)])
    onnx.checker.check_model(model)
    return model


def _vec(name: str, batch, width: int):
    return oh.make_tensor_value_info(name, TensorProto.FLOAT, [batch, width])


def _one_line_error(capsys, args: list[str], *needles: str) -> str:
    assert cli.main(args) == 2, args
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"neuralao {args[0]}: error:"), err
    assert all(n in err[0] for n in needles), (needles, err[0])
    return err[0]


def _shader_text(glsl_dir: Path) -> str:
    return "".join(p.read_text() for p in sorted(glsl_dir.iterdir()) if p.suffix in (".vert", ".frag"))


def _difference(a: str, b: str) -> onnx.ModelProto:
    """y = a - b on two (N, 3) inputs: not symmetric, so swapped or merged inputs show."""
    return _model(
        [oh.make_node("Sub", [a, b], ["y"], name="diff")],
        [_vec(a, "N", 3), _vec(b, "N", 3)],
        [_vec("y", "N", 3)],
    )


def test_inputs_whose_names_sanitise_alike_stay_distinct(tmp_path):
    path, out = tmp_path / "m.onnx", tmp_path / "vec"
    model = _difference("pos.x", "pos-x")
    onnx.save(model, path)
    assert cli.main(["glsl", str(path), "--target", "vector", "--out", str(out)]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    textures = {n: b["texture"] for n, b in manifest["bindings"].items()}
    assert textures == {"pos.x": "pos.x", "pos-x": "pos-x"}, textures
    # the shaders on distinct inputs against onnxruntime on the same inputs
    rng = np.random.default_rng(0)
    h, w = 6, 5
    tex = {t: rng.uniform(-1, 1, (h, w, 4)).astype(np.float32) for t in textures.values()}
    tex["pos.x"][..., 3] = 1.0  # the first texture's w is the mask: all foreground
    feeds = {n: tex[t][..., :3].reshape(-1, 3) for n, t in textures.items()}
    ref = run_onnxruntime(model.SerializeToString(), feeds)[0].reshape(h, w, 3)
    assert float(np.abs(ref).max()) > 0.5  # a - b, not a - a
    for dialect in manifest["dialects"]:
        got = run_vector_fragment(out / "glsl", tex, dialect=dialect)
        assert got.shape == ref.shape and float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32, dialect
    assert parity(out, seed=1, size=(7, 5))["passed"]


def test_hostile_names_never_reach_shader_source(tmp_path):
    # an input named like shader code, one named like a generated sampler, and a file name with a newline
    path, out = tmp_path / "evil\n#error name.onnx", tmp_path / "vec"
    onnx.save(_difference(HOSTILE, "u_tex0"), path)
    assert cli.main(["glsl", str(path), "--target", "vector", "--out", str(out)]) == 0
    text = _shader_text(out / "glsl")
    for needle in ("gl_FragColor", "void_main", "#error", "evil"):
        assert needle not in text, needle
    manifest = json.loads((out / "manifest.json").read_text())
    assert list(manifest["bindings"]) == [HOSTILE, "u_tex0"]
    glsl = json.loads((out / "glsl" / "manifest.json").read_text())
    assert [i["sampler"] for i in glsl["passes"][0]["inputs"]] == ["u_tex0", "u_tex1"]
    r = parity(out, seed=2, size=(6, 4))  # compiles on Mesa, and a - b comes out right
    assert r["passed"] and r["max_abs_err"] <= TOL.parity_mlp_fp32


def test_default_texture_taken_by_a_bind_is_refused(tmp_path, capsys):
    path = tmp_path / "m.onnx"
    onnx.save(_difference("a", "b"), path)
    _one_line_error(
        capsys,
        ["glsl", str(path), "--target", "vector", "--bind", "a=b.xyz", "--out", str(tmp_path / "o")],
        "'b'",
        "--bind",
    )
    assert not (tmp_path / "o" / "manifest.json").exists()


def _mlp(batch) -> onnx.ModelProto:
    rng = np.random.default_rng(3)
    nodes = [
        oh.make_node("Gemm", ["normal", "w1", "b1"], ["h"], name="l1", transB=1),
        oh.make_node("Relu", ["h"], ["r"], name="relu"),
        oh.make_node("Gemm", ["r", "w2", "b2"], ["z"], name="l2", transB=1),
        oh.make_node("Sigmoid", ["z"], ["ao"], name="ao"),
    ]
    inits = [
        ("w1", rng.normal(size=(8, 3))),
        ("b1", rng.normal(size=8)),
        ("w2", rng.normal(size=(1, 8))),
        ("b2", [0.1]),
    ]
    return _model(nodes, [_vec("normal", batch, 3)], [_vec("ao", batch, 1)], inits)


def test_parity_tiles_a_static_batch(tmp_path):
    for batch, size in ((4096, (64, 48)), (16, (9, 7))):  # one padded chunk; several, the last one padded
        path, out = tmp_path / f"mlp{batch}.onnx", tmp_path / f"mlp{batch}"
        onnx.save(_mlp(batch), path)
        assert (
            cli.main(["glsl", str(path), "--target", "vector", "--dialect", "glsl330", "--out", str(out)])
            == 0
        )
        report = tmp_path / f"p{batch}.json"
        args = ["parity", str(out), "--size", str(size[0]), str(size[1]), "--out", str(report)]
        assert cli.main(args) == 0, batch
        r = json.loads(report.read_text())["exports"][out.name]
        assert r["passed"] and r["max_abs_err"] <= TOL.parity_mlp_fp32
        assert r["checks"][0]["pixels"] > (batch if batch < 100 else 0)


def _strided(path: Path, dims: list) -> None:
    """(1, 3, H, W) -> Conv 3x3 stride 2 -> Relu -> (1, 4, H/2, W/2)."""
    w = np.random.default_rng(4).normal(size=(4, 3, 3, 3)) * 0.3
    out_dims = [1, 4, *(d // 2 if isinstance(d, int) else f"{d}2" for d in dims[2:])]
    model = _model(
        [
            oh.make_node("Conv", ["x", "w"], ["c"], name="down", pads=[1, 1, 1, 1], strides=[2, 2]),
            oh.make_node("Relu", ["c"], ["y"], name="relu"),
        ],
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, dims)],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, out_dims)],
        [("w", w)],
    )
    onnx.save(model, path)


def test_bad_size_is_one_line_before_any_allocation(tmp_path, capsys):
    dyn, fixed = tmp_path / "dyn", tmp_path / "fixed"
    _strided(tmp_path / "dyn.onnx", [1, 3, "H", "W"])
    _strided(tmp_path / "fixed.onnx", [1, 3, 12, 8])
    for src, out in ((tmp_path / "dyn.onnx", dyn), (tmp_path / "fixed.onnx", fixed)):
        assert cli.main(["glsl", str(src), "--target", "image", "--out", str(out)]) == 0
    cases = [
        (dyn, ["0", "0"], "at least 1"),
        (dyn, ["-4", "4"], "at least 1"),
        (dyn, ["37", "29"], "multiple of 2"),
        (dyn, ["100000", "100000"], "GiB"),
        (fixed, ["20", "20"], "static"),
        (fixed, ["12", "8"], "static"),  # W H: the transposed size is refused too
    ]
    for d, size, needle in cases:
        _one_line_error(capsys, ["parity", str(d), "--size", *size], needle)
    assert parity(dyn, size=(10, 6))["passed"]
    assert (
        parity(fixed, size=(8, 12))["passed"] and parity(fixed)["passed"]
    )  # equal to the static size, or none
    # the vector target: positive sizes, within the memory bound
    onnx.save(_mlp("N"), tmp_path / "mlp.onnx")
    assert (
        cli.main(["glsl", str(tmp_path / "mlp.onnx"), "--target", "vector", "--out", str(tmp_path / "v")])
        == 0
    )
    for size, needle in ((["0", "0"], "at least 1"), (["16000", "16000"], "GiB")):
        _one_line_error(capsys, ["parity", str(tmp_path / "v"), "--size", *size], needle)


def test_glsl_out_that_is_a_file(tmp_path, capsys):
    path = tmp_path / "m.onnx"
    onnx.save(_difference("a", "b"), path)
    (tmp_path / "taken").write_text("not a folder")
    _one_line_error(
        capsys, ["glsl", str(path), "--target", "vector", "--out", str(tmp_path / "taken")], "is a file"
    )
    _one_line_error(
        capsys,
        ["glsl", str(path), "--target", "vector", "--out", str(tmp_path / "taken" / "sub")],
        "is a file",
    )
    assert (tmp_path / "taken").read_text() == "not a folder"


def test_large_folded_constant_names_the_conv_that_uses_it(tmp_path, capsys):
    """Weights computed in the graph (as onnx's light models make them) are welcome up to what weights.bin
    holds; past that the one-line error names the constant and the node that uses it."""
    from neuralao.export.glsl import MAX_FOLDED_ELEMENTS

    def conv_model(shape):
        return _model(
            [
                oh.make_node("ConstantOfShape", ["w_shape"], ["w_big"], name="make_w"),
                oh.make_node("Identity", ["w_big"], ["w_view"], name="view"),
                oh.make_node("Conv", ["x", "w_view"], ["y"], name="conv_big", pads=[1, 1, 1, 1]),
            ],
            [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, int(shape[1]), 8, 8])],
            [oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, int(shape[0]), 8, 8])],
            [("w_shape", np.array(shape, np.int64))],
        )

    generate_compute(conv_model([128, 64, 3, 3]))  # 73,728 elements: fine
    with pytest.raises(NeuralaoError) as err:
        generate_compute(conv_model([4096, 1024, 3, 3]))  # 37.7M elements
    for needle in ("'w_big'", "Conv node 'conv_big'", f"{MAX_FOLDED_ELEMENTS:,}"):
        assert needle in str(err.value), (needle, str(err.value))
    # onnx's own light test models store their weights this way; alexnet's fc6 is past the limit
    light = Path(onnx.__file__).parent / "backend" / "test" / "data" / "light" / "light_bvlc_alexnet.onnx"
    assert light.is_file(), light
    _one_line_error(
        capsys,
        ["glsl", str(light), "--target", "image", "--out", str(tmp_path / "alexnet")],
        "Gemm node",
        "'fc6_w_0'",
        "[4096, 9216]",
    )
