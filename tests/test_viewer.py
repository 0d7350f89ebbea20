"""`neuralao view` in a real headless Chromium (Debian's chromium + chromium-driver, driven by selenium).

The page renders fixed camera poses into its float targets; the test reads them back and checks each
method against an independent computation on the *same* G-buffer:

* the generated ES 3.00 field and MLP shaders against onnxruntime on the read-back position / normal;
* the vertex bake against the bake file's per-vertex AO interpolated at the read-back positions;
* the texture bake against a bilinear lookup (neuralao.pipeline.bakes.texture.sample_bilinear) of the .glb's
  map.

WebGL here runs on SwiftShader (Chromium's CPU Vulkan / GL implementation): the bound stated and
checked is TOL_SHADER (see the constant). Screenshots of every method go to NEURALAO_ARTIFACTS (if set)
or the test's temporary folder.
"""

from __future__ import annotations

import base64
import os
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import needs_chromium

from neuralao.pipeline import cli
from neuralao.runtime.chromium import SWIFTSHADER_WEBGL, headless_chromium, wait_for_page

pytestmark = needs_chromium
SIZE = 96
POSES = [(30.0, 20.0, 1.6), (-120.0, -10.0, 1.3)]  # azimuth, elevation (degrees), distance (diagonals)
# Generated shader vs onnxruntime, max abs error over foreground pixels. The path is float32 end to
# end (RGBA32F G-buffer, fp32 shader, RGBA32F target). Measured under SwiftShader (2 poses, 96x96):
# MLP 1.2e-7, field 2.1e-5 (llvmpipe: <= 1.4e-6, README).
TOL_SHADER = {
    "shader-mlp": 1e-5,
    "shader-field": 5e-5,  # SwiftShader's sin/cos are off by up to 1.9e-4 (measured, any |x|); tanh by 1e-7
}
# Vertex bake: the rasteriser's perspective-correct interpolation vs barycentrics recomputed from the
# read-back float32 position. Every pixel strictly inside a triangle (barycentrics > 1e-3) is held to
# it; pixels on an edge may belong to either triangle, and where the mesh duplicates vertices at UV
# seams (spot.obj) the two sides carry different vertex AO, so there only the 99th percentile is.
# Measured under SwiftShader: inside max 6e-7, 99th percentile 2.5e-7.
TOL_VERTEX = 1e-5
# Texture bake: the GPU's LINEAR lookup of the 8-bit map vs neuralao.pipeline.bakes.texture.sample_bilinear.
# The texel a pixel lands in can differ at chart seams (one pixel measured at 0.078), so the 99th percentile
# and the mean are bounded. Measured under SwiftShader: p99 1.3e-6, mean <= 7e-5.
TOL_TEXTURE_P99, TOL_TEXTURE_MEAN = 1e-4, 1e-3


def _random_checkpoints(root: Path) -> tuple[Path, Path]:
    """A seeded, untrained field (16x8) and MLP (16x8) of spot: non-trivial functions, no training time."""
    from neuralao.pipeline.geometry.scene import load_scene
    from neuralao.pipeline.models.checkpoint import per_mesh_checkpoint, save_checkpoint
    from neuralao.pipeline.models.field import FORMAT_VERSION as FIELD_VERSION
    from neuralao.pipeline.models.field import KIND as FIELD_KIND
    from neuralao.pipeline.models.field import FieldNet, bounding_box
    from neuralao.pipeline.models.field import model_args_dict as field_args
    from neuralao.pipeline.models.field import parameter_bytes as field_bytes
    from neuralao.pipeline.models.mlp import FORMAT_VERSION as MLP_VERSION
    from neuralao.pipeline.models.mlp import KIND as MLP_KIND
    from neuralao.pipeline.models.mlp import BakedMLP
    from neuralao.pipeline.models.mlp import model_args_dict as mlp_args
    from neuralao.pipeline.models.mlp import parameter_bytes as mlp_bytes

    scene = load_scene("spot")
    info = {"scene": "spot", "mesh": scene.source}
    torch.manual_seed(0)
    centre, inv_half = bounding_box(scene.vertices)
    field = FieldNet([16, 8], 4, centre, inv_half)
    mlp = BakedMLP(hidden=[16, 8])
    out = []
    for name, model, kind, version, args, nbytes in (
        ("field", field, FIELD_KIND, FIELD_VERSION, field_args, field_bytes),
        ("mlp", mlp, MLP_KIND, MLP_VERSION, mlp_args, mlp_bytes),
    ):
        ckpt = per_mesh_checkpoint(
            kind, version, model, args(model), {}, info, {}, {"seconds": 0.0}, nbytes(model)
        )
        save_checkpoint(root / f"{name}.pt", ckpt)
        out.append(root / f"{name}.pt")
    return out[0], out[1]


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    from neuralao.export.field import export_checkpoint as export_field
    from neuralao.export.mlp import export_checkpoint as export_mlp

    root = tmp_path_factory.mktemp("viewer")
    field_ckpt, mlp_ckpt = _random_checkpoints(root)
    export_field(field_ckpt, root / "field")
    export_mlp(mlp_ckpt, root / "mlp")
    bake = ["bake", "spot", "--rays", "16", "--workers", "1"]
    assert cli.main([*bake, "--method", "vertex", "--out", str(root / "vertex.glb")]) == 0
    assert (
        cli.main([*bake, "--to", "texture", "--resolution", "128", "--out", str(root / "texture.glb")]) == 0
    )
    inputs = [str(root / n) for n in ("vertex.glb", "texture.glb", "field", "mlp")]
    assert cli.main(["view", *inputs, "--out", str(root / "page"), "--size", str(SIZE), str(SIZE)]) == 0
    return root


