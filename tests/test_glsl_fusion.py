"""The gpu preset's reads fused into a conv: AveragePool 2x2 and Resize x2 (linear, half_pixel) are not
passes of their own but the way the consuming conv reads its input (directly or through a Concat read in
place). Each case: the gpu preset has fewer passes and the same output as onnxruntime (GLSL on Mesa,
and WGSL where a WebGPU adapter exists), the cpu preset keeps its passes; a case the read templates do
not implement keeps its pass.
"""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from helpers import both_presets, image_model, named_node, seeded_weights

from neuralao.export.glsl import generate_compute
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute_all

C = 5
SHAPE = (1, C, "H", "W")  # dynamic: sizes are multiples of the pad multiple the pools and resizes need


def _conv(x: str, out: str, cin: int, seed: int, cout: int = 6) -> tuple[list, list]:
    """A 3x3 conv (pads 1) ``x`` -> ``out`` with seeded weights, and its initializers."""
    w, b = f"w_{out}", f"b_{out}"
    inits = [(w, seeded_weights((cout, cin, 3, 3), seed) * 0.3), (b, seeded_weights((cout,), seed + 1))]
    return [named_node("Conv", (x, w, b), out, pads=[1, 1, 1, 1])], inits


def _up(x: str, out: str, mode: str = "half_pixel") -> tuple[list, list]:
    scales = f"s_{out}"
    node = named_node("Resize", (x, "", scales), out, mode="linear", coordinate_transformation_mode=mode)
    return [node], [(scales, np.array([1, 1, 2, 2], np.float32))]


def _pool(x: str, out: str) -> list:
    return [named_node("AveragePool", (x,), out, kernel_shape=[2, 2], strides=[2, 2])]


def _check(nodes, inits, x: np.ndarray) -> tuple[dict, dict]:
    """Both presets vs onnxruntime (GLSL 4.30 on Mesa); the (gpu, cpu) manifests."""
    model = image_model(nodes, inits, in_shape=SHAPE)
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    cpu = both_presets(model, ref, lambda program: run_compute_all(program, x)["y"], TOL.glsl_op_fp32)
    gpu = generate_compute(model, preset="gpu")
    _wgsl_matches(model, x, ref)
    return gpu.manifest, cpu.manifest


def _wgsl_matches(model: onnx.ModelProto, x: np.ndarray, ref: np.ndarray) -> None:
    """The gpu preset's WGSL vs onnxruntime too, where wgpu finds an adapter."""
    try:
        import wgpu

        adapter = wgpu.gpu.request_adapter_sync()
    except (ImportError, RuntimeError):
        adapter = None
    if adapter is None:
        return
    from neuralao.runtime.wgsl_runner import run_wgsl_all

    got = run_wgsl_all(generate_compute(model, preset="gpu", dialect="wgsl"), x)["y"]
    assert float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32


def _x(h: int, w: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(1, C, h, w)).astype(np.float32)


def _kinds(manifest: dict) -> list[str]:
    return [p["kind"] for p in manifest["passes"]]


def test_pool_read_by_conv():
    conv, inits = _conv("p", "y", C, 3)
    gpu, cpu = _check(_pool("x", "p") + conv, inits, _x(12, 20))
    assert "pool_avg" in _kinds(cpu) and "pool_avg" not in _kinds(gpu)
    assert len(gpu["passes"]) < len(cpu["passes"])
    assert ["AveragePool", "Conv"] == next(p["ops"] for p in gpu["passes"] if p["kind"] == "conv")[:2]
    assert len(gpu["memory"]["textures"]) < len(cpu["memory"]["textures"])  # the pooled texture is gone


def test_pool_read_by_two_convs_in_a_concat():
    """A pool feeding two convs, one of them through a Concat with the pool's own input pooled again."""
    a, ia = _conv("p", "a", C, 3)
    b, ib = _conv("c", "y0", C + 6, 5)
    nodes = _pool("x", "p") + a + [named_node("Concat", ("a", "p"), "c", axis=1)] + b
    nodes.append(named_node("Relu", ("y0",), "y"))
    gpu, cpu = _check(nodes, ia + ib, _x(16, 12, 1))
    assert _kinds(cpu).count("pool_avg") == 1 and "pool_avg" not in _kinds(gpu)


