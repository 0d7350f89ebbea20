"""Scalar graph inputs of the image (compute) target as uniforms: generated GLSL on Mesa vs onnxruntime.

A single-element input ((1, 1, 1, 1), (1,) or (); e.g. the U-Net's AO radius) becomes a ``uniform
float`` written to a 1x1 texture by its own pass; the ops broadcast it as any 1x1 image. Graphs are
built with onnx.helper, inputs seeded, TOL.glsl_op_fp32 unless a case states its own tolerance.
"""

from __future__ import annotations

import json

import numpy as np
import onnx
import pytest
from helpers import both_presets
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import generate_compute, write_compute_export
from neuralao.export.onnx_glsl import parity
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.pipeline import cli
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_npz
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute, run_compute_all, scalar_inputs, time_compute

OPSET = 17  # the U-Net exporter's opset
H, W = 8, 12  # multiples of the pad multiple of the half-resolution graphs: no padding enters the result
EPS, CAP = 1e-3, 4.0  # the radius input's depth floor and screen-space cap


def _model(nodes, inputs, inits=(), metadata=None) -> onnx.ModelProto:
    """inputs: [(name, shape)]; the one output is "y", (n, c, h, w) symbolic."""
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info(n, TensorProto.FLOAT, s) for n, s in inputs],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, ["n", "c", "h", "w"])],
        [nh.from_array(np.asarray(v, np.float32), k) for k, v in inits],
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", OPSET)])
    for k, v in (metadata or {}).items():
        model.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(model)
    return model


def _check(
    model, feeds: dict[str, np.ndarray], image: str, tol=TOL.glsl_op_fp32, precision="fp32", relative=False
):
    """Both presets' GLSL vs onnxruntime on ``feeds`` (the image and every scalar, by ONNX name)."""
    ref = run_onnxruntime(model.SerializeToString(), feeds)[0]
    scalars = {n: v for n, v in feeds.items() if n != image}
    run = lambda program: run_compute(program, feeds[image], scalars=scalars)  # noqa: E731
    return both_presets(model, ref, run, tol, relative, precision=precision)


def _x(shape=(1, 3, H, W), seed=0, offset=0.0):
    """Seeded normal values; offset > 0 moves them to |x| + offset (safe divisors)."""
    x = np.random.default_rng(seed).normal(size=shape).astype(np.float32)
    return (np.abs(x) + offset).astype(np.float32) if offset else x


@pytest.mark.parametrize("shape", [[1, 1, 1, 1], [1], []], ids=["1111", "1", "rank0"])
@pytest.mark.parametrize("scalar_first", [True, False], ids=["s_op_x", "x_op_s"])
@pytest.mark.parametrize("op", ["Div", "Mul", "Add", "Sub"])
def test_scalar_input_with_an_image(op, scalar_first, shape):
    ins = ["r", "x"] if scalar_first else ["x", "r"]
    model = _model([oh.make_node(op, ins, ["y"], name="op")], [("x", [1, 3, "H", "W"]), ("r", shape)])
    x = _x(offset=0.5 if op == "Div" else 0.0)
    r = np.full(shape, 0.7, np.float32)
    program = _check(model, {"x": x, "r": r}, "x")
    (u,) = program.manifest["uniforms"]
    assert u["onnx_input"] == "r" and u["glsl_name"] == "u_r" and u["declared_shape"] == shape
    assert f"uniform float {u['glsl_name']};" in program.sources[u["shader"]]


def test_scalar_first_input_static_image_and_fused_scalar_arithmetic():
    """The image need not be the first input; ops on the scalar alone fuse into its uniform pass."""
    nodes = [
        oh.make_node("Mul", ["r", "two"], ["r2"], name="double"),
        oh.make_node("Clip", ["r2", "lo", ""], ["rc"], name="floor"),
        oh.make_node("Div", ["x", "rc"], ["y"], name="div"),
    ]
    model = _model(nodes, [("r", [1, 1, 1, 1]), ("x", [1, 5, 6, 7])], [("two", 2.0), ("lo", 0.5)])
    program = _check(model, {"r": np.full((1, 1, 1, 1), 0.2, np.float32), "x": _x((1, 5, 6, 7))}, "x")
    kinds = [p["kind"] for p in program.manifest["passes"]]
    assert kinds == ["pad", "uniform", "binary", "crop"], kinds
    assert program.manifest["passes"][1]["ops"] == ["Uniform", "Mul", "Clip"]
    assert program.manifest["input"]["onnx_name"] == "x"


