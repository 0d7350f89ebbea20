"""`neuralao view --screen-space` in headless Chromium with WebGPU (Dawn on SwiftShader): the page's own
camera-space G-buffer against the project's rasterizer, and the AO its WebGPU path computed from that
G-buffer against runtime's onnxruntime predictor on the same (read-back) G-buffer.

The page is written from Python (not the CLI) so the test can ask for one texel per conv invocation
(conv_block (1, 1, 1)): SwiftShader compiles the default blocked conv shaders far too slowly (see
tests/test_wgsl_browser.py). The model runs at its declared internal height (point-sampled up from the
small canvas, AO upsampled by the joint bilateral filter), exactly as ``unet_predictor`` does.
"""

from __future__ import annotations

import base64
import json
import math
import time

import numpy as np
import onnx
import pytest
from helpers import needs_chromium

from neuralao.pipeline import cli
from neuralao.pipeline.bakes.viewer_inputs import method_from_unet, screen_space_mesh
from neuralao.runtime.chromium import SWIFTSHADER_WEBGL, headless_chromium, wait_for_page
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.predict import unet_predictor
from neuralao.runtime.shipped import pure_unet_export
from neuralao.runtime.viewer import write_page

pytestmark = needs_chromium
W, H = 48, 40
POSE = (30.0, 20.0, 0.9)  # azimuth, elevation (degrees), distance (diagonals), as the page's setPose
# Page G-buffer vs pipeline/gbuffers/rasterizer.py (llvmpipe): both snap vertices to their own sub-pixel
# grid, so at 48 x 40 a pixel samples the surface up to a fraction of a pixel apart and depth differs by
# that fraction of its per-pixel change (measured: median 1.7e-4 relative, the ratio to the per-pixel
# change <= 0.094 px, p99 0.032 px). Held to SNAP_PX pixels of the reference's depth gradient plus
# TOL.gbuffer_depth_rel; a wrong depth convention (clip depth, distance, a scale) is O(1) pixels.
SNAP_PX = 0.125


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    root = tmp_path_factory.mktemp("viewer_webgpu")
    pos, nrm = screen_space_mesh([], "spot")
    method = method_from_unet(None, pos, nrm, conv_block=(1, 1, 1))
    write_page([method], root / "page", (W, H))
    return root, method


@pytest.fixture(scope="module")
def browser(page):
    flags = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--enable-unsafe-webgpu")
    with headless_chromium(*flags, "--window-size=400,300") as driver:
        driver.get((page[0] / "page" / "index.html").as_uri())  # file:// is a secure context
        if not driver.execute_script("return !!navigator.gpu"):
            pytest.skip("this Chromium exposes no WebGPU")
        state = wait_for_page(driver)
        assert state and state[0] and not state[1], state
        yield driver


def _capture_network(driver) -> dict:
    """The page's U-Net run at POSE: G-buffer and AO, row 0 at the top."""
    driver.execute_script(
        "window.__nao = null; neuralao.setPose(...arguments[0]); neuralao.captureNetwork().then("
        "r => { window.__nao = r; }, e => { window.__nao = { error: String(e) }; });",
        list(POSE),
    )
    deadline = time.monotonic() + 300
    while (r := driver.execute_script("return window.__nao")) is None:
        assert time.monotonic() < deadline, "the page's U-Net did not finish within 300 s"
        time.sleep(0.2)
    assert "error" not in r, r["error"]
    h, w = r["height"], r["width"]
    img = {
        k: np.frombuffer(base64.b64decode(r[k]), np.float32).reshape(h, w, -1)[::-1]
        for k in ("position", "normal")
    }
    img["ao"] = np.frombuffer(base64.b64decode(r["ao"]), np.float32).reshape(h, w)[::-1]
    return r | img


def _reference_gbuffer(pos: np.ndarray) -> dict:
    """The project's rasterizer (pipeline/gbuffers/rasterizer.py) from the camera the page uses."""
    from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
    from neuralao.pipeline.geometry.camera import Camera
    from neuralao.pipeline.geometry.scene import load_scene

    lo, hi = pos.min(axis=0).astype(np.float64), pos.max(axis=0).astype(np.float64)
    centre, diag = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    az, el, r = math.radians(POSE[0]), math.radians(POSE[1]), POSE[2] * diag
    eye = centre + r * np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
    z = (eye - centre) / np.linalg.norm(eye - centre)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, np.cross(z, x), z, eye
    camera = Camera(pose, W, H, yfov=math.radians(45.0), znear=max(r - diag, r * 0.01), zfar=r + diag)
    return render_gbuffer(load_scene("spot"), camera)


