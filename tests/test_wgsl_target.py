"""The WGSL compute target (the image target's passes written by the WGSL dialect) run with wgpu on a
WebGPU adapter (Mesa lavapipe here) against onnxruntime, and the HLSL / MSL made from the GLSL passes
through SPIR-V (HLSL compiled back with glslang's HLSL front end).

Single-node graphs built with onnx.helper, seeded inputs, shape and dtype before values,
TOL.glsl_op_fp32 unless a case says why not; the shipped default U-Net at a small odd size.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import onnx
import pytest
from helpers import image_model, named_node, seeded_weights

from neuralao.export.glsl import generate_compute, write_compute_export
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.shipped import pure_unet_export

wgpu = pytest.importorskip("wgpu")

from neuralao.runtime.wgsl_runner import run_wgsl_all  # noqa: E402


def _adapter_or_skip() -> None:
    try:
        adapter = wgpu.gpu.request_adapter_sync()
    except RuntimeError:
        adapter = None
    if adapter is None:
        pytest.skip("no WebGPU adapter (Debian: mesa-vulkan-drivers)")


# One case per kind of pass the writer emits (conv, blocked conv, transposed, depthwise, pools, resize
# modes, pads, concat, binary, gather, reduce, moments + normalize, softmax, LRN) and the activations
# whose WGSL text differs from the GLSL.
CASES = {
    "conv_blocked_leaky": (
        [
            named_node("Conv", ("x", "w", "b"), "c", pads=[1, 1, 1, 1]),
            named_node("LeakyRelu", ("c",), alpha=0.1),
        ],
        [("w", seeded_weights((9, 6, 3, 3))), ("b", seeded_weights((9,), 2))],
    ),
    "conv_transpose": (
        [named_node("ConvTranspose", ("x", "w"), strides=[2, 2], pads=[0, 1, 0, 1])],
        [("w", seeded_weights((6, 5, 3, 3)))],
    ),
    "depthwise_hardswish": (
        [named_node("Conv", ("x", "w"), "c", group=6, pads=[1, 1, 1, 1]), named_node("HardSwish", ("c",))],
        [("w", seeded_weights((6, 1, 3, 3)))],
    ),
    "maxpool_ceil": ([named_node("MaxPool", kernel_shape=[2, 2], strides=[2, 2], ceil_mode=1)], []),
    "avgpool_pads": (
        [named_node("AveragePool", kernel_shape=[3, 3], pads=[1, 1, 1, 1], count_include_pad=1)],
        [],
    ),
    "resize_nearest": (
        [named_node("Resize", ("x", "", "s"), mode="nearest", coordinate_transformation_mode="asymmetric")],
        [("s", np.array([1, 1, 1.5, 2], np.float32))],
    ),
    "resize_linear_align": (
        [named_node("Resize", ("x", "", "s"), mode="linear", coordinate_transformation_mode="align_corners")],
        [("s", np.array([1, 1, 2, 2], np.float32))],
    ),
    "resize_cubic": (
        [named_node("Resize", ("x", "", "s"), mode="cubic")],
        [("s", np.array([1, 1, 2, 2], np.float32))],
    ),
    "pad_wrap": (
        [named_node("Pad", ("x", "p"), mode="wrap")],
        [("p", np.array([0, 0, 2, 1, 0, 0, 1, 3], np.int64))],
    ),
    "concat_mul_elu": (
        [
            named_node("Concat", ("x", "x"), "c", axis=1),
            named_node("Mul", ("c", "c"), "m"),
            named_node("Elu", ("m",)),
        ],
        [],
    ),
    "div_prelu": (
        [named_node("Div", ("x", "k"), "d"), named_node("PRelu", ("d", "s"))],
        [("k", np.full((1, 6, 1, 1), 3.0, np.float32)), ("s", seeded_weights((6, 1, 1), 3))],
    ),
    "depth_to_space": (
        [named_node("DepthToSpace", blocksize=2, mode="CRD")],
        [],
    ),  # C = 6 is not divisible: see shape
    "instance_norm_gelu": (
        [named_node("InstanceNormalization", ("x", "s", "b"), "n"), named_node("Gelu", ("n",))],
        [("s", seeded_weights((6,), 4)), ("b", seeded_weights((6,), 5))],
    ),
    "reduce_mean_softmax": (
        [
            named_node("ReduceMean", ("x", "a"), "r", keepdims=1),
            named_node("Softmax", ("x",), "s", axis=1),
            named_node("Add", ("s", "r")),
        ],
        [("a", np.array([2, 3], np.int64))],
    ),
    "lrn_mish": ([named_node("LRN", ("x",), "l", size=3), named_node("Mish", ("l",))], []),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_single_ops_wgsl_vs_onnxruntime(name):
    _adapter_or_skip()
    nodes, inits = CASES[name]
    shape = (1, 8, 3, 5) if name == "depth_to_space" else (1, 6, 5, 7)
    model = image_model(nodes, inits, in_shape=shape)
    x = np.random.default_rng(0).normal(size=shape).astype(np.float32)
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    program = generate_compute(model, dialect="wgsl")
    assert program.manifest["format"] == "neuralao-wgsl-compute"
    assert all(name.endswith(".wgsl") for name in program.sources)
    got = run_wgsl_all(program, x)["y"]
    assert got.shape == ref.shape, (got.shape, ref.shape)
    assert got.dtype == ref.dtype == np.float32
    tol = TOL.glsl_op_fp32 * (
        10 if name == "lrn_mish" else 1
    )  # pow(.., 0.75) after a sum of squares: 2 ulp of ~30
    err = float(np.abs(got - ref).max())
    assert err <= tol, f"{name}: max abs err {err:.3g} > {tol}"


@pytest.mark.slow
def test_shipped_default_wgsl_vs_onnxruntime(tmp_path):
    """The shipped default U-Net, exported to WGSL and read back from disk, on an odd size (pad + crop)."""
    _adapter_or_skip()
    model_path = pure_unet_export() / "model.onnx"
    program = generate_compute(onnx.load(model_path), dialect="wgsl")
    write_compute_export(program, tmp_path / "wgsl")
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(0.5, 1.5, (1, 1, 28, 36)), rng.normal(size=(1, 3, 28, 36))], 1).astype(
        np.float32
    )
    radius = np.full((1, 1, 1, 1), 0.3, np.float32)
    padded = np.pad(
        x, ((0, 0), (0, 0), (0, 4), (0, 4)), mode="reflect"
    )  # what the pad pass does (multiple 8)
    ref = run_onnxruntime(model_path.read_bytes(), {"gbuffer": padded, "radius": radius})[0][..., :28, :36]
    got = next(iter(run_wgsl_all(tmp_path / "wgsl", x, scalars={"radius": radius}).values()))
    assert got.shape == ref.shape == (1, 1, 28, 36)
    assert float(np.abs(got - ref).max()) <= TOL.parity_unet_fp32


@pytest.mark.skipif(
    shutil.which("spirv-cross") is None, reason="spirv-cross not installed (Debian: spirv-cross)"
)
def test_hlsl_and_msl_beside_the_glsl(tmp_path):
    """--hlsl-msl writes <pass>.hlsl and <pass>.metal for every pass; each HLSL compiles back with glslang's
    HLSL front end (write_compute_export validates it), each declares its entry point named after the pass
    (tests/test_hlsl_target.py checks names and registers and runs the HLSL)."""
    nodes, inits = CASES["conv_blocked_leaky"]
    model = image_model(
        nodes
        + [
            named_node("AveragePool", ("y",), "p", kernel_shape=[2, 2], strides=[2, 2]),
            named_node("Resize", ("p", "", "s"), "r", mode="linear"),
        ],
        inits + [("s", np.array([1, 1, 2, 2], np.float32))],
        in_shape=(1, 6, "H", "W"),
    )
    model.graph.output[0].name = "r"
    manifest = json.loads(write_compute_export(generate_compute(model), tmp_path, cross=True).read_text())
    assert "HLSL front end" in manifest["cross_compiled"]["validated"]
    for p in manifest["passes"]:
        hlsl, msl = (tmp_path / p["hlsl"]["file"]).read_text(), (tmp_path / p["msl"]["file"]).read_text()
        assert f"[numthreads(8, 8, 1)]\nvoid {p['name']}(" in hlsl
        assert "RWTexture2DArray<float4> dst : register(u0)" in hlsl
        assert f"kernel void {p['name']}(" in msl
        assert manifest["files"][p["hlsl"]["file"]] and manifest["files"][p["msl"]["file"]]
