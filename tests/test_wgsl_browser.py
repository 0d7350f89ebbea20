"""The generated WGSL in a second WebGPU implementation: headless Chromium (Dawn, its Tint compiler,
SwiftShader), through the browser runner runtime/viewer/wgsl.js, against onnxruntime.

wgpu (tests/test_wgsl_target.py) compiles WGSL with naga; this holds the same sources to Tint, the
compiler of the browsers that ship WebGPU. SwiftShader compiles large unrolled shaders very slowly (the
default conv block, 8 x 4 texels x 2 layers = 64 accumulators, did not finish within 10 minutes for one
small conv), so the shipped default runs with one texel per conv invocation (conv_block (1, 1, 1)) and a
small network with a 2 x 1 x 2 block, so the blocked template meets Tint too.
"""

from __future__ import annotations

import base64
import time
from pathlib import Path

import numpy as np
import onnx
import pytest
from helpers import needs_chromium
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import ComputeProgram, generate_compute
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.chromium import headless_chromium
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.shipped import pure_unet_export

pytestmark = needs_chromium
RUNNER = Path(__file__).resolve().parents[1] / "runtime" / "viewer" / "wgsl.js"

# Started by the test, collected by polling (SwiftShader may compile for longer than one WebDriver call).
_START = """
const [manifest, sources, weightsB64, xB64, w, h, scalars] = arguments;
const dec = s => Uint8Array.from(atob(s), c => c.charCodeAt(0)).buffer;
window.__nao = null;
(async () => {
  const adapter = await navigator.gpu.requestAdapter();
  if (!adapter) return { error: "no WebGPU adapter" };
  const device = await adapter.requestDevice();
  const errors = [];
  device.addEventListener("uncapturederror", e => errors.push(e.error.message));
  const out = await neuralaoWgsl.run(device, { manifest, sources, weights: dec(weightsB64) },
                                     new Float32Array(dec(xB64)), w, h, scalars, false);
  const u8 = new Uint8Array(out.buffer);
  let s = "";
  for (let i = 0; i < u8.length; i += 0x8000) \
s += String.fromCharCode.apply(null, u8.subarray(i, i + 0x8000));
  return errors.length ? { error: errors[0] } : { out: btoa(s) };
})().then(r => { window.__nao = r; }, e => { window.__nao = { error: String(e) }; });
"""


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    page = tmp_path_factory.mktemp("wgsl_page")
    (page / "wgsl.js").write_text(RUNNER.read_text())
    (page / "index.html").write_text('<!doctype html><meta charset="utf-8"><script src="wgsl.js"></script>\n')
    with headless_chromium("--enable-unsafe-webgpu", "--enable-unsafe-swiftshader") as driver:
        driver.get((page / "index.html").as_uri())  # file:// is a secure context: navigator.gpu exists
        if not driver.execute_script("return !!navigator.gpu"):
            pytest.skip("this Chromium exposes no WebGPU")
        yield driver


def _run(driver, program: ComputeProgram, x: np.ndarray, scalars: dict) -> np.ndarray:
    """program's first output on x (1, C, H, W) in the browser: (C_out, H, W) float32."""
    _, _, h, w = x.shape
    weights = base64.b64encode(program.weights).decode()
    driver.execute_script(
        _START,
        program.manifest,
        program.sources,
        weights,
        base64.b64encode(np.ascontiguousarray(x[0]).tobytes()).decode(),
        w,
        h,
        scalars,
    )
    deadline = time.monotonic() + 600
    while (r := driver.execute_script("return window.__nao")) is None:
        assert time.monotonic() < deadline, "the browser did not finish within 600 s"
        time.sleep(0.2)
    assert "error" not in r, r["error"]
    return np.frombuffer(base64.b64decode(r["out"]), np.float32).reshape(-1, h, w)


def test_shipped_default_in_chromium_webgpu(browser):
    model_path = pure_unet_export() / "model.onnx"
    program = generate_compute(onnx.load(model_path), dialect="wgsl", conv_block=(1, 1, 1))
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(0.5, 1.5, (1, 1, 28, 36)), rng.normal(size=(1, 3, 28, 36))], 1).astype(
        np.float32
    )
    got = _run(browser, program, x, {"radius": 0.3})
    padded = np.pad(x, ((0, 0), (0, 0), (0, 4), (0, 4)), mode="reflect")  # the pad pass's work
    radius = np.full((1, 1, 1, 1), 0.3, np.float32)
    ref = run_onnxruntime(model_path.read_bytes(), {"gbuffer": padded, "radius": radius})[0][0, :, :28, :36]
    assert got.shape == ref.shape == (1, 28, 36)
    assert float(np.abs(got - ref).max()) <= TOL.parity_unet_fp32


def test_blocked_conv_in_chromium_webgpu(browser):
    rng = np.random.default_rng(1)
    inits = [
        nh.from_array(rng.normal(size=(8, 6, 3, 3)).astype(np.float32), "w"),
        nh.from_array(rng.normal(size=(8,)).astype(np.float32), "b"),
        nh.from_array(np.array([1, 1, 2, 2], np.float32), "s"),
    ]
    nodes = [
        oh.make_node("Conv", ["x", "w", "b"], ["c"], pads=[1, 1, 1, 1]),
        oh.make_node("LeakyRelu", ["c"], ["l"], alpha=0.1),
        oh.make_node("AveragePool", ["l"], ["p"], kernel_shape=[2, 2], strides=[2, 2]),
        oh.make_node("Resize", ["p", "", "s"], ["y"], mode="linear"),
    ]
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 6, 10, 14])],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, None)],
        inits,
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", 19)])
    program = generate_compute(model, dialect="wgsl", conv_block=(2, 1, 2))
    assert [p["block"] for p in program.manifest["passes"] if p["kind"] == "conv"] == [[2, 1, 2]]
    x = rng.normal(size=(1, 6, 10, 14)).astype(np.float32)
    got = _run(browser, program, x, {})
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0][0]
    assert got.shape == ref.shape
    assert float(np.abs(got - ref).max()) <= TOL.glsl_op_fp32 * 10  # sums of 54 products of N(0, 1) values
