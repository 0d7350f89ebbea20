"""Baked-MLP export: ONNX (dynamic N) + generated GLSL fragment shader + manifest; backend checks,
parity, inference.

The ONNX graph is the raw :class:`neuralao.pipeline.models.mlp.BakedMLP`: input ``normals`` (N, 48) float32
= 16 object-space unit normals, xyz interleaved, output ``ao`` (N, 1) float32 = accessibility. The output is
the network's **linear, unclamped** value (no Clip node: the GLSL generator emits exactly the graph, and a
UNORM / clamped render target or the consumer clamps); everything here that produces an image clamps to [0,
1] and sets background to 1.

At run time the network is evaluated at radius zero: each pixel's own normal repeated 16 times
(Erra et al.); the generated shader does that itself (and folds the 16 column blocks of the first
layer into one, which changes only float32 rounding; parity holds it to TOL.parity_mlp_fp32).

Export layout (``export_checkpoint``)::

    OUT/model.onnx       checked, with metadata (input semantics, training mesh, measured error, size)
    OUT/glsl/ neuralao.export.glsl.write_mlp_export: mlp.vert/.frag (GLSL 3.30), ES 3.0, 4.30 variants,
                         uniform-block weight files and its own manifest.json
    OUT/manifest.json    everything: files + hashes, backend checks (torch / onnxruntime / OpenCV dnn),
                         checkpoint provenance, config and metrics (written last, atomically)
"""

from __future__ import annotations

import io
import json
import logging
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import onnx
import torch

from neuralao.export.glsl import generate_mlp_fragment, load_mlp_export, write_mlp_export
from neuralao.export.manifest import DIALECTS, OPSET, glsl_summary_of, per_mesh_manifest
from neuralao.export.onnx_io import (
    backend_checks,
    load_onnx,
    ort_session,
    run_opencv,
    save_onnx,
)
from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
from neuralao.pipeline.geometry.camera import orbit
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.pipeline.models.mlp import (
    CIRCLE_SAMPLES,
    INPUTS,
    BakedMLP,
    count_parameters,
    load_checkpoint,
    model_from_checkpoint,
    parameter_bytes,
    predict,
    radius_zero_inputs,
    size_name,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json
from neuralao.runtime.foundation.manifest import read_manifest
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.glsl_runner import run_mlp_fragment

# onnxruntime inference is the consumer runtime's (one copy); re-exported for parity and callers.
from neuralao.runtime.predict import MLP_INPUT, check_mlp_onnx, frame_normals
from neuralao.runtime.predict import run_mlp as run_network

log = logging.getLogger(__name__)

INPUT, OUTPUT = MLP_INPUT, "ao"
GLSL_DIR = "glsl"
# Batch sizes of the export-time backend checks: one row, an odd count, a large batch (dynamic N).
CHECK_BATCHES = (1, 7, 4096)
INPUT_DESCRIPTION = (
    f"normals: (N, {INPUTS}) float32, {CIRCLE_SAMPLES} object-space unit normals xyz-interleaved "
    "(x0, y0, z0, x1, ...); trained on the normals at angles k*2pi/16 on a circle of radius_px pixels around "
    "the pixel (background / off-screen points replaced by the centre normal); deployed at radius zero: "
    "the pixel's own normal repeated 16 times"
)
OUTPUT_DESCRIPTION = (
    "ao: (N, 1) float32 accessibility (1 = open, 0 = occluded), the network's linear output, NOT clamped: "
    "clamp to [0, 1]; background pixels are 1 by convention (not produced by the network)"
)


# ----------------------------------------------------------------------------------------------- ONNX


def onnx_metadata(model: BakedMLP, ckpt: dict | None = None) -> dict:
    """``metadata_props`` of the exported file: semantics, provenance, measured error, sizes."""
    ckpt = ckpt or {}
    metrics = ckpt.get("metrics", {})
    config = ckpt.get("config", {})
    samples = ckpt.get("samples", {})
    return {
        "neuralao_kind": "mlp",
        "input": INPUT_DESCRIPTION,
        "output": OUTPUT_DESCRIPTION,
        "output_clamped": "false",
        "units": (
            "normals are unitless object-space (= world-space of the flattened training mesh) directions"
        ),
        "radius_px": str(config.get("radius_px", "")),
        "train_inputs": str(config.get("train_inputs", "")),
        "training_mesh": str(ckpt.get("mesh") or ""),
        "scene": str(ckpt.get("scene") or ""),
        "sample_source": samples.get("source", ""),
        "ao_labels": samples.get("labels", {}),
        "model_size": size_name(model.hidden),
        "model_args": {"inputs": model.inputs, "hidden": list(model.hidden)},
        "parameters": str(count_parameters(model)),
        "parameter_bytes": str(parameter_bytes(model)),
        "measured_error": {
            k: metrics.get(k)
            for k in (
                "test_rmse",
                "val_rmse",
                "constant_test_rmse",
                "holdout_ssim",
                "holdout_rmse",
                "holdout_frames",
            )
        },
        "measured_error_note": (
            "holdout_*: held-back views, radius-zero input, clamped, masked SSIM (Gaussian 11, sigma 1.5)"
        ),
    }


def onnx_bytes(model: BakedMLP) -> bytes:
    """TorchScript exporter (``dynamo=False``), opset 17, dynamic batch N: Gemm / Tanh graph as bytes."""
    model = model.eval().to(torch.float32)
    buf = io.BytesIO()
    # dynamo=False is the exporter DESIGN.md names (Linear -> Gemm, Tanh); its deprecation warning is
    # expected.
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            model,
            (torch.zeros(2, model.inputs),),
            buf,
            dynamo=False,
            opset_version=OPSET,
            input_names=[INPUT],
            output_names=[OUTPUT],
            dynamic_axes={INPUT: {0: "N"}, OUTPUT: {0: "N"}},
            do_constant_folding=True,
        )
    return buf.getvalue()