@pytest.mark.parametrize("skip", [False, True])
def test_resize_read_by_conv(skip):
    """Conv(Resize(x)) and Conv(Concat(Resize(x), skip)), the U-Net's decoder step."""
    if skip:
        conv, inits = _conv("c", "y", 2 * C, 7)
        nodes = _up("h", "u")[0] + [named_node("Concat", ("u", "x"), "c", axis=1)] + conv
        nodes = [*_pool("x", "h"), *nodes]
        inits = _up("h", "u")[1] + inits
    else:
        conv, inits = _conv("u", "y", C, 7)
        nodes, up_inits = _up("x", "u")
        nodes, inits = nodes + conv, up_inits + inits
    gpu, cpu = _check(nodes, inits, _x(8, 16, 2))
    assert "resize_linear" in _kinds(cpu) and "resize_linear" not in _kinds(gpu)
    assert len(cpu["passes"]) - len(gpu["passes"]) == 2  # the resize and the crop (into the conv)


def test_the_shipped_unet_fuses_the_pad_every_pool_and_resize():
    """unet-gtao: the pad, 3 pools, 3 resizes, the crop and the input assembly's elementwise passes gone
    (32 passes -> 14), the same output as onnxruntime on the reflect-padded input at an odd size."""
    from neuralao.runtime.shipped import shipped_models

    model = onnx.load(shipped_models()["unet-gtao"] / "model.onnx")
    gpu = generate_compute(model, preset="gpu")
    cpu = generate_compute(model, preset="cpu")
    assert _kinds(cpu.manifest).count("pool_avg") == 3 and _kinds(cpu.manifest).count("resize_linear") == 3
    assert not {"pad", "pool_avg", "resize_linear"} & set(_kinds(gpu.manifest))
    assert len(gpu.manifest["passes"]) == 14 and len(cpu.manifest["passes"]) == 32
    channels = model.graph.input[0].type.tensor_type.shape.dim[1].dim_value  # 5 or 6: GTAO's images
    x = np.random.default_rng(6).normal(size=(1, channels, 29, 35)).astype(np.float32)
    x[:, 0] = np.abs(x[:, 0]) + 0.5  # depth
    padded = np.pad(x, ((0, 0), (0, 0), (0, 3), (0, 5)), mode="reflect")
    feeds = {"gbuffer": padded, "radius": np.full((1, 1, 1, 1), 0.3, np.float32)}
    ref = run_onnxruntime(model.SerializeToString(), feeds)[0][:, :, :29, :35]
    got = next(iter(run_compute_all(gpu, x, scalars={"radius": 0.3}).values()))
    # the whole network: a U-Net's tolerance, not one op's
    assert got.shape == ref.shape and float(np.abs(got - ref).max()) <= TOL.parity_unet_fp32


@pytest.mark.parametrize(
    "case",
    ["asymmetric", "pool_relu", "pool_output", "pool_3x3", "pad_relu"],
)
def test_reads_not_implemented_keep_their_pass(case):
    """Only the exact pool and resize the read templates implement fuse; others stay passes."""
    conv, inits = _conv("p", "y", C, 3)
    if case == "asymmetric":
        nodes, up_inits = _up("x", "p", mode="asymmetric")
        nodes, inits, kind = nodes + conv, up_inits + inits, "resize_linear"
    elif case == "pool_relu":  # the Relu joins the pool's epilogue: the read would skip it
        nodes = _pool("x", "q") + [named_node("Relu", ("q",), "p")] + conv
        kind = "pool_avg"
    elif case == "pad_relu":  # the Relu of the input joins the pad pass's epilogue
        nodes, kind = [named_node("Relu", ("x",), "p"), *conv], "pad"
    elif case == "pool_output":  # the pooled image is also a graph output (a crop reads it)
        nodes, kind = _pool("x", "p") + conv, "pool_avg"
    else:
        nodes = [
            named_node("AveragePool", ("x",), "p", kernel_shape=[3, 3], strides=[2, 2], pads=[1, 1, 1, 1])
        ]
        nodes, kind = nodes + conv, "pool_avg"
    model = image_model(nodes, inits, in_shape=SHAPE)
    if case == "pool_output":
        model.graph.output.append(onnx.helper.make_tensor_value_info("p", onnx.TensorProto.FLOAT, None))
    gpu = generate_compute(model, preset="gpu")
    assert kind in _kinds(gpu.manifest)
    x = _x(8, 16, 4)
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    got = run_compute_all(gpu, x)["y"]
    assert float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32


