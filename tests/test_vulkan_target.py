"""The Vulkan dialect of the compute target: Vulkan GLSL passes compiled to SPIR-V and run.

* every pass of both shipped U-Nets (fp32, fp16) and of onnx's node-test image graphs
  (export/node_tests.py) compiles with ``glslangValidator -V`` and passes ``spirv-val``;
* the manifest's descriptor bindings and uniform block layout are those of the SPIR-V itself
  (``spirv-cross --reflect``), and its SPIR-V files match their hashes;
* the SPIR-V runs on a Vulkan driver (Mesa lavapipe, through wgpu: the words as they are, and through
  naga's SPIR-V front end) against onnxruntime: the shipped fast U-Net on a real G-buffer frame at a
  size that is not a multiple of 8, single-op graphs, a dynamic-size graph with a bottom-up input.

Single-node graphs built with onnx.helper, seeded inputs, shape and dtype before values,
TOL.glsl_op_fp32 unless a case says why not. Skipped, with the reason, only where a tool is missing.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import warnings

import numpy as np
import onnx
import pytest
from helpers import image_model, named_node, seeded_weights
from onnx import TensorProto
from onnx import helper as oh

from neuralao.export.glsl import compile_spirv, generate_compute, load_compute_export, write_compute_export
from neuralao.export.glsl.graph import sha256_hex
from neuralao.export.node_tests import _with_initializers, node_cases
from neuralao.export.onnx_glsl import parity
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.pipeline import cli
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.shipped import shipped_models

needs_glslang = pytest.mark.skipif(
    shutil.which("glslangValidator") is None, reason="glslangValidator not installed (Debian: glslang-tools)"
)
SPIRV_MAGIC = b"\x03\x02\x23\x07"


def _run_spirv(program, x, via, **kw):
    """run_spirv_all, skipped (with the reason) where wgpu, a Vulkan adapter or SPIR-V passthrough is
    missing."""
    wgpu = pytest.importorskip("wgpu", reason="the wgpu package is not installed (pyproject pins it)")
    if shutil.which("glslangValidator") is None:
        pytest.skip("glslangValidator not installed (Debian: glslang-tools)")
    try:
        adapter = wgpu.gpu.request_adapter_sync()
    except RuntimeError:
        adapter = None
    if adapter is None:
        pytest.skip("no WebGPU adapter (Debian: mesa-vulkan-drivers)")
    if via == "passthrough" and "spirv-shader-passthrough" not in adapter.features:
        pytest.skip(f"adapter {adapter.info['device']!r} has no SPIR-V passthrough (not a Vulkan adapter)")
    from neuralao.runtime.wgsl_runner import run_spirv_all

    return run_spirv_all(program, x, via=via, **kw)


# ----------------------------------------------------------------------------- compiled, bindings


_REFLECT_KINDS = {
    "separate_images": "sampled_image",
    "images": "storage_image",
    "ssbos": "storage_buffer",
    "ubos": "uniform_buffer",
}


def _reflected_bindings(spv: bytes, tmp_path) -> tuple[list[dict], dict]:
    """(set, binding, kind) of every resource of a SPIR-V module, by spirv-cross's reflection, and the
    uniform block's member offsets {name: offset}."""
    path = tmp_path / "pass.spv"
    path.write_bytes(spv)
    r = subprocess.run(["spirv-cross", str(path), "--reflect"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    refl = json.loads(r.stdout)
    got = [
        {"set": res["set"], "binding": res["binding"], "kind": kind}
        for key, kind in _REFLECT_KINDS.items()
        for res in refl.get(key, [])
    ]
    assert not refl.get("textures") and not refl.get("separate_samplers")  # no sampler to bind
    members = {
        m["name"]: m["offset"] for ubo in refl.get("ubos", []) for m in refl["types"][ubo["type"]]["members"]
    }
    return sorted(got, key=lambda b: b["binding"]), members


@pytest.fixture(scope="module", params=[(m, p) for m in ("unet-gtao", "unet-fast") for p in ("fp32", "fp16")])
def shipped_vulkan_export(request, tmp_path_factory):
    """(export folder, manifest) of a shipped U-Net in Vulkan GLSL + SPIR-V, (model, precision) each."""
    if shutil.which("glslangValidator") is None:
        pytest.skip("glslangValidator not installed (Debian: glslang-tools)")
    model, precision = request.param
    program = generate_compute(onnx.load(shipped_models()[model] / "model.onnx"), precision, dialect="vulkan")
    out = tmp_path_factory.mktemp(f"{model}-{precision}")
    return out, json.loads(write_compute_export(program, out).read_text())


def test_shipped_passes_compile_to_spirv(shipped_vulkan_export):
    out, manifest = shipped_vulkan_export
    assert manifest["format"] == "neuralao-vulkan-compute" and manifest["spirv"]["compiled"]
    for p in manifest["passes"]:
        source = (out / p["shader"]).read_text()
        assert source.startswith("#version 450\n") and "layout(location" not in source
        spv = (out / p["spirv"]["file"]).read_bytes()
        assert spv[:4] == SPIRV_MAGIC
        assert sha256_hex(spv) == p["spirv"]["sha256"] == manifest["files"][p["spirv"]["file"]]
        bindings = [b["binding"] for b in p["bindings"]]
        assert len(set(bindings)) == len(bindings), p["name"]  # distinct per pass
    loaded = load_compute_export(out)
    assert set(loaded.spirv) == set(loaded.sources)


@pytest.mark.skipif(
    shutil.which("spirv-cross") is None, reason="spirv-cross not installed (Debian: spirv-cross)"
)
def test_manifest_bindings_are_the_spirv_bindings(shipped_vulkan_export, tmp_path):
    """Each pass's ``bindings`` (set, binding, kind) and ``uniform_block`` member offsets, as the
    engine reads them, are those the SPIR-V declares (spirv-cross's reflection)."""
    out, manifest = shipped_vulkan_export
    for p in manifest["passes"]:
        got, members = _reflected_bindings((out / p["spirv"]["file"]).read_bytes(), tmp_path)
        assert got == [{k: b[k] for k in ("set", "binding", "kind")} for b in p["bindings"]], p["name"]
        block = p.get("uniform_block", {"members": []})
        assert members == {m["name"]: m["offset"] for m in block["members"]}, p["name"]


@pytest.fixture(scope="module")
def node_test_graphs() -> list[tuple[str, onnx.ModelProto]]:
    """onnx's node tests of the ops the other dialects' node tests and shader-conformance run, as the
    image graphs export/node_tests.py builds (test inputs 2.. as initializers)."""
    ops = (
        "Conv", "ConvTranspose", "MaxPool", "AveragePool", "GlobalAveragePool", "GlobalMaxPool", "Resize",
        "Upsample", "Pad", "Concat", "Add", "Relu", "LeakyRelu", "PRelu", "DepthToSpace", "SpaceToDepth",
        "InstanceNormalization", "GroupNormalization", "LayerNormalization", "ReduceMean", "ReduceMax",
        "ReduceSum", "ReduceL2", "Softmax", "LogSoftmax", "Erf", "Gelu", "Mish", "Sum", "Mean", "Min",
        "Max", "LRN", "LpPool", "GlobalLpPool", "Dropout",
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cases = node_cases(ops)
    return [(c.name, _with_initializers(c.model, list(c.data_sets[0][0]))) for c in cases]


@needs_glslang
def test_node_test_graphs_compile_to_spirv(node_test_graphs):
    sources: dict[str, str] = {}
    for name, model in node_test_graphs:
        try:
            program = generate_compute(model, dialect="vulkan")
        except NeuralaoError:  # refused for every dialect alike (rank-3 inputs, ...): not this test's
            continue
        sources.update({src: f"{name}/{shader}" for shader, src in program.sources.items()})
    assert len(sources) > 50  # most ops' cases have a (1, C, H, W) input
    failed = []
    for src, where in sources.items():
        try:
            assert compile_spirv(src)[:4] == SPIRV_MAGIC
        except NeuralaoError as e:
            failed.append((where, str(e)))
    assert not failed, failed


# ----------------------------------------------------------------------------- executed


# One case per kind of pass: conv (blocked), transposed, depthwise, pools, resize (nearest reads the
# ``precise`` coordinates), pad, concat + binary, moments + normalize, and a scalar graph input (the
# uniform pass: a float in the uniform block).
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
    "resize_nearest": (
        [named_node("Resize", ("x", "", "s"), mode="nearest", coordinate_transformation_mode="asymmetric")],
        [("s", np.array([1, 1, 1.5, 2], np.float32))],
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
    "instance_norm_gelu": (
        [named_node("InstanceNormalization", ("x", "s", "b"), "n"), named_node("Gelu", ("n",))],
        [("s", seeded_weights((6,), 4)), ("b", seeded_weights((6,), 5))],
    ),
    "scalar_input": ([named_node("Mul", ("x", "k"))], []),
    # per-pixel ops computed inside their reader (the gpu preset's pointwise group)
    "pointwise_chain": (
        [
            named_node("Conv", ("x", "w"), "a"),
            named_node("Mul", ("a", "x"), "b"),
            named_node("Neg", ("b",), "n"),
            named_node("Sigmoid", ("n",), "s"),
            named_node("Add", ("s", "a")),
        ],
        [("w", seeded_weights((6, 6, 1, 1), 6) * 0.4)],
    ),
}


@pytest.mark.parametrize("via", ["passthrough", "naga"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_single_ops_spirv_vs_onnxruntime(name, via):
    nodes, inits = CASES[name]
    scalar = name == "scalar_input"
    extra = [oh.make_tensor_value_info("k", TensorProto.FLOAT, [1, 1, 1, 1])] if scalar else []
    model = image_model(nodes, inits, extra_inputs=extra)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(1, 6, 5, 7)).astype(np.float32)
    feeds = {"x": x, **({"k": np.full((1, 1, 1, 1), 0.7, np.float32)} if scalar else {})}
    ref = run_onnxruntime(model.SerializeToString(), feeds)[0]
    program = generate_compute(model, dialect="vulkan")
    if name == "pointwise_chain":
        assert [p["kind"] for p in program.manifest["passes"]] == ["pointwise"]
    got = _run_spirv(program, x, via, scalars={"k": feeds["k"]} if scalar else None)["y"]
    assert got.shape == ref.shape, (got.shape, ref.shape)
    assert got.dtype == ref.dtype == np.float32
    err = float(np.abs(got - ref).max())
    assert err <= TOL.glsl_op_fp32, f"{name} ({via}): max abs err {err:.3g} > {TOL.glsl_op_fp32}"


@pytest.mark.parametrize("via", ["passthrough", "naga"])
def test_dynamic_size_pad_crop_and_bottom_up_input(via):
    """A dynamic-size graph (pad multiple 2: the pad and crop passes, whose u_flip_y is the int of their
    uniform blocks) at an odd size; a bottom-up input with flip_y=True gives the bottom-up output."""
    nodes = [
        named_node("Conv", ("x", "w"), "c", pads=[1, 1, 1, 1]),
        named_node("AveragePool", ("c",), "p", kernel_shape=[2, 2], strides=[2, 2]),
        named_node("Resize", ("p", "", "s"), mode="linear"),
    ]
    model = image_model(
        nodes,
        [("w", seeded_weights((5, 3, 3, 3))), ("s", np.array([1, 1, 2, 2], np.float32))],
        (1, 3, "H", "W"),
    )
    x = np.random.default_rng(1).normal(size=(1, 3, 7, 9)).astype(np.float32)
    program = generate_compute(model, dialect="vulkan")
    assert program.pad_multiple == 2
    padded = np.pad(x, ((0, 0), (0, 0), (0, 1), (0, 1)), mode="reflect")  # what the pad pass does
    ref = run_onnxruntime(model.SerializeToString(), {"x": padded})[0][..., :7, :9]
    got = _run_spirv(program, x, via)["y"]
    assert got.shape == ref.shape == (1, 5, 7, 9)
    assert float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32
    flipped = _run_spirv(program, np.ascontiguousarray(x[:, :, ::-1]), via, flip_y=True)["y"]
    assert float(np.abs(flipped[:, :, ::-1] - ref).max()) <= TOL.glsl_op_fp32


@pytest.mark.slow
def test_shipped_fast_unet_spirv_on_a_real_frame(tmp_path):
    """The shipped fast U-Net's network, exported to Vulkan GLSL + SPIR-V and read back from disk, on a
    rendered G-buffer frame of 61 x 45 (the pad pass pads to 64 x 48, the crop pass crops) vs onnxruntime."""
    from neuralao.export.unet import render_parity_frames
    from neuralao.runtime.predict import radius_array
    from neuralao.runtime.unet_input import pad_to_multiple, preprocess, radius_param

    if shutil.which("glslangValidator") is None:
        pytest.skip("glslangValidator not installed (Debian: glslang-tools)")
    export = shipped_models()["unet-fast"]
    version = int(json.loads((export / "manifest.json").read_text())["preprocess_version"])
    program = generate_compute(onnx.load(export / "model.onnx"), dialect="vulkan")
    write_compute_export(program, tmp_path / "vk")
    frame = render_parity_frames((61, 45))[0]
    rho = radius_param(0.1, frame["depth"], frame["mask"], float(frame["yfov"]), version)
    x = preprocess(frame["depth"], frame["normal_cam"], frame["mask"], version)
    ref = run_onnxruntime(
        (export / "model.onnx").read_bytes(),
        {"gbuffer": pad_to_multiple(x, 8)[None], "radius": radius_array(rho)},
    )[0][..., :45, :61]
    got = next(
        iter(
            _run_spirv(
                tmp_path / "vk", x[None], "passthrough", scalars={"radius": radius_array(rho)}
            ).values()
        )
    )
    assert got.shape == ref.shape == (1, 1, 45, 61)
    assert frame["mask"].any() and float(np.abs(got - ref).max()) <= TOL.parity_unet_fp32


# ----------------------------------------------------------------------------- command line


@needs_glslang
def test_cli_writes_vulkan_passes_and_spirv_and_parity_runs_them(tmp_path, capsys):
    nodes, inits = CASES["conv_blocked_leaky"]
    model = image_model(
        nodes + [named_node("AveragePool", ("y",), "z", kernel_shape=[2, 2], strides=[2, 2])],
        inits,
        (1, 6, "H", "W"),
    )
    model.graph.output[0].CopyFrom(oh.make_tensor_value_info("z", TensorProto.FLOAT, [1, 9, None, None]))
    path = tmp_path / "m.onnx"
    onnx.save(model, path)
    out = tmp_path / "out"
    assert cli.main(["glsl", str(path), "--target", "image", "--dialect", "vulkan", "--out", str(out)]) == 0
    top = json.loads((out / "manifest.json").read_text())
    assert top["dialect"] == "vulkan" and top["glsl"] == "vulkan"
    manifest = json.loads((out / "vulkan" / "manifest.json").read_text())
    assert manifest["format"] == "neuralao-vulkan-compute"
    for p in manifest["passes"]:
        assert (out / "vulkan" / p["spirv"]["file"]).read_bytes()[:4] == SPIRV_MAGIC
    pytest.importorskip("wgpu", reason="the wgpu package is not installed (pyproject pins it)")
    r = parity(out, seed=2, size=(10, 6))
    assert r["passed"] and r["max_abs_err"] <= TOL.parity_unet_fp32
    for args, needle in (
        (["--target", "wgsl", "--dialect", "vulkan"], "--dialect vulkan"),
        (["--target", "image", "--dialect", "vulkan", "--hlsl-msl"], "GLSL 4.30"),
    ):
        bad = tmp_path / "bad"
        assert cli.main(["glsl", str(path), *args, "--out", str(bad)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], err
        assert not (bad / "manifest.json").exists()
