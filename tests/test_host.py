"""The standalone C host (runtime/host/neuralao_host.c, `make host`) against the Python runners.

The host reads an export and a raw float32 G-buffer (H x W x (depth, nx, ny, nz, mask), row 0 on top)
and writes AO (H x W float32, 1 on background):

* an export with a frame section (the shipped ones): the whole frame on the GPU in the order of
  ``frame.steps``, against ``neuralao.runtime.frame_runner``'s FrameRunner on the same files;
* an export without one: the network's passes with the engine's steps on the CPU around them (mean
  depth, input texture, radius uniform), against the glsl_runner path and onnxruntime, and a hybrid's
  fragment passes at its internal resolution against ``neuralao.runtime.predict``.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import onnx
import pytest
from helpers import analytic_gbuffer

from neuralao.export.glsl import load_compute_export, write_compute_export
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.export.unet import glsl_runner, render_parity_frames
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.frame_runner import FrameRunner, frame_program
from neuralao.runtime.predict import composite, radius_array, run_padded
from neuralao.runtime.shipped import pure_unet_export, shipped_models
from neuralao.runtime.unet_input import pad_to_multiple, preprocess, radius_param

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


def _drop_frame_section(export: Path) -> None:
    """The export as one written before frame passes existed: the host takes its older path."""
    path = export / "glsl" / "manifest.json"
    glsl = json.loads(path.read_text())
    glsl.pop("frame")
    path.write_text(json.dumps(glsl))


FRAME_SIZE = (75, 53)  # neither side a multiple of 8; the network at 362 x 256, point-sampled up
FRAME_RADII = (0.15, 1.0)


@pytest.mark.parametrize("name", ["unet-gtao", "unet-fast"])
def test_c_host_runs_the_frame_steps_as_the_python_runner(name, tmp_path):
    """A shipped model's whole frame from its frame section (position, GTAO, point sampling, the mean depth,
    the network's input and radius, the network, upsampling with the hybrid's correction) in the C host
    against FrameRunner on the same files (same shaders, same driver: measured identical on llvmpipe) and
    against the reference ``neuralao infer`` runs (GTAO in fragment shaders, numpy resampling,
    onnxruntime; measured <= 1.2e-6), at two radii."""
    from neuralao.runtime.predict import unet_predictor

    host = _build_host()
    export = shipped_models()[name]
    frame = analytic_gbuffer(*FRAME_SIZE)
    reference = unet_predictor(export / "model.onnx")
    errors, aos = [], []
    with FrameRunner(load_compute_export(export / "glsl"), *FRAME_SIZE) as runner:
        for radius in FRAME_RADII:
            ao = _run_host(host, export, frame, radius, tmp_path)
            errors.append(float(np.abs(ao - runner.run(frame, radius)).max()))
            errors.append(float(np.abs(ao - reference(frame, radius)).max()))
            assert np.all(ao[~frame["mask"]] == 1.0) and frame["mask"].any()
            aos.append(ao)
    assert max(errors) <= TOL.frame_passes_vs_reference, (name, errors)
    # the test can fail: the radius moves the AO far more than the tolerance
    assert float(np.abs(aos[0] - aos[1]).max()) > 100 * TOL.frame_passes_vs_reference


def test_c_host_runs_an_fp16_export_as_the_python_runner(tmp_path):
    """An export written with --precision fp16 (RGBA16F network textures, the AO R16F, the hybrid's GTAO
    R16: 16-bit unsigned normalised) in the C host against FrameRunner on the same program (same shaders,
    same driver), and within the model's fp16 bound of the shipped fp32 export."""
    host = _build_host()
    shipped = shipped_models()["unet-gtao"]
    program = frame_program(onnx.load(shipped / "model.onnx"), precision="fp16")
    write_compute_export(program, tmp_path / "fp16" / "glsl", validate=False)
    textures = program.manifest["frame"]["textures"]
    assert (textures["gtao_raw"]["format"], textures["gtao"]["format"], textures["ao"]["format"]) == (
        "R16",
        "R16",
        "R16F",
    )
    frame, radius = analytic_gbuffer(*FRAME_SIZE), FRAME_RADII[0]
    half = _run_host(host, tmp_path / "fp16", frame, radius, tmp_path)
    with FrameRunner(program, *FRAME_SIZE) as runner:
        assert float(np.abs(half - runner.run(frame, radius)).max()) <= TOL.frame_passes_vs_reference
    full = _run_host(host, shipped, frame, radius, tmp_path)
    bound = json.loads((shipped / "manifest.json").read_text())["fp16"]["bound"]
    assert 0 < float(np.abs(half - full).max()) <= bound  # 0 would mean the fp16 passes did not run