def test_webgpu_unet_matches_onnxruntime_on_the_page_gbuffer(browser, page):
    _, method = page
    r = _capture_network(browser)
    mask = r["position"][..., 3] > 0.5
    assert mask.mean() > 0.15  # the mesh fills much of the frame
    assert np.all(r["position"][~mask] == 0) and np.all(r["normal"][~mask] == 0)

    # the G-buffer itself, against the rasterizer the U-Net's training frames come from
    ref = _reference_gbuffer(method.positions)
    depth = np.where(mask, -r["position"][..., 2], 0.0)
    assert np.mean(mask != ref["mask"]) <= TOL.gbuffer_id_mismatch_frac
    both = mask & ref["mask"]
    rel = np.abs(depth[both] - ref["depth"][both]) / ref["depth"][both]
    slope = np.hypot(*np.gradient(ref["depth"]))[both] / ref["depth"][both]  # relative depth per pixel
    cos = np.sum(r["normal"][..., :3][both] * ref["normal_cam"][both], axis=-1)
    # pixels on an occlusion edge may see either surface: a share as small as the mask's may differ
    outside = rel > TOL.gbuffer_depth_rel + SNAP_PX * slope
    assert np.mean(outside) <= TOL.gbuffer_id_mismatch_frac, np.quantile(rel / slope, 0.99)
    assert np.mean(cos < TOL.gbuffer_normal_cos) <= TOL.gbuffer_id_mismatch_frac, np.quantile(cos, 0.01)

    # the AO, against onnxruntime on the same G-buffer (internal height, upsampling and all)
    frame = {
        "depth": depth.astype(np.float32),
        "normal_cam": np.where(mask[..., None], r["normal"][..., :3], 0.0).astype(np.float32),
        "mask": mask,
        "yfov": math.radians(45.0),
    }
    onnx_path = method.info["onnx"]
    expected = unet_predictor(onnx_path)(frame, r["radius"])
    err = np.abs(r["ao"] - expected)
    print(
        f"\nWebGPU U-Net ({r['model']}, internal {r['internal']}, {r['ms']:.0f} ms, "
        f"adapter {r['adapter']!r}) "
        f"vs onnxruntime: max {err.max():.2e} mean {err.mean():.2e}; G-buffer depth rel p99 "
        f"{np.quantile(rel, 0.99):.2e}, normal cos p1 {np.quantile(cos, 0.01):.7f}, "
        f"mask mismatch {np.mean(mask != ref['mask']):.4f}"
    )
    assert np.all(r["ao"][~mask] == 1.0)
    assert np.ptp(expected[mask]) > 0.05  # a non-trivial AO over the view
    assert float(err.max()) <= TOL.parity_unet_fp32


def test_the_viewer_runs_a_pure_shipped_unet():
    from neuralao.runtime.predict import is_hybrid

    folder = pure_unet_export()
    assert not is_hybrid({p.key: p.value for p in onnx.load(folder / "model.onnx").metadata_props})


def test_a_hybrid_is_a_one_line_error_naming_a_pure_model(tmp_path, capsys):
    folder = pure_unet_export()
    hybrid = tmp_path / "hybrid"
    hybrid.mkdir()
    model = onnx.load(folder / "model.onnx")
    for p in model.metadata_props:
        if p.key == "input_channels":
            p.value += ",gtao"
    onnx.save(model, hybrid / "model.onnx")
    (hybrid / "manifest.json").write_text(json.dumps({"kind": "unet", "onnx": "model.onnx"}))
    out = tmp_path / "out"
    assert cli.main(["view", "--mesh", "spot", "--screen-space", str(hybrid), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "hybrid" in err and folder.name in err and "\n" not in err
    assert not out.exists()


def test_without_webgpu_the_page_says_so_and_still_draws(page):
    """Chromium without --enable-unsafe-webgpu (WebGL2 on SwiftShader only): a visible note, no error."""
    with headless_chromium(*SWIFTSHADER_WEBGL) as driver:
        driver.get((page[0] / "page" / "index.html").as_uri())
        deadline = time.monotonic() + 60
        note = ""
        while "WebGPU" not in note and time.monotonic() < deadline:
            time.sleep(0.1)
            note = driver.execute_script("return document.getElementById('note').textContent")
        if (
            driver.execute_script("return !!(window.neuralao && neuralao.ready) && !!navigator.gpu")
            and not note
        ):
            pytest.skip("this Chromium has WebGPU even without the flag")
        assert driver.execute_script("return [neuralao.ready, neuralao.error]") == [True, None]
        assert "WebGPU is not available" in note
        assert driver.execute_script("return neuralao.capture().position.length") > 0  # WebGL2 still draws
