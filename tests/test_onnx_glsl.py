"""`neuralao glsl MODEL.onnx` on users' own models (built here with onnx.helper), then `neuralao parity`.

The exports are run from disk on Mesa and compared with onnxruntime by the parity command itself;
the tests also recompute the comparison independently for one case, so a parity that always passes
would be caught.
"""

from __future__ import annotations

import json

import numpy as np
import onnx
import pytest
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.onnx_glsl import parity
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.pipeline import cli
from neuralao.runtime.foundation.io import write_npz
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute

OPSET = 19


def _save(tmp_path, nodes, inputs, outputs, inits, name="m.onnx"):
    graph = oh.make_graph(
        nodes, "user", inputs, outputs, [nh.from_array(np.asarray(v, np.float32), k) for k, v in inits]
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", OPSET)])
    onnx.checker.check_model(model)
    path = tmp_path / name
    onnx.save(model, path)
    return path, model


def _residual_net(tmp_path):
    """conv -> relu -> conv, + skip, average pool, linear upsample back: dynamic H and W."""
    rng = np.random.default_rng(0)
    nodes = [
        oh.make_node("Conv", ["x", "w1", "b1"], ["c1"], name="c1", pads=[1, 1, 1, 1]),
        oh.make_node("Relu", ["c1"], ["r1"], name="r1"),
        oh.make_node("Conv", ["r1", "w2"], ["c2"], name="c2", pads=[1, 1, 1, 1]),
        oh.make_node("Add", ["c2", "x"], ["res"], name="skip"),
        oh.make_node("AveragePool", ["res"], ["p"], name="pool", kernel_shape=[2, 2], strides=[2, 2]),
        oh.make_node("Resize", ["p", "", "scales"], ["y"], name="up", mode="linear"),
    ]
    inits = [
        ("w1", rng.normal(size=(6, 3, 3, 3)) * 0.3),
        ("b1", rng.normal(size=6)),
        ("w2", rng.normal(size=(3, 6, 3, 3)) * 0.3),
        ("scales", [1.0, 1.0, 2.0, 2.0]),
    ]
    return _save(
        tmp_path,
        nodes,
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, "H", "W"])],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 3, "H", "W"])],
        inits,
    )


def test_image_target_from_a_users_onnx(tmp_path):
    path, model = _residual_net(tmp_path)
    out = tmp_path / "img"
    assert cli.main(["glsl", str(path), "--target", "image", "--out", str(out)]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["kind"] == "onnx-glsl" and manifest["target"] == "image"
    assert (out / "model.onnx").read_bytes() == path.read_bytes()
    assert cli.main(["parity", str(out), "--size", "20", "14", "--out", str(tmp_path / "p.json")]) == 0
    r = json.loads((tmp_path / "p.json").read_text())["exports"]["img"]
    assert r["passed"] and r["max_abs_err"] <= TOL.parity_unet_fp32
    # given inputs, and an independent recomputation of the same comparison
    x = np.random.default_rng(5).normal(size=(1, 3, 10, 18)).astype(np.float32)
    write_npz(tmp_path / "x.npz", x=x)
    r = parity(out, inputs=tmp_path / "x.npz")
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    got = run_compute(out / "glsl", x)
    assert got.shape == ref.shape == (1, 3, 10, 18)
    assert r["max_abs_err"] == pytest.approx(float(np.abs(got - ref).max()), abs=1e-9)
    # fp16 storage
    assert (
        cli.main(
            ["glsl", str(path), "--target", "image", "--precision", "fp16", "--out", str(tmp_path / "h")]
        )
        == 0
    )
    assert parity(tmp_path / "h", size=(16, 12))["passed"]


def test_vector_target_with_bindings_and_defaults(tmp_path):
    rng = np.random.default_rng(1)
    nodes = [
        oh.make_node("Gemm", ["normals", "w1", "b1"], ["h"], name="l1", transB=1),
        oh.make_node("Tanh", ["h"], ["t"], name="t"),
        oh.make_node("Gemm", ["t", "w2"], ["y0"], name="l2", transB=1),
        oh.make_node("Mul", ["y0", "gain"], ["y1"], name="gain"),
        oh.make_node("Add", ["y1", "bias"], ["y"], name="bias"),
    ]
    inits = [
        ("w1", rng.normal(size=(8, 48)) * 0.3),
        ("b1", rng.normal(size=8)),
        ("w2", rng.normal(size=(1, 8))),
    ]
    path, _ = _save(
        tmp_path,
        nodes,
        [
            oh.make_tensor_value_info("normals", TensorProto.FLOAT, ["N", 48]),
            oh.make_tensor_value_info("gain", TensorProto.FLOAT, ["N", 1]),
            oh.make_tensor_value_info("bias", TensorProto.FLOAT, ["N", 1]),
        ],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, ["N", 1])],
        inits,
    )
    out = tmp_path / "vec"
    # normals: the G-buffer normal repeated 16 times; gain and bias (width 1) default to textures of their
    # names
    assert (
        cli.main(
            [
                "glsl",
                str(path),
                "--target",
                "vector",
                "--bind",
                "normals=gbuffer.xyzx16",
                "--dialect",
                "glsl330",
                "--dialect",
                "es300",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["bindings"]["gain"] == {"texture": "gain", "channels": "x", "repeats": 1}
    assert manifest["dialects"] == ["es300", "glsl330"]
    r = parity(out, seed=3, size=(9, 7))
    assert r["passed"] and r["max_abs_err"] <= TOL.parity_mlp_fp32 and len(r["checks"]) == 2


def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys):
    path, _ = _residual_net(tmp_path)
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not an onnx file")
    soft = _save(
        tmp_path,
        [oh.make_node("Softmax", ["x"], ["y"], name="sm")],
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, 4, 4])],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 3, 4, 4])],
        [],
        name="soft.onnx",
    )[0]
    cases = [
        (["glsl", str(bad), "--target", "image"], "cannot"),
        (["glsl", str(tmp_path / "missing.onnx"), "--target", "image"], "missing.onnx"),
        (["glsl", str(soft), "--target", "image"], "Softmax"),
        (["glsl", str(path), "--target", "vector"], "image model, use --target image"),
        (["glsl", str(path), "--target", "vector", "--bind", "x=tex.xyq"], "expected INPUT=TEXTURE"),
        (["glsl", str(path), "--target", "image", "--bind", "x=t.xyz"], "vector only"),
    ]
    img = tmp_path / "img"
    assert cli.main(["glsl", str(path), "--target", "image", "--out", str(img)]) == 0
    write_npz(tmp_path / "rank.npz", x=np.zeros((3, 8), np.float32))
    write_npz(tmp_path / "other.npz", y=np.zeros((1, 3, 8, 8), np.float32))
    for npz, needle in (("rank.npz", "does not fit"), ("other.npz", "has no array")):
        assert cli.main(["parity", str(img), "--inputs", str(tmp_path / npz)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], err
    for i, (args, needle) in enumerate(cases):
        out = tmp_path / f"out{i}"
        assert cli.main([*args, "--out", str(out)]) == 2, args
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("neuralao glsl: error:") and needle in err[0], (args, err)
        assert not (out / "manifest.json").exists()