def test_uniform_names_plain_identifiers_only():
    """u_<name> for a plain identifier; any other ONNX name stays out of the shader (u_scalar<k>)."""
    names = ["radius", "r; } void main() {", "a__b", "scalar1"]
    nodes, prev = [], "x"
    for i, n in enumerate(names):
        nodes.append(oh.make_node("Mul", [prev, n], [f"m{i}"], name=f"mul{i}"))
        prev = f"m{i}"
    nodes.append(oh.make_node("Identity", [prev], ["y"], name="out"))
    model = _model(nodes, [("x", [1, 2, 3, 4])] + [(n, [1]) for n in names])
    feeds = {"x": _x((1, 2, 3, 4))} | {n: np.full([1], 0.5 + i, np.float32) for i, n in enumerate(names)}
    program = _check(model, feeds, "x")
    got = [u["glsl_name"] for u in program.manifest["uniforms"]]
    assert got == ["u_radius", "u_scalar1", "u_scalar2", "u_scalar1_1"], got
    assert not any(n in src for src in program.sources.values() for n in names[1:3])


def _radius_net(half: str | None = None):
    """The U-Net's radius input: d = Conv1x1(gbuffer) (depth select), r = clip(radius / clip(d, eps), 0, cap),
    concat([gbuffer, r]) -> conv 3x3 -> LeakyRelu -> AveragePool -> conv -> Resize x2 -> conv 1x1 -> Sigmoid.
    half: None, or "nearest" / "linear": the whole network on the G-buffer resized by 1/2, AO resized back."""
    rng = np.random.default_rng(3)
    select = np.zeros((1, 4, 1, 1), np.float32)
    select[0, 3] = 1.0  # depth in channel 3
    g = "g" if half else "gbuffer"
    nodes = [oh.make_node("Resize", ["gbuffer", "", "down"], ["g"], name="down", mode=half)] if half else []
    nodes += [
        oh.make_node("Conv", [g, "select"], ["d"], name="depth"),
        oh.make_node("Clip", ["d", "eps", ""], ["dc"], name="depth_floor"),
        oh.make_node("Div", ["radius", "dc"], ["rs"], name="screen_radius"),
        oh.make_node("Clip", ["rs", "zero", "cap"], ["rsc"], name="radius_cap"),
        oh.make_node("Concat", [g, "rsc"], ["cat"], name="cat", axis=1),
        oh.make_node("Conv", ["cat", "w1", "b1"], ["c1"], name="c1", pads=[1, 1, 1, 1]),
        oh.make_node("LeakyRelu", ["c1"], ["a1"], name="a1", alpha=0.1),
        oh.make_node("AveragePool", ["a1"], ["p1"], name="p1", kernel_shape=[2, 2], strides=[2, 2]),
        oh.make_node("Conv", ["p1", "w2", "b2"], ["c2"], name="c2", pads=[1, 1, 1, 1]),
        oh.make_node("Resize", ["c2", "", "up"], ["u2"], name="u2", mode="nearest"),
        oh.make_node("Concat", ["u2", "a1"], ["cat2"], name="cat2", axis=1),
        oh.make_node("Conv", ["cat2", "w3", "b3"], ["c3"], name="c3"),
        oh.make_node("Sigmoid", ["c3"], ["ao" if half else "y"], name="sig"),
    ]
    if half:
        nodes.append(oh.make_node("Resize", ["ao", "", "up"], ["y"], name="back", mode=half))
    inits = [
        ("select", select),
        ("eps", EPS),
        ("zero", 0.0),
        ("cap", CAP),
        ("w1", rng.normal(size=(6, 5, 3, 3)) * 0.3),
        ("b1", rng.normal(size=6) * 0.1),
        ("w2", rng.normal(size=(6, 6, 3, 3)) * 0.3),
        ("b2", rng.normal(size=6) * 0.1),
        ("w3", rng.normal(size=(1, 12, 1, 1)) * 0.3),
        ("b3", [0.1]),
        ("up", [1, 1, 2, 2]),
        ("down", [1, 1, 0.5, 0.5]),
    ]
    meta = {"radius_description": "AO radius in world units (labels' max distance)"}
    return _model(nodes, [("gbuffer", [1, 4, "height", "width"]), ("radius", [1, 1, 1, 1])], inits, meta)