@pytest.fixture(scope="module")
def browser(page):
    with headless_chromium(*SWIFTSHADER_WEBGL, "--window-size=700,600") as driver:
        driver.get((page / "page" / "index.html").as_uri())
        state = wait_for_page(driver)
        assert state and state[0] and not state[1], state
        yield driver


def _capture(driver, method: int, pose) -> dict:
    driver.execute_script(
        f"window.neuralao.setMethod({method}); window.neuralao.setPose({pose[0]}, {pose[1]}, {pose[2]});"
    )
    c = driver.execute_script("return window.neuralao.capture()")
    h, w = c["height"], c["width"]
    # readPixels returns the bottom row first: flip to row 0 at the top (the project's convention)
    img = {
        k: np.frombuffer(base64.b64decode(c[k]), np.float32).reshape(h, w, 4)[::-1]
        for k in ("position", "normal", "ao")
    }
    img["mask"] = img["position"][..., 3] > 0.5
    img["renderer"] = c["renderer"]
    return img


def _methods(driver) -> dict[str, int]:
    return {
        m["kind"] + ("-" + m["name"].split()[0] if m["kind"] == "shader" else ""): i
        for i, m in enumerate(driver.execute_script("return window.neuralao.methods"))
    }


def test_generated_shaders_match_onnxruntime_on_the_same_gbuffer(browser, page):
    from neuralao.export.onnx_io import run_onnxruntime

    methods = _methods(browser)
    worst = {}
    for kind, folder in (("shader-field", "field"), ("shader-mlp", "mlp")):
        errs = []
        for pose in POSES:
            img = _capture(browser, methods[kind], pose)
            m = img["mask"]
            assert m.sum() > 0.1 * SIZE * SIZE  # the mesh fills the frame
            pos, nrm = img["position"][m][:, :3], img["normal"][m][:, :3]
            if folder == "field":
                ref = run_onnxruntime(page / folder / "model.onnx", {"position": pos, "normal": nrm})
            else:  # Erra et al.: the pixel's own normal repeated 16 times
                ref = run_onnxruntime(page / folder / "model.onnx", {"normals": np.tile(nrm, (1, 16))})
            ref = np.asarray(ref, np.float32).reshape(-1)
            got = img["ao"][..., 0]
            assert np.all(got[~m] == 1.0)  # background exactly 1, as the shader says
            assert np.ptp(ref) > 0.01  # a non-trivial function of the G-buffer
            errs.append(float(np.abs(got[m] - ref).max()))
        worst[kind] = max(errs)
    print(f"\nbrowser parity on {img['renderer']}: {worst}")
    assert all(worst[k] <= TOL_SHADER[k] for k in worst), worst


def _locate(vertices, faces, points):
    """Face (k,) and barycentrics (k, 3) of points lying on the mesh: nearest face centroids, then the
    candidate whose plane is closest and whose barycentrics are inside (largest minimum coordinate)."""
    from scipy.spatial import cKDTree

    tri = vertices[faces]
    _, cand = cKDTree(tri.mean(axis=1)).query(points, k=24)
    a, b, c = tri[cand, 0], tri[cand, 1], tri[cand, 2]
    n = np.cross(b - a, c - a)
    n2 = np.einsum("kjd,kjd->kj", n, n)
    p = points[:, None, :]
    l1 = np.einsum("kjd,kjd->kj", np.cross(p - a, c - a), n) / n2
    l2 = np.einsum("kjd,kjd->kj", np.cross(b - a, p - a), n) / n2
    bary = np.stack([1 - l1 - l2, l1, l2], axis=-1)
    dist = np.abs(np.einsum("kjd,kjd->kj", p - a, n)) / np.sqrt(n2)
    score = np.minimum(bary.min(axis=-1), 0.0) * 10 - dist / np.linalg.norm(np.ptp(vertices, axis=0))
    best = np.argmax(score, axis=1)
    k = np.arange(len(points))
    return cand[k, best], np.clip(bary[k, best], 0, 1) / np.clip(bary[k, best], 0, 1).sum(
        axis=1, keepdims=True
    )


