"""`neuralao view --screen-space` in headless Chromium with WebGPU (Dawn, its Tint compiler, SwiftShader):
the shipped U-Nets' whole frame run by the page from the export's ``wgsl/`` folder alone, following the
manifest's ``frame.steps`` (runtime/viewer/wgsl.js ``runFrame``).

* the page's own camera-space G-buffer against the project's rasterizer (pipeline/gbuffers/rasterizer.py);
* the AO the page computed in WebGPU from that G-buffer (depth and normal uploaded, FrameUniforms from its
  camera, u_flip_y = 0) against the references on the same (read-back) G-buffer: what ``neuralao infer``
  computes (``unet_predictor``: GTAO in GL fragment shaders, numpy point sampling and upsampling,
  onnxruntime) and the same WGSL run by runtime/frame_runner.py through wgpu (naga, lavapipe), for the
  default hybrid (GTAO refined by the network) and the pure unet-fast;
* the command writes the default (a hybrid) without refusing it; without WebGPU the page says so.

The frame is 64 x 48 pixels and the network runs at the shipped internal height (256 rows: 341 x 256,
point-sampled up from the frame, its AO upsampled back), exactly as shipped: the page gets the export's
files unchanged.
"""

from __future__ import annotations

import base64
import math
import time

import numpy as np
import pytest
from helpers import needs_chromium

from neuralao.export.glsl import ComputeProgram
from neuralao.pipeline import cli
from neuralao.pipeline.bakes.viewer_inputs import method_from_unet, screen_space_mesh
from neuralao.runtime.baselines import hybrid_gtao
from neuralao.runtime.chromium import SWIFTSHADER_WEBGL, headless_chromium, wait_for_page
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.predict import unet_predictor
from neuralao.runtime.shipped import default_export
from neuralao.runtime.viewer import write_page

pytestmark = needs_chromium
W, H = 64, 48
MODELS = ("unet-gtao", "unet-fast")  # the page's methods, in this order; the first is the default
POSE = (30.0, 20.0, 0.9)  # azimuth, elevation (degrees), distance (diagonals), as the page's setPose
# Page G-buffer vs pipeline/gbuffers/rasterizer.py (llvmpipe): both snap vertices to their own sub-pixel
# grid, so at this size a pixel samples the surface up to a fraction of a pixel apart and depth differs by
# that fraction of its per-pixel change (measured at 48 x 40: median 1.7e-4 relative, the ratio to the
# per-pixel change <= 0.094 px, p99 0.032 px). Held to SNAP_PX pixels of the reference's depth gradient
# plus TOL.gbuffer_depth_rel; a wrong depth convention (clip depth, distance, a scale) is O(1) pixels.
SNAP_PX = 0.125


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    """(page folder, {model: ViewerMethod}) of a page with both shipped U-Nets, from their wgsl/ folders."""
    root = tmp_path_factory.mktemp("viewer_webgpu")
    pos, nrm = screen_space_mesh([], "spot")
    methods = {name: method_from_unet(name, pos, nrm) for name in MODELS}
    write_page(list(methods.values()), root / "page", (W, H))
    return root / "page", methods


@pytest.fixture(scope="module")
def browser(page):
    flags = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--enable-unsafe-webgpu")
    with headless_chromium(*flags, "--window-size=400,300") as driver:
        driver.get((page[0] / "index.html").as_uri())  # file:// is a secure context
        if not driver.execute_script("return !!navigator.gpu"):
            pytest.skip("this Chromium exposes no WebGPU")
        state = wait_for_page(driver)
        assert state and state[0] and not state[1], state
        yield driver


def _capture_network(driver, method: int) -> dict:
    """The page's frame run of method ``method`` at POSE: G-buffer and AO, row 0 at the top."""
    driver.execute_script(
        "window.__nao = null; neuralao.setMethod(arguments[1]); neuralao.setPose(...arguments[0]);"
        "neuralao.captureNetwork().then("
        "r => { window.__nao = r; }, e => { window.__nao = { error: String(e) }; });",
        list(POSE),
        method,
    )
    deadline = time.monotonic() + 300
    while (r := driver.execute_script("return window.__nao")) is None:
        assert time.monotonic() < deadline, "the page's frame did not finish within 300 s"
        time.sleep(0.1)
    assert "error" not in r, r["error"]
    h, w = r["height"], r["width"]
    img = {
        k: np.frombuffer(base64.b64decode(r[k]), np.float32).reshape(h, w, -1)[::-1]
        for k in ("position", "normal")
    }
    img["ao"] = np.frombuffer(base64.b64decode(r["ao"]), np.float32).reshape(h, w)[::-1]
    return r | img


def _read_network_texture(driver, ident: str) -> np.ndarray:
    """Texture ``ident`` of the page's latest frame: float32 (layers * h * w * lanes,), top row first."""
    driver.execute_script(
        "window.__nao = null; neuralao.readNetworkTexture(arguments[0]).then("
        "r => { window.__nao = { out: r }; }, e => { window.__nao = { error: String(e) }; });",
        ident,
    )
    while (r := driver.execute_script("return window.__nao")) is None:
        time.sleep(0.05)
    assert "error" not in r, r["error"]
    return np.frombuffer(base64.b64decode(r["out"]), np.float32)