def _gbuffer(h=H, w=W, seed=0):
    """(1, 4, h, w): noisy normals in 0..2, depth in 0.5..2 in channel 3, a background (depth 0) corner."""
    rng = np.random.default_rng(seed)
    g = rng.normal(size=(1, 4, h, w)).astype(np.float32)
    g[0, 3] = rng.uniform(0.5, 2.0, size=(h, w))
    g[0, 3, : h // 3, : w // 3] = 0.0  # background: the eps floor and the cap are exercised
    return g


@pytest.mark.parametrize("half", [None, "nearest", "linear"])
def test_radius_input_network(half):
    model = _radius_net(half)
    for radius in (0.05, 0.8):
        feeds = {"gbuffer": _gbuffer(), "radius": np.full((1, 1, 1, 1), radius, np.float32)}
        program = _check(model, feeds, "gbuffer")
    (u,) = program.manifest["uniforms"]
    assert u["meaning"] == "AO radius in world units (labels' max distance)"
    assert program.manifest["textures"][u["texture"]]["format"] == "RGBA32F"


def test_radius_input_network_fp16_storage():
    """fp16 storage: TOL.parity_fp16_image relative (RGBA16F intermediates); the radius stays RGBA32F."""
    model = _radius_net()
    feeds = {"gbuffer": _gbuffer(), "radius": np.full((1, 1, 1, 1), 0.3, np.float32)}
    program = _check(model, feeds, "gbuffer", TOL.parity_fp16_image, "fp16", relative=True)
    u = program.manifest["uniforms"][0]
    assert program.manifest["textures"][u["texture"]]["format"] == "RGBA32F"
    assert "rgba32f" in program.sources[u["shader"]]


def test_scalars_missing_unknown_or_not_scalar_are_one_line_errors(tmp_path):
    program = generate_compute(_radius_net())
    write_compute_export(program, tmp_path / "glsl")
    assert scalar_inputs(tmp_path / "glsl") == ["radius"]
    g = _gbuffer()
    cases = [
        ({}, "'radius' not given"),
        ({"r": 2.0}, "'radius' not given"),
        ({"radius": np.ones(2)}, "one finite value"),
        ({"radius": float("nan")}, "one finite value"),
    ]
    for scalars, needle in cases:
        for fn in (run_compute, run_compute_all):
            with pytest.raises(NeuralaoError) as e:
                fn(tmp_path / "glsl", g, scalars=scalars or None)
            assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)
    # names a program does not take are ignored (one dict for exports with and without the input)
    x = _x((1, 3, H, W))
    plain = generate_compute(_model([oh.make_node("Relu", ["x"], ["y"])], [("x", [1, 3, "H", "W"])]))
    np.testing.assert_array_equal(run_compute(plain, x, scalars={"radius": 1.0}), run_compute(plain, x))
    # timing needs no value (1.0 by default)
    assert time_compute(tmp_path / "glsl", H, W, repeats=1, warmup=0) > 0


@pytest.mark.parametrize(
    "inputs,needle",
    [
        ([("x", [1, 3, "H", "W"]), ("y2", [1, 3, "H", "W"])], "'y2'"),
        ([("x", [1, 3, "H", "W"]), ("v", [1, 2, 1, 1])], "'v'"),
        ([("x", [1, 3, "H", "W"]), ("n", ["N"])], "'n'"),
    ],
    ids=["second_image", "two_channels", "symbolic"],
)
def test_refused_extra_inputs_name_the_input(inputs, needle):
    second = inputs[1][0]
    model = _model([oh.make_node("Add", ["x", second], ["y"], name="add")], inputs)
    with pytest.raises(NeuralaoError) as e:
        generate_compute(model)
    assert needle in str(e.value) and "single-element scalars" in str(e.value), str(e.value)


def test_glsl_and_parity_cli_with_a_radius_input(tmp_path, capsys):
    path = tmp_path / "radius.onnx"
    onnx.save(_radius_net("linear"), path)
    out = tmp_path / "img"
    assert cli.main(["glsl", str(path), "--target", "image", "--out", str(out)]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["uniforms"] == {"radius": "u_radius"}
    glsl = json.loads((out / "glsl" / "manifest.json").read_text())
    assert [u["onnx_input"] for u in glsl["uniforms"]] == ["radius"]
    assert cli.main(["parity", str(out), "--size", "16", "12", "--out", str(tmp_path / "p.json")]) == 0
    r = json.loads((tmp_path / "p.json").read_text())["exports"]["img"]
    assert r["passed"] and r["max_abs_err"] <= TOL.parity_unet_fp32
    # given inputs, scalars by ONNX name, and an independent recomputation of the comparison
    g, radius = _gbuffer(), np.full((1, 1, 1, 1), 0.4, np.float32)
    write_npz(tmp_path / "x.npz", gbuffer=g, radius=radius)
    r = parity(out, inputs=tmp_path / "x.npz")
    ref = run_onnxruntime(path.read_bytes(), {"gbuffer": g, "radius": radius})[0]
    got = run_compute(out / "glsl", g, scalars={"radius": 0.4})
    assert r["passed"] and r["max_abs_err"] == pytest.approx(float(np.abs(got - ref).max()), abs=1e-9)
    # an .npz without the radius: a one-line error naming it
    write_npz(tmp_path / "no_radius.npz", gbuffer=g)
    assert cli.main(["parity", str(out), "--inputs", str(tmp_path / "no_radius.npz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'radius'" in err[0], err
