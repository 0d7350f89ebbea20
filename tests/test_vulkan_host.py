"""The Vulkan runner (runtime/host/neuralao_vk.c, `make host-vk`) against the GL host (`make host`).

Both read an export and a raw float32 G-buffer (H x W x (depth, nx, ny, nz, mask), row 0 on top) and write
AO (H x W float32, 1 on background) by the export's frame steps: the GL host from glsl/, the Vulkan runner
from vulkan/ (the same passes as Vulkan GLSL, compiled to SPIR-V), on Mesa's llvmpipe and lavapipe here.

* both shipped models on a rendered frame, at a size that is a multiple of 8 and one that is not, at two
  radii: the runner's AO within TOL.frame_passes_vs_reference of the GL host's;
* an fp16 export (the AO R16F, the hybrid's GTAO R16, fp16 arithmetic) within the manifest's fp16 bound of
  the fp32 export;
* weight ranges at offsets the device cannot bind are repacked: the same AO bit for bit;
* the timing line (NEURALAO_HOST_REPEATS) and one-line errors on bad input.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import onnx
import pytest
from test_host import _build_host

from neuralao.export.glsl import write_compute_export
from neuralao.export.glsl.frame import dispatch_counts
from neuralao.export.unet import render_parity_frames
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.frame_runner import frame_program
from neuralao.runtime.shipped import shipped_models

REPO = Path(__file__).resolve().parents[1]
SIZES = ((96, 64), (83, 61))  # (w, h); 83 x 61: neither side a multiple of 8
RADII = (0.15, 1.0)


@pytest.fixture(scope="module")
def runner() -> Path:
    """`make host-vk`, skipped (with the reason) only where no C compiler or Vulkan headers exist."""
    if shutil.which("make") is None or (shutil.which("cc") is None and shutil.which("gcc") is None):
        pytest.skip("no C compiler (Debian: gcc)")
    if not Path("/usr/include/vulkan/vulkan.h").exists():
        pytest.skip("no vulkan/vulkan.h (Debian: libvulkan-dev)")
    r = subprocess.run(["make", "-s", "host-vk"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return REPO / "build/host/neuralao_vk"


@pytest.fixture(scope="module")
def frames() -> dict[tuple[int, int], dict]:
    """A rendered G-buffer frame (the Cornell box from inside: occlusion in the corners, some background)
    at each size of SIZES."""
    return {size: render_parity_frames(size)[1] for size in SIZES}


def _run(binary: Path, export: Path, frame: dict, radius: float, tmp_path: Path, **env: str):
    """(AO (H, W) float32, the finished process) of one run of ``binary`` on ``frame``."""
    h, w = frame["depth"].shape
    gbuffer = np.concatenate([frame["depth"][..., None], frame["normal_cam"], frame["mask"][..., None]], -1)
    gbuffer.astype("<f4").tofile(tmp_path / "gbuffer.f32")
    args = [str(tmp_path / "gbuffer.f32"), str(w), str(h), repr(radius), repr(math.degrees(frame["yfov"]))]
    out = tmp_path / "ao.f32"
    out.unlink(missing_ok=True)
    r = subprocess.run(
        [str(binary), str(export), *args, str(out)],
        env=os.environ | env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    return np.fromfile(out, "<f4").reshape(h, w), r


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("name", ["unet-gtao", "unet-fast"])
def test_vulkan_runner_matches_the_gl_host(name, size, runner, frames, tmp_path):
    """A shipped model's whole frame from its SPIR-V (vulkan/) against the GL host's from its GLSL (glsl/):
    the same passes, two compilers and drivers (measured max 4.5e-6 on lavapipe against llvmpipe)."""
    host = _build_host()
    export, frame = shipped_models()[name], frames[size]
    errors, aos = [], []
    for radius in RADII:
        vk, _ = _run(runner, export, frame, radius, tmp_path)
        gl, _ = _run(host, export, frame, radius, tmp_path)
        errors.append(float(np.abs(vk - gl).max()))
        assert np.all(vk[~frame["mask"]] == 1.0) and frame["mask"].any() and not frame["mask"].all()
        aos.append(vk)
    assert max(errors) <= TOL.frame_passes_vs_reference, (name, size, errors)
    # the test can fail: the radius moves the AO far more than the tolerance
    assert float(np.abs(aos[0] - aos[1]).max()) > 100 * TOL.frame_passes_vs_reference


def test_fp16_export_runs_within_the_fp16_bound(runner, frames, tmp_path):
    """An export written at fp16 (RGBA16F network textures, the AO R16F, the hybrid's GTAO R16: 16-bit
    unsigned normalised, fp16 arithmetic where the device has shaderFloat16) against the shipped fp32
    export: within the fp16 bound the model's manifest states (measured 1.2e-3 on lavapipe here; 1.0e-3 to
    1.8e-3 over both models, both sizes and three radii)."""
    export = tmp_path / "fp16"
    program = frame_program(
        onnx.load(shipped_models()["unet-gtao"] / "model.onnx"), dialect="vulkan", precision="fp16"
    )
    write_compute_export(program, export / "vulkan", validate=False)
    manifest = json.loads((export / "vulkan" / "manifest.json").read_text())
    assert manifest["frame"]["textures"]["ao"]["format"] == "R16F"  # the half-float read-back is exercised
    assert manifest["frame"]["textures"]["gtao"]["format"] == "R16"  # VK_FORMAT_R16_UNORM storage images
    frame = frames[SIZES[1]]
    half, _ = _run(runner, export, frame, 0.3, tmp_path)
    full, _ = _run(runner, shipped_models()["unet-gtao"], frame, 0.3, tmp_path)
    err = float(np.abs(half - full).max())
    bound = json.loads((shipped_models()["unet-gtao"] / "manifest.json").read_text())["fp16"]["bound"]
    assert 0 < err <= bound, (err, bound)  # 0 would mean the fp16 passes did not run


def test_unaligned_weight_ranges_are_repacked(runner, frames, tmp_path):
    """weights.bin with every pass's range moved 4 bytes on (below lavapipe's 16-byte
    minStorageBufferOffsetAlignment): the runner copies the ranges to offsets it can bind, same AO."""
    src = shipped_models()["unet-fast"]
    export = tmp_path / "shifted"
    shutil.copytree(src / "vulkan", export / "vulkan")
    manifest = json.loads((export / "vulkan" / "manifest.json").read_text())
    weights = (export / "vulkan" / "weights.bin").read_bytes()
    (export / "vulkan" / "weights.bin").write_bytes(b"\0" * 4 + weights)
    manifest["weights"]["bytes"] += 4
    for p in manifest["passes"]:
        if "params" in p:
            p["params"]["offset"] += 4
    (export / "vulkan" / "manifest.json").write_text(json.dumps(manifest))
    frame = frames[SIZES[0]]
    shifted, _ = _run(runner, export, frame, 0.4, tmp_path)
    want, _ = _run(runner, src, frame, 0.4, tmp_path)
    assert np.array_equal(shifted, want)


def test_timing_line(runner, tmp_path):
    """NEURALAO_HOST_REPEATS=1: one JSON line, the GL host's keys with "api": "vulkan", the device's name,
    the whole frame, its network and GTAO steps timed by timestamps (-1 where the queue has none) and on
    the wall clock."""
    out = tmp_path / "ao.f32"
    r = subprocess.run(
        [str(runner), str(shipped_models()["unet-gtao"]), "synthetic", "64", "48", "0.5", "60", str(out)],
        env=os.environ | {"NEURALAO_HOST_REPEATS": "1"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    line = json.loads(r.stdout)
    assert line["api"] == "vulkan" and line["renderer"] and line["version"].startswith("Vulkan ")
    assert (line["width"], line["height"], line["repeats"], line["path"]) == (64, 48, 1, "frame")
    for key in ("frame", "network", "gtao"):
        assert line[f"{key}_ms"] > 0 or line[f"{key}_ms"] == -1, line
        assert line[f"{key}_wall_ms"] > 0, line
    manifest = json.loads((shipped_models()["unet-gtao"] / "vulkan" / "manifest.json").read_text())
    assert line["ssao_ms"] == -1 and line["passes"] == dispatch_counts(manifest, 64, 48)["passes"]
    assert np.fromfile(out, "<f4").size == 64 * 48


@pytest.mark.parametrize(
    "case",
    ["missing export", "wrong G-buffer", "no such device"],
)
def test_bad_input_is_one_line_on_stderr(case, runner, tmp_path):
    export, gbuffer, env = shipped_models()["unet-fast"], "synthetic", {}
    if case == "missing export":
        export = tmp_path / "nothing-here"
    elif case == "wrong G-buffer":
        np.zeros(10, "<f4").tofile(tmp_path / "g.f32")
        gbuffer = str(tmp_path / "g.f32")
    else:
        env = {"NEURALAO_VK_DEVICE": "no device is named like this"}
    out = tmp_path / "ao.f32"
    r = subprocess.run(
        [str(runner), str(export), gbuffer, "16", "16", "0.1", "60", str(out)],
        env=os.environ | env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode != 0 and not out.exists()
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("neuralao_vk: "), r.stderr
    expected = {
        "missing export": "cannot open",
        "wrong G-buffer": "5 floats a pixel",
        "no such device": "devices:",
    }
    assert expected[case] in r.stderr, r.stderr