def hybrid_images(method) -> list[str]:
    """The GTAO textures a hybrid's network reads: ``gtao``, and ``gtao_raw`` where it reads both images."""
    textures = method.network["manifest"]["frame"]["textures"]
    return [k for k in ("gtao", "gtao_raw") if k in textures]


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


def _frame(r: dict) -> dict:
    """The G-buffer frame the page's run read (what its depth and normal textures held)."""
    mask = r["position"][..., 3] > 0.5
    return {
        "depth": np.where(mask, -r["position"][..., 2], 0.0).astype(np.float32),
        "normal_cam": np.where(mask[..., None], r["normal"][..., :3], 0.0).astype(np.float32),
        "mask": mask,
        "yfov": r["yfov"],
    }


def _wgpu_frame(method, frame: dict, radius: float) -> np.ndarray | None:
    """The same WGSL through runtime/frame_runner.py on wgpu (naga, lavapipe); None without an adapter."""
    wgpu = pytest.importorskip("wgpu", reason="the wgpu package is not installed (pyproject pins it)")
    try:
        if wgpu.gpu.request_adapter_sync() is None:
            return None
    except RuntimeError:
        return None
    from neuralao.runtime.frame_runner import run_frame

    n = method.network
    program = ComputeProgram(n["sources"], base64.b64decode(n["weights"]), n["manifest"])
    return run_frame(program, frame, radius)


def test_the_page_gbuffer_matches_the_rasterizer(browser, page):
    r = _capture_network(browser, 0)
    mask = r["position"][..., 3] > 0.5
    assert mask.mean() > 0.15  # the mesh fills much of the frame
    assert np.all(r["position"][~mask] == 0) and np.all(r["normal"][~mask] == 0)
    ref = _reference_gbuffer(page[1][MODELS[0]].positions)
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


@pytest.mark.parametrize("index", range(len(MODELS)), ids=MODELS)
def test_the_page_runs_the_whole_frame_as_the_references(browser, page, index):
    name = MODELS[index]
    method = page[1][name]
    hybrid = method.network["manifest"]["frame"]["hybrid"]
    r = _capture_network(browser, index)
    assert r["model"] == name and r["internal"] == [341, 256]  # round(64 * 256 / 48) x the shipped 256
    frame = _frame(r)
    predict = unet_predictor(method.info["onnx"])
    references, got = {}, {}
    if hybrid:
        # GTAO's images against the GL fragment shaders, then the network and its frame passes on the page's
        # own GTAO: SwiftShader's GTAO differs from llvmpipe's by up to ~7e-5, which the network carries on
        page_gtao = {k: _read_network_texture(browser, k).reshape(H, W) for k in hybrid_images(method)}
        for k, expected in hybrid_gtao(frame, r["radius"], raw="gtao_raw" in page_gtao).items():
            references[f"run_gtao {k}"], got[f"run_gtao {k}"] = expected, page_gtao[k]
        references["unet_predictor on the page's GTAO"] = predict(frame, r["radius"], gtao=page_gtao)
    else:
        references["unet_predictor"] = predict(frame, r["radius"])
    wgpu_ao = _wgpu_frame(method, frame, r["radius"])
    if wgpu_ao is not None:
        if hybrid:  # the same WGSL on lavapipe, whose math is llvmpipe's: against the GL references
            references["wgpu vs unet_predictor"], got["wgpu vs unet_predictor"] = (
                predict(frame, r["radius"]),
                wgpu_ao,
            )
        else:
            references["wgpu"] = wgpu_ao
    report, worst = [], {}
    for what, expected in references.items():
        err = np.abs(got.get(what, r["ao"]) - expected)[frame["mask"]]
        over = np.mean(err > TOL.frame_passes_vs_reference)
        report.append(f"{what} max {err.max():.2e} ({over:.2%} of the foreground > 1e-4)")
        worst[what] = float(err.max())
    print(
        f"\nWebGPU frame of {name} in Chromium (adapter {r['adapter']!r}, {W}x{H}, network "
        f"{r['internal']}, {r['ms']:.0f} ms) vs " + "; ".join(report)
    )
    for what, err in worst.items():
        # GTAO's slice directions are baked constants: SwiftShader's coarse cos / sin move no tap
        bound = TOL.gtao_other_driver if what == "run_gtao gtao_raw" else TOL.frame_passes_vs_reference
        assert err <= bound, what
    assert np.all(r["ao"][~frame["mask"]] == 1.0)
    assert np.ptp(r["ao"][frame["mask"]]) > 0.05  # a non-trivial AO over the view


def test_the_command_writes_the_default_hybrid(tmp_path):
    out = tmp_path / "out"
    assert cli.main(["view", "--mesh", "spot", "--screen-space", "--out", str(out)]) == 0
    scene = (out / "scene.js").read_text()
    assert f'"model": "{default_export("unet").name}"' in scene and '"hybrid": true' in scene
    assert '"frame_pass": "f_gtao"' in scene


def test_without_webgpu_the_page_says_so_and_still_draws(page):
    """Chromium without --enable-unsafe-webgpu (WebGL2 on SwiftShader only): a visible note, no error."""
    with headless_chromium(*SWIFTSHADER_WEBGL) as driver:
        driver.get((page[0] / "index.html").as_uri())
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