@pytest.mark.parametrize("flip_y", [False, True])
def test_pad_read_by_the_first_convs(flip_y):
    """The reflect pad (to a multiple of 8, bottom/right) read by the convs of the input, also through
    a Concat, with the input stored bottom-up (u_flip_y): no pad pass, the padded texture gone."""
    a, ia = _conv("x", "a", C, 3)
    b, ib = _conv("c", "y", C + 6, 5, cout=3)
    model = image_model(a + [named_node("Concat", ("x", "a"), "c", axis=1)] + b, ia + ib, in_shape=SHAPE)
    onnx.helper.set_model_props(model, {"pad_multiple": "8"})
    x = _x(13, 21, 5)
    padded = np.pad(x, ((0, 0), (0, 0), (0, 3), (0, 3)), mode="reflect")
    ref = run_onnxruntime(model.SerializeToString(), {"x": padded})[0][:, :, :13, :21]
    gpu, cpu = (generate_compute(model, preset=p) for p in ("gpu", "cpu"))
    assert _kinds(cpu.manifest)[0] == "pad" and "pad" not in _kinds(gpu.manifest)
    assert gpu.manifest["pad"]["pass"] is None and len(gpu.manifest["pad"]["read_by"]) == 2
    assert cpu.manifest["pad"]["pass"] == "p00_pad" and "read_by" not in cpu.manifest["pad"]
    assert all("u_flip_y" in p["uniforms"] for p in gpu.manifest["passes"])
    assert len(gpu.manifest["memory"]["textures"]) < len(cpu.manifest["memory"]["textures"])
    for program in (gpu, cpu):
        stored = x[:, :, ::-1] if flip_y else x
        got = run_compute_all(program, np.ascontiguousarray(stored), flip_y=flip_y)["y"]
        got = got[:, :, ::-1] if flip_y else got
        assert got.shape == ref.shape and float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32
    try:
        import wgpu

        adapter = wgpu.gpu.request_adapter_sync()
    except (ImportError, RuntimeError):
        adapter = None
    if adapter is not None:
        from neuralao.runtime.wgsl_runner import run_wgsl_all

        got = run_wgsl_all(generate_compute(model, preset="gpu", dialect="wgsl"), x)["y"]
        assert float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32


def _pointwise_preamble() -> tuple[list, list]:
    """A network's input assembly as a chain of per-pixel ops (a foreground mask from the squared input
    through a 1x1 conv, depth against a scalar input, a clipped exponential, a channel-broadcast Div, a
    1x1 conv added back onto the input with a Tanh), read by a 3x3 conv through a Concat."""
    k = np.zeros((1, C, 1, 1), np.float32)
    k[0, 1:4] = 1.0
    sel = np.zeros((1, C, 1, 1), np.float32)
    sel[0, 0] = 1.0
    back = seeded_weights((C, 1, 1, 1), 9) * 0.5
    nodes = [
        named_node("Mul", ("x", "x"), "sq"),
        named_node("Conv", ("sq", "k"), "m"),
        named_node("Mul", ("m", "gain"), "mg0"),
        named_node("Clip", ("mg0", "zero", "one"), "mg"),
        named_node("Conv", ("x", "sel"), "d"),
        named_node("Sub", ("d", "r"), "dr"),
        named_node("Mul", ("dr", "mg"), "rel"),
        named_node("Neg", ("rel",), "nrel"),
        named_node("Exp", ("nrel",), "e0"),
        named_node("Clip", ("e0", "zero", "four"), "e1"),
        named_node("Mul", ("e1", "mg"), "e"),
        named_node("Div", ("x", "d"), "xd"),
        named_node("Sub", ("rel", "d"), "g"),
        named_node("Conv", ("g", "back", "back_b"), "gb"),
        named_node("Add", ("xd", "gb"), "a0"),
        named_node("Tanh", ("a0",), "a"),
        named_node("Concat", ("a", "e"), "c", axis=1),
    ]
    conv, inits = _conv("c", "y", C + 1, 11, cout=3)
    consts = [
        ("k", k),
        ("sel", sel),
        ("back", back),
        ("back_b", seeded_weights((C,), 10)),
        ("gain", np.array(3.0, np.float32)),
        ("zero", np.array(0.0, np.float32)),
        ("one", np.array(1.0, np.float32)),
        ("four", np.array(4.0, np.float32)),
    ]
    return nodes + conv, consts + inits


def _scalar_input(name: str) -> onnx.ValueInfoProto:
    return onnx.helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, [1, 1, 1, 1])


def _depth_like(h: int, w: int, seed: int) -> np.ndarray:
    x = _x(h, w, seed)
    x[:, 0] = np.abs(x[:, 0]) + 0.5  # the Div's denominator, a depth
    return x