def test_c_host_matches_python_runner(tmp_path):
    host = _build_host()
    # the network's own pass chain at the frame's size: a copy of the pure shipped export without its
    # frame section and internal-resolution passes (those are checked by the tests below)
    export = tmp_path / "export"
    shutil.copytree(pure_unet_export(), export)
    manifest = json.loads((export / "manifest.json").read_text())
    manifest.pop("internal_resolution", None)
    manifest.pop("internal_height", None)
    (export / "manifest.json").write_text(json.dumps(manifest))
    _drop_frame_section(export)
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

    version = int(manifest["preprocess_version"])  # the host follows the export's input contract
    rho = radius_param(radius, frame["depth"], frame["mask"], yfov, version)
    x = preprocess(frame["depth"], frame["normal_cam"], frame["mask"], version)
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
    export = pure_unet_export()
    np.zeros(10, "<f4").tofile(tmp_path / "g.f32")
    r = subprocess.run(
        [str(host), str(export), str(tmp_path / "g.f32"), "16", "16", "0.1", "0.7", str(tmp_path / "ao.f32")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 1 and "5 floats a pixel" in r.stderr and not (tmp_path / "ao.f32").exists()


def _host_process(
    host: Path, export: Path, frame: dict, radius: float, tmp_path: Path
) -> subprocess.CompletedProcess:
    """The C host on ``frame``'s G-buffer (written to tmp_path/gbuffer.f32), its AO to tmp_path/ao.f32."""
    h, w = frame["depth"].shape
    gbuffer = np.concatenate([frame["depth"][..., None], frame["normal_cam"], frame["mask"][..., None]], -1)
    gbuffer.astype("<f4").tofile(tmp_path / "gbuffer.f32")
    args = [str(tmp_path / "gbuffer.f32"), str(w), str(h), repr(radius), repr(math.degrees(frame["yfov"]))]
    return subprocess.run(
        [str(host), str(export), *args, str(tmp_path / "ao.f32")], capture_output=True, text=True, timeout=300
    )


def _run_host(host: Path, export: Path, frame: dict, radius: float, tmp_path: Path) -> np.ndarray:
    r = _host_process(host, export, frame, radius, tmp_path)
    assert r.returncode == 0, r.stderr
    return np.fromfile(tmp_path / "ao.f32", "<f4").reshape(frame["depth"].shape)


@pytest.mark.parametrize("blur", [True, False], ids=["gtao", "gtao-pass-alone"])
@pytest.mark.parametrize("route", ["frame", "fragment"])
def test_c_host_runs_a_hybrid_export_at_its_internal_resolution(route, blur, tmp_path):
    """GTAO pass, point sampling, the network at the internal size, upsampling of its correction and
    clamp(GTAO + correction), by the export's frame section (compute passes, ``frame``) or, without one,
    by its internal-resolution fragment passes with the CPU between them (``fragment``): the C host from
    the export's files alone against neuralao.runtime.predict's
    reference (onnxruntime network, float64 numpy upsampler). The two differ by the generated GLSL vs
    onnxruntime (TOL.parity_unet_fp32; the correction passes through the upsampler's convex weights, so
    it does not grow) plus the GLSL vs numpy upsampler (TOL.upsample_glsl_vs_numpy); GTAO is the same
    shader on the same driver. A hybrid trained on GTAO's pass alone (``blur`` False) runs no blur."""
    from test_hybrid import _hybrid, write_internal_export

    from neuralao.runtime.baselines import GTAOSettings, run_gtao
    from neuralao.runtime.internal_resolution import downsample_frame, upsample_ao
    from neuralao.runtime.predict import unet_predictor

    host = _build_host()
    frame = render_parity_frames((96, 64))[0]
    radius, internal = 0.3, 40  # the network runs at 60 x 40
    write_internal_export(_hybrid(gtao_blur=blur), tmp_path / "export", internal)
    if route == "fragment":
        _drop_frame_section(tmp_path / "export")
    ao = _run_host(host, tmp_path / "export", frame, radius, tmp_path)
    ref = unet_predictor(tmp_path / "export" / "model.onnx", "model")(frame, radius)
    tol = TOL.parity_unet_fp32 + TOL.upsample_glsl_vs_numpy
    err = float(np.abs(ao - ref).max())
    assert err <= tol, err
    assert np.all(ao[~frame["mask"]] == 1.0) and frame["mask"].any()

    # the test can fail: the correction is visible, and a shortcut (GTAO run on the point-sampled frame,
    # the AO upsampled as a pure export's is) lands far outside the tolerance
    assert float(np.abs(ref - run_gtao(frame, radius, GTAOSettings(blur=blur))).max()) > 10 * tol
    low = downsample_frame(frame, 60, internal)
    shortcut = upsample_ao(unet_predictor(tmp_path / "export" / "model.onnx", None)(low, radius), frame)
    assert float(np.abs(shortcut - ref).max()) > 10 * tol


def test_c_host_refuses_a_model_that_reads_an_input_it_does_not_feed(tmp_path):
    """An export of input version 4 reads the engine's back layer (depth_back) beside depth and normal:
    the host, which feeds those two, refuses it in one line instead of running it with a zero texture."""
    import torch

    from neuralao.export.unet import export_onnx, onnx_metadata
    from neuralao.pipeline.models.unet import UNet, UNetArgs

    host = _build_host()
    model = UNet(UNetArgs(in_channels=6, widths=[4, 8], gtao_input=True, preprocess_version=4)).eval()
    with torch.no_grad():
        proto = export_onnx(model, tmp_path / "model.onnx", onnx_metadata(model) | {"internal_height": "32"})
    write_compute_export(frame_program(proto), tmp_path / "v4" / "glsl", validate=False)
    r = _host_process(host, tmp_path / "v4", analytic_gbuffer(*FRAME_SIZE), 0.5, tmp_path)
    assert r.returncode != 0 and not (tmp_path / "ao.f32").exists()
    assert "depth_back" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_c_host_runs_a_hybrid_on_both_gtao_images_from_its_frame_section_only(tmp_path):
    """A hybrid that reads GTAO before its blur beside the blurred GTAO: the C host runs its frame section
    (both images made, point-sampled and packed by the generated passes) as neuralao.runtime.predict does;
    its fragment route, which assembles one GTAO image on the CPU, refuses it in one line."""
    import torch
    from test_hybrid import write_internal_export

    from neuralao.pipeline.models.unet import UNet, UNetArgs
    from neuralao.runtime.predict import unet_predictor

    host = _build_host()
    torch.manual_seed(3)
    model = UNet(UNetArgs(in_channels=6, widths=[4, 8, 16], gtao_input=True, gtao_raw_input=True)).eval()
    with torch.no_grad():
        model.out.weight.mul_(4.0)
    frame = render_parity_frames((96, 64))[0]
    radius, internal = 0.3, 40
    write_internal_export(model, tmp_path / "export", internal)
    ao = _run_host(host, tmp_path / "export", frame, radius, tmp_path)
    ref = unet_predictor(tmp_path / "export" / "model.onnx", "model")(frame, radius)
    err = float(np.abs(ao - ref).max())
    assert err <= TOL.frame_passes_vs_reference, err

    _drop_frame_section(tmp_path / "export")
    (tmp_path / "ao.f32").unlink()
    r = _host_process(host, tmp_path / "export", frame, radius, tmp_path)
    assert r.returncode != 0 and not (tmp_path / "ao.f32").exists()
    assert "before its blur" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