def export_onnx(model: BakedMLP, path: str | Path, metadata: dict | None = None) -> onnx.ModelProto:
    """Export, check (onnx.checker, full) and write ``path`` atomically. Returns the ModelProto."""
    proto = onnx.load_from_string(onnx_bytes(model))
    save_onnx(proto, path, metadata if metadata is not None else onnx_metadata(model))
    return proto


def random_normals(n: int, seed: int = 0, radius_zero: bool = False) -> np.ndarray:
    """(n, 48) float32 inputs of unit normals: 16 independent ones, or one repeated (radius zero)."""
    rng = np.random.default_rng(seed)
    k = 1 if radius_zero else CIRCLE_SAMPLES
    v = rng.standard_normal((n, k, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    x = v.reshape(n, 3 * k).astype(np.float32)
    return radius_zero_inputs(x) if radius_zero else x


def _quiet_opencv() -> None:
    """OpenCV dnn logs a warning per network about setPreferableTarget; errors still surface."""
    try:
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    except AttributeError:  # a build without the logging utilities
        pass


def check_backends(model: BakedMLP, onnx_path: str | Path, seed: int = 0) -> dict:
    """Max |difference| onnxruntime vs torch and OpenCV dnn vs onnxruntime on random unit-normal inputs
    (independent circles and radius-zero rows) at batch sizes CHECK_BATCHES.

    Raises NeuralaoError above TOL.onnx_vs_torch (the rule for these outputs and this depth) /
    TOL.opencv_vs_onnx.
    """
    _quiet_opencv()
    sess = ort_session(onnx_path)
    rows, ref_max = [], 0.0
    for k, n in enumerate(CHECK_BATCHES):
        for radius_zero in (False, True):
            x = random_normals(n, seed + 2 * k + int(radius_zero), radius_zero)
            ref = predict(model, x)
            ref_max = max(ref_max, float(np.abs(ref).max()))
            y_ort = sess.run(None, {INPUT: x})[0]
            y_cv = run_opencv(onnx_path, {INPUT: x})
            if y_ort.shape != (n, 1) or y_cv.reshape(-1).shape != (n,):
                raise NeuralaoError(
                    f"exported MLP returned shape {y_ort.shape} (OpenCV {y_cv.shape}) for N={n}"
                )
            rows.append(
                {
                    "batch": n,
                    "radius_zero": radius_zero,
                    "onnxruntime_vs_torch": float(np.abs(y_ort[:, 0] - ref).max()),
                    "opencv_vs_onnxruntime": float(np.abs(y_cv.reshape(-1) - y_ort[:, 0]).max()),
                }
            )
    return backend_checks(
        rows,
        ref_max,
        onnx_path,
        checks=rows,
        inputs="random unit normals (16 independent per row, and radius-zero rows)",
    )


# ----------------------------------------------------------------------------------------------- export


def write_glsl(proto: onnx.ModelProto, out_dir: Path) -> dict:
    """Generate the fragment shader from the ONNX graph and write it (all dialects) to ``out_dir``.

    Returns the GLSL export's manifest (as written).
    """
    shader = generate_mlp_fragment(proto, dialect="glsl330")
    path = write_mlp_export(shader, out_dir)
    return json.loads(Path(path).read_text())


def export_checkpoint(ckpt_path: str | Path, out_dir: str | Path) -> dict:
    """model.onnx + glsl/ + manifest.json in ``out_dir`` from an MLP checkpoint. Returns the manifest."""
    t0 = time.perf_counter()
    ckpt_path, out_dir = Path(ckpt_path), Path(out_dir)
    ckpt = load_checkpoint(ckpt_path)
    model = model_from_checkpoint(ckpt)
    out_dir.mkdir(parents=True, exist_ok=True)
    onnx_path = out_dir / "model.onnx"
    metadata = onnx_metadata(model, ckpt)
    proto = export_onnx(model, onnx_path, metadata)
    checks = check_backends(model, onnx_path)
    glsl_manifest = write_glsl(proto, out_dir / GLSL_DIR)
    summary = glsl_summary_of(
        glsl_manifest, fold_repeated_input=glsl_manifest.get("network", {}).get("fold_repeated_input")
    )
    metrics = {k: v for k, v in ckpt.get("metrics", {}).items() if k != "holdout_per_view"}
    manifest = per_mesh_manifest(
        "mlp",
        out_dir,
        ckpt_path,
        ckpt,
        proto,
        GLSL_DIR,
        summary,
        metrics,
        t0,
        input={"name": INPUT, "shape": ["N", INPUTS], "dtype": "float32", "semantics": INPUT_DESCRIPTION},
        output={"name": OUTPUT, "shape": ["N", 1], "dtype": "float32", "semantics": OUTPUT_DESCRIPTION},
        metadata=metadata,
        model_size=size_name(model.hidden),
        parameters=count_parameters(model),
        parameter_bytes=parameter_bytes(model),
        checks=checks,
    )
    write_json(out_dir / "manifest.json", manifest)
    log.info(
        "exported %s: %s, %d parameters, ort-vs-torch %.2g, opencv-vs-ort %.2g",
        out_dir,
        manifest["model_size"],
        manifest["parameters"],
        checks["onnxruntime_vs_torch"],
        checks["opencv_vs_onnxruntime"],
    )
    return manifest


# ----------------------------------------------------------------------------------------------- inference


# ----------------------------------------------------------------------------------------------- parity


def render_parity_frames(mesh: str, views: int = 2, size: tuple[int, int] = (128, 128)) -> list[dict]:
    """Real G-buffer frames of the training mesh: ``views`` orbit cameras (seed 2, not training cameras)."""
    scene = load_scene(mesh)
    with GBufferRenderer(scene) as renderer:
        frames = [renderer.render(cam) for cam in orbit(scene, views, size[0], size[1], seed=2)]
    for f in frames:
        f["scene"] = scene.name
    return frames


def parity_export(
    export_dir: Path, kind: str, label: str, check_onnx: Callable[[onnx.ModelProto, Path], None]
) -> tuple[dict, onnx.ModelProto, Path]:
    """(manifest, checked ONNX graph, GLSL folder) of a per-mesh export folder of ``kind`` (``label``
    names it in errors); ``check_onnx(proto, path)`` is the kind's graph check."""
    manifest = read_manifest(export_dir, kind, label)
    onnx_path = export_dir / manifest.get("onnx", "model.onnx")
    proto = load_onnx(onnx_path)
    check_onnx(proto, onnx_path)
    return manifest, proto, export_dir / manifest.get("glsl", GLSL_DIR)


def parity_frames(export_dir: Path, manifest: dict, frames: list[FrameLike] | None) -> tuple[list[dict], str]:
    """The frames parity runs on and where they came from: ``frames`` if given, else
    :func:`render_parity_frames` of the export's training mesh."""
    if frames:
        return frames, "given frames"
    if not manifest.get("mesh"):
        raise NeuralaoError(f"export {export_dir} names no training mesh to render parity frames from")
    return render_parity_frames(manifest["mesh"]), f"rendered: 2 orbit views of {manifest['mesh']} at 128x128"


def pixel_errors(out: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> dict:
    """A parity row's figures for shader output ``out`` vs ``ref`` (H, W) float32 under ``mask`` (H, W)
    bool: foreground pixels, max |error| on them, max |out - 1| on the background (0 if none)."""
    return {
        "foreground_pixels": int(mask.sum()),
        "max_abs_err": float(np.abs(out[mask] - ref[mask]).max()),
        "background_max_abs_err": float(np.abs(out[~mask] - 1.0).max()) if (~mask).any() else 0.0,
    }


def parity(
    export_dir: str | Path,
    frames: list[FrameLike] | None = None,
    fp16: bool = True,
    dialects: tuple[str, ...] = DIALECTS,
) -> dict:
    """Generated GLSL (read from the export folder) vs onnxruntime on real frames, radius-zero input.

    Both get the same G-buffer (object-space normals + mask); the raw (unclamped) outputs are compared
    on every foreground pixel, and background must be exactly 1 in the shader. ``dialects``: GLSL 3.30
    and ES 3.0 by default (fp32, gated by TOL.parity_mlp_fp32); with ``fp16`` also GLSL 3.30 with
    RGBA16F storage (gated by TOL.parity_fp16). frames : G-buffer frame dicts, default: rendered views
    of the training mesh. Each dialect is a separate program: on llvmpipe its first draw compiles it
    (seconds for 16x8, minutes for 64x32 uncached; Mesa's disk cache keeps it afterwards).
    Returns figures with ``passed``.
    """
    export_dir = Path(export_dir)
    manifest, proto, glsl_dir = parity_export(export_dir, "mlp", "an MLP", check_mlp_onnx)
    if not (glsl_dir / "manifest.json").is_file():
        raise NeuralaoError(f"export {export_dir} has no GLSL export in {glsl_dir.name}/")
    frames, source = parity_frames(export_dir, manifest, frames)
    sess = ort_session(proto.SerializeToString())
    unknown = sorted(set(dialects) - set(DIALECTS))
    if unknown or not dialects:
        raise NeuralaoError(f"parity dialects must be among {DIALECTS}, got {list(dialects)}")
    variants = [(d, False) for d in dialects] + ([("glsl330", True)] if fp16 else [])
    shaders = {d: load_mlp_export(glsl_dir, dialect=d) for d in {v[0] for v in variants}}
    rows = []
    for i, frame in enumerate(frames):
        normal_obj, mask = frame_normals(frame)
        if not mask.any():
            continue
        ref = run_network(sess, normal_obj, mask)
        for dialect, half in variants:
            t0 = time.perf_counter()
            out = run_mlp_fragment(shaders[dialect], normal_obj, mask, fp16=half, dialect=dialect)
            seconds = time.perf_counter() - t0
            rows.append(
                {
                    "frame": i,
                    "scene": str(frame.get("scene", "")),
                    "view": int(frame["view"]) if "view" in frame else None,
                    "size": [int(mask.shape[1]), int(mask.shape[0])],
                    "dialect": dialect,
                    "storage": "fp16" if half else "fp32",
                    **pixel_errors(out, ref, mask),
                    "glsl_seconds": seconds,
                }
            )
    if not rows:
        raise NeuralaoError("parity: no frame with foreground pixels to check")

    def worst(storage: str, dialect: str | None = None) -> float | None:
        errs = [r["max_abs_err"] for r in rows if r["storage"] == storage and dialect in (None, r["dialect"])]
        return max(errs) if errs else None

    fp32_err = worst("fp32")
    fp16_err = worst("fp16")
    bg_err = max(r["background_max_abs_err"] for r in rows)
    passed = (
        fp32_err <= TOL.parity_mlp_fp32
        and bg_err == 0.0
        and (fp16_err is None or fp16_err <= TOL.parity_fp16)
    )
    return {
        "kind": "mlp",
        "model_size": manifest.get("model_size"),
        "frames": len(frames),
        "frame_source": source,
        "input": "radius zero (each pixel's object-space normal repeated 16 times), raw unclamped output",
        "max_abs_err": fp32_err,
        "max_abs_err_glsl330": worst("fp32", "glsl330"),
        "max_abs_err_es300": worst("fp32", "es300"),
        "max_abs_err_fp16": fp16_err,
        "background_max_abs_err": bg_err,
        "tolerance": TOL.parity_mlp_fp32,
        "tolerance_fp16": TOL.parity_fp16,
        "passed": bool(passed),
        "checks": rows,
    }