def test_pointwise_chain_computed_in_its_readers():
    """The gpu preset computes a chain of per-pixel passes inside the passes that read it (each texel
    recomputes its inputs' chain, reading the input reflect-padded in place of the pad pass): 11 passes
    fewer, the same output as
    onnxruntime in GLSL (and WGSL where a WebGPU adapter exists); the cpu preset keeps a pass per op."""
    nodes, inits = _pointwise_preamble()
    model = image_model(nodes, inits, in_shape=SHAPE, extra_inputs=[_scalar_input("r")])
    x = _depth_like(9, 14, 7)
    feeds = {"x": x, "r": np.full((1, 1, 1, 1), 0.4, np.float32)}
    ref = run_onnxruntime(model.SerializeToString(), feeds)[0]
    run = lambda program: run_compute_all(program, x, scalars={"r": 0.4})["y"]  # noqa: E731
    cpu = both_presets(model, ref, run, TOL.glsl_op_fp32, relative=True).manifest
    gpu = generate_compute(model, preset="gpu").manifest
    # the groups read the input reflect-padded, as the convs do: no pad pass either
    assert _kinds(gpu) == ["uniform", "pointwise", "pointwise", "conv"] and len(cpu["passes"]) == 15
    assert len(gpu["memory"]["textures"]) == len(cpu["memory"]["textures"]) - 11
    assert gpu["pad"]["read_by"] == ["p01_pointwise", "p02_pointwise"]
    grouped = [op for p in gpu["passes"] if p["kind"] == "pointwise" for op in p["ops"]]
    assert {"Mul", "Conv", "Clip", "Sub", "Neg", "Exp", "Div", "Add", "Tanh"} <= set(grouped)
    for dialect in ("wgsl", "vulkan"):  # every dialect writes the group
        assert generate_compute(model, preset="gpu", dialect=dialect).manifest["preset"]["dispatches"] == len(
            gpu["passes"]
        )
    try:
        import wgpu

        adapter = wgpu.gpu.request_adapter_sync()
    except (ImportError, RuntimeError):
        adapter = None
    if adapter is not None:
        from neuralao.runtime.wgsl_runner import run_wgsl_all

        got = run_wgsl_all(generate_compute(model, preset="gpu", dialect="wgsl"), x, scalars={"r": 0.4})["y"]
        assert float((np.abs(got - ref) / np.maximum(1.0, np.abs(ref))).max()) <= TOL.glsl_op_fp32


@pytest.mark.parametrize("flip_y", [False, True])
@pytest.mark.parametrize("channels", [4, C])
def test_pointwise_chain_ending_at_the_output(flip_y, channels):
    """A per-pixel chain whose last op is the graph's output: one pass that reads the input reflect-padded
    and crops (row-flipped for a bottom-up engine texture), with and without unused input lanes."""
    back = seeded_weights((channels, channels, 1, 1), 12) * 0.4
    nodes = [
        named_node("Conv", ("x", "back"), "b"),
        named_node("Add", ("b", "x"), "s"),
        named_node("Mul", ("s", "b"), "y"),
    ]
    model = image_model(nodes, [("back", back)], in_shape=(1, channels, "H", "W"))
    x = _x(7, 11, 8)[:, :channels].copy()
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    gpu = generate_compute(model, preset="gpu")
    assert _kinds(gpu.manifest) == ["pointwise"]  # the pad read by reflection, the crop its store
    stored = np.ascontiguousarray(x[:, :, ::-1]) if flip_y else x
    got = run_compute_all(gpu, stored, flip_y=flip_y)["y"]
    got = got[:, :, ::-1] if flip_y else got
    assert got.shape == ref.shape and float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32


def test_a_wide_1x1_conv_keeps_its_pass():
    """Recomputing a 16-channel 1x1 conv in each layer of its reader would cost more than its pass: it
    stays a pass, its cheap reader does not."""
    wide = 16
    nodes = [
        named_node("Conv", ("x", "w1"), "a"),
        named_node("Mul", ("a", "a"), "b"),
        named_node("Relu", ("b",), "y"),
    ]
    model = image_model(
        nodes, [("w1", seeded_weights((wide, wide, 1, 1), 13) * 0.3)], in_shape=(1, wide, "H", "W")
    )
    x = np.random.default_rng(9).normal(size=(1, wide, 6, 10)).astype(np.float32)
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    gpu = generate_compute(model, preset="gpu")
    assert [p["ops"] for p in gpu.manifest["passes"] if p["kind"] == "conv"] == [["Pad", "Conv"]]
    got = run_compute_all(gpu, x)["y"]
    assert float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32 * max(1.0, float(np.abs(ref).max()))
