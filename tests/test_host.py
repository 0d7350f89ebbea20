"""The standalone C host (runtime/host/neuralao_host.c, `make host`) on a real rendered frame against the
Python runner (export.unet's run_padded + glsl_runner path) and onnxruntime.

The host reads the shipped default export and a raw float32 G-buffer (H x W x (depth, nx, ny, nz,
mask), row 0 on top), does the engine's steps (mean depth, input texture, radius uniform, passes,
crop) and writes AO (H x W float32, 1 on background).
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from export.onnx_io import run_onnxruntime
from export.unet import composite, glsl_runner, radius_array, render_parity_frames, run_padded
from pipeline.foundation.tolerances import TOL
from pipeline.models.unet import pad_to_multiple, preprocess, radius_param
from runtime.shipped import INDEX, MODELS_DIR

REPO = Path(__file__).resolve().parents[1]


def _build_host() -> Path:
    """`make host`, skipped (with the reason) only where no C compiler or EGL / GL headers exist."""
    if shutil.which("make") is None or (shutil.which("cc") is None and shutil.which("gcc") is None):
        pytest.skip("no C compiler (Debian: gcc)")
    missing = [h for h in ("EGL/egl.h", "GL/glcorearb.h") if not Path("/usr/include", h).exists()]
    if missing:
        pytest.skip(f"no {missing[0]} (Debian: libegl-dev, libgl-dev)")
    r = subprocess.run(["make", "-s", "host"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return REPO / "build/host/neuralao_host"


def test_c_host_matches_python_runner(tmp_path):
    host = _build_host()
    export = MODELS_DIR / json.loads(INDEX.read_text())["default"]["unet"]
    frame = render_parity_frames((61, 45))[0]  # odd size: the pad pass pads to 64 x 48, the crop pass crops
    h, w = frame["depth"].shape
    gbuffer = np.concatenate([frame["depth"][..., None], frame["normal_cam"], frame["mask"][..., None]], -1)
    gbuffer.astype("<f4").tofile(tmp_path / "gbuffer.f32")
    radius, yfov = 0.1, float(frame["yfov"])
    r = subprocess.run(
        [
            str(host),
            str(export),
            str(tmp_path / "gbuffer.f32"),
            str(w),
            str(h),
            repr(radius),
            repr(math.degrees(yfov)),
            str(tmp_path / "ao.f32"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    ao = np.fromfile(tmp_path / "ao.f32", "<f4").reshape(h, w)

    rho = radius_param(radius, frame["depth"], frame["mask"], yfov)
    x = preprocess(frame["depth"], frame["normal_cam"], frame["mask"])
    python = composite(run_padded(glsl_runner(export / "glsl"), x, 8, rho), frame)
    assert float(np.abs(ao - python).max()) <= TOL.glsl_op_fp32  # same shaders, same driver
    ort = run_onnxruntime(
        (export / "model.onnx").read_bytes(),
        {"gbuffer": pad_to_multiple(x, 8)[None], "radius": radius_array(rho)},
    )[0]
    assert float(np.abs(ao - composite(ort[0, 0, :h, :w], frame)).max()) <= TOL.parity_unet_fp32
    assert np.all(ao[~frame["mask"]] == 1.0) and frame["mask"].any()


def test_c_host_refuses_a_wrong_gbuffer(tmp_path):
    host = _build_host()
    export = MODELS_DIR / json.loads(INDEX.read_text())["default"]["unet"]
    np.zeros(10, "<f4").tofile(tmp_path / "g.f32")
    r = subprocess.run(
        [str(host), str(export), str(tmp_path / "g.f32"), "16", "16", "0.1", "0.7", str(tmp_path / "ao.f32")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 1 and "5 floats a pixel" in r.stderr and not (tmp_path / "ao.f32").exists()