def test_vertex_and_texture_bakes_match_their_files(browser, page):
    from neuralao.pipeline.bakes.texture import point_uvs, read_texture_glb, sample_bilinear
    from neuralao.pipeline.bakes.vertex import read_baked_mesh

    methods = _methods(browser)
    vertices, faces, vertex_ao, _ = read_baked_mesh(page / "vertex.glb")
    tex_mesh, red = read_texture_glb(page / "texture.glb")
    for pose in POSES:
        img = _capture(browser, methods["vertex"], pose)
        m = img["mask"]
        face, bary = _locate(vertices, faces, img["position"][m][:, :3].astype(np.float64))
        ref = np.einsum("kc,kc->k", bary, vertex_ao[faces[face]].astype(np.float64))
        err = np.abs(img["ao"][..., 0][m] - ref)
        inside = bary.min(axis=1) > 1e-3
        assert inside.mean() > 0.9 and err[inside].max() <= TOL_VERTEX, err[inside].max()
        assert np.quantile(err, 0.99) <= TOL_VERTEX

        img = _capture(browser, methods["texture"], pose)
        m = img["mask"]
        face, bary = _locate(tex_mesh.vertices, tex_mesh.faces, img["position"][m][:, :3].astype(np.float64))
        ref = sample_bilinear(red, point_uvs(tex_mesh, face, bary))
        err = np.abs(img["ao"][..., 0][m] - ref)
        assert np.quantile(err, 0.99) <= TOL_TEXTURE_P99 and err.mean() <= TOL_TEXTURE_MEAN, (
            np.quantile(err, 0.99),
            err.mean(),
        )
        assert np.ptp(ref) > 0.2  # the map really varies over the view


def test_screenshots_of_every_method(browser, page, tmp_path):
    """Each method's canvas at 320x240 (the page reloaded at that size), and a 2x2 sheet of them
    (viewer-methods.png: the README's screenshot)."""
    from PIL import Image, ImageDraw
    from selenium.webdriver.common.by import By

    out = Path(os.environ.get("NEURALAO_ARTIFACTS", tmp_path))
    out.mkdir(parents=True, exist_ok=True)
    url = browser.current_url
    browser.get((page / "page" / "index.html").as_uri() + "?w=320&h=240")
    try:
        deadline = time.monotonic() + 60
        while (
            not browser.execute_script("return window.neuralao && window.neuralao.ready")
            and time.monotonic() < deadline
        ):
            time.sleep(0.05)
        shots = []
        for name, i in _methods(browser).items():
            browser.execute_script(f"window.neuralao.setMethod({i}); window.neuralao.setPose(35, 15, 1.1);")
            path = out / f"viewer-{name}.png"
            path.write_bytes(browser.find_element(By.ID, "view").screenshot_as_png)
            shot = Image.open(path).convert("RGB")
            assert shot.size == (320, 240) and np.asarray(shot.convert("L")).std() > 10  # drawn, not blank
            ImageDraw.Draw(shot).text(
                (6, 4),
                browser.execute_script("return window.neuralao.methods")[i]["name"],
                fill=(230, 230, 230),
            )
            shots.append(shot)
        assert len(shots) == 4
        sheet = Image.new("RGB", (640, 480))
        for k, shot in enumerate(shots):
            sheet.paste(shot, ((k % 2) * 320, (k // 2) * 240))
        sheet.save(out / "viewer-methods.png")
    finally:
        browser.get(url)


def test_serve_answers_on_localhost(page):
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "neuralao.pipeline.cli",
            "view",
            str(page / "vertex.glb"),
            "--out",
            str(page / "served"),
            "--serve",
            "--port",
            "0",
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = ""
        deadline = time.monotonic() + 60
        while "serving" not in line and time.monotonic() < deadline:
            line = proc.stderr.readline()
        url = line.split(" on ")[1].split()[0]
        html = urllib.request.urlopen(url, timeout=10).read().decode()
        assert "viewer.js" in html and "scene.js" in html
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.mark.parametrize(
    "args, message",
    [
        (["nonexistent.glb"], "no such file"),
        (["{root}/field/model.onnx"], "expected a bake"),
        (["{root}"], "not an export folder"),
        (["{root}/vertex.glb", "--size", "0", "10"], "--size"),
    ],
)
def test_bad_input_is_a_one_line_error(page, tmp_path, capsys, args, message):
    args = [a.format(root=page) for a in args]
    assert cli.main(["view", *args, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
    assert not (tmp_path / "out").exists()
