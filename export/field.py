"""Neural-field export: ONNX (two inputs, dynamic N) + generated GLSL fragment shader + manifest; parity.

The ONNX graph is :class:`neuralao.pipeline.models.field.FieldNet` as is: inputs ``position`` (N, 3) float32
= the object-space position in the mesh's own units (the graph normalises it by the bounding box itself) and
``normal`` (N, 3) float32 = the viewer-facing object-space unit normal; output ``ao`` (N, 1) float32,
linear and unclamped. Ops: Sub, Mul, MatMul, Sin, Cos, Concat, Gemm, Tanh.

The fragment shader reads two RGBA32F G-buffer textures, ``position`` (xyz object-space position,
w foreground mask; sampler ``u_tex0``) and ``normal`` (xyz object-space normal; ``u_tex1``), and writes
the AO; everything it needs (weights, normalisation, frequencies) is in std140 uniform blocks described
by its manifest.

Export layout (``export_checkpoint``)::

    OUT/model.onnx       checked, with metadata (encoding, bounding box, sizes, exact bytes, error)
    OUT/glsl/            the fragment target's files: mlp.vert/.frag (GLSL 3.30), mlp_es300.*, mlp_430.*,
                         uniform-block weight files, manifest.json (kind "field")
    OUT/manifest.json    files + hashes, backend checks, provenance, metrics (written last)
"""

from __future__ import annotations

import io
import json
import logging
import time
import warnings
from pathlib import Path

import numpy as np
import onnx
import torch

from neuralao.export.glsl import InputBinding, generate_vector_fragment, load_mlp_export, write_mlp_export
from neuralao.export.manifest import DIALECTS, OPSET, glsl_summary_of, per_mesh_manifest
from neuralao.export.mlp import parity_export, parity_frames, pixel_errors
from neuralao.export.onnx_io import ort_session, save_onnx, weighted_layers
from neuralao.pipeline.models.field import (
    FieldNet,
    count_parameters,
    load_checkpoint,
    model_from_checkpoint,
    parameter_bytes,
    predict,
    size_name,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.glsl_runner import run_vector_fragment

# onnxruntime inference is the consumer runtime's (one copy); re-exported for parity and callers.
from neuralao.runtime.predict import FIELD_NORMAL, FIELD_POSITION, check_field_onnx, frame_inputs
from neuralao.runtime.predict import run_field as run_network

log = logging.getLogger(__name__)

POSITION, NORMAL, OUTPUT = FIELD_POSITION, FIELD_NORMAL, "ao"
GLSL_DIR = "glsl"
CHECK_BATCHES = (1, 7, 4096)
TEXTURES = {
    "position": "xyz object-space position, w mask (>= 0.5 foreground)",
    "normal": "xyz object-space normal",
}


def bindings():
    return {POSITION: InputBinding("position", "xyz"), NORMAL: InputBinding("normal", "xyz")}


def encoding_description(model: FieldNet) -> str:
    if model.octaves == 0:
        return "none: features = [q, normal], q = (position - centre) * inv_half"
    return (
        f"axis-aligned positional encoding, {model.octaves} octaves: q = (position - centre) * inv_half, "
        f"z[3k+a] = q[a] * pi * 2^k (k < {model.octaves}), features = [q, normal, sin(z), cos(z)] "
        f"({model.features} floats)"
    )


def onnx_metadata(model: FieldNet, ckpt: dict | None = None) -> dict:
    ckpt = ckpt or {}
    metrics = ckpt.get("metrics", {})
    return {
        "neuralao_kind": "field",
        "input": f"{POSITION}: (N, 3) float32 object-space position in the mesh's units; "
        f"{NORMAL}: (N, 3) float32 viewer-facing object-space unit normal (the G-buffer's, "
        "flipped towards the camera on back faces)",
        "output": (
            "ao: (N, 1) float32 accessibility (1 open, 0 occluded), linear, NOT clamped: clamp to [0, 1]"
        ),
        "output_clamped": "false",
        "encoding": encoding_description(model),
        "octaves": str(model.octaves),
        "bounding_box_centre": model.centre.reshape(-1).tolist(),
        "bounding_box_inv_half_extent": model.inv_half.reshape(-1).tolist(),
        "model_size": size_name(model.hidden),
        "model_args": ckpt.get("model_args", {}),
        "parameters": str(count_parameters(model)),
        "parameter_bytes": str(parameter_bytes(model)),
        "parameter_bytes_note": (
            "float32: trainable weights + 6 normalisation constants + 3*octaves frequencies"
        ),
        "training_mesh": str(ckpt.get("mesh") or ""),
        "scene": str(ckpt.get("scene") or ""),
        "ao_labels": ckpt.get("samples", {}).get("labels", {}),
        "measured_error": {
            k: metrics.get(k)
            for k in ("val_rmse", "constant_val_rmse", "holdout_ssim", "holdout_rmse", "holdout_frames")
        },
        "measured_error_note": "val: surface samples held out; holdout_*: held-back orbit views, clamped, "
        "masked SSIM (Gaussian 11, sigma 1.5) and RMSE over valid foreground pixels",
    }


def onnx_bytes(model: FieldNet) -> bytes:
    model = model.eval().to(torch.float32)
    buf = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            model,
            (torch.zeros(2, 3), torch.zeros(2, 3)),
            buf,
            dynamo=False,
            opset_version=OPSET,
            input_names=[POSITION, NORMAL],
            output_names=[OUTPUT],
            dynamic_axes={POSITION: {0: "N"}, NORMAL: {0: "N"}, OUTPUT: {0: "N"}},
            do_constant_folding=True,
        )
    return buf.getvalue()


def random_inputs(model: FieldNet, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions uniform in the bounding box grown by 10%, unit normals."""
    rng = np.random.default_rng(seed)
    centre = model.centre.reshape(-1).numpy()
    half = 1.0 / model.inv_half.reshape(-1).numpy()
    p = (centre + rng.uniform(-1.1, 1.1, size=(n, 3)) * half).astype(np.float32)
    v = rng.standard_normal((n, 3))
    return p, (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


def check_backends(model: FieldNet, onnx_path: Path, seed: int = 0) -> dict:
    """onnxruntime vs torch on random inputs at CHECK_BATCHES; raises above TOL.onnx_vs_torch (the rule
    for these outputs and this depth)."""
    sess = ort_session(onnx_path)
    rows, ref_max = [], 0.0
    for k, n in enumerate(CHECK_BATCHES):
        p, nrm = random_inputs(model, n, seed + k)
        y = sess.run(None, {POSITION: p, NORMAL: nrm})[0]
        if y.shape != (n, 1):
            raise NeuralaoError(f"exported field returned shape {y.shape} for N={n}")
        ref = predict(model, p, nrm)
        ref_max = max(ref_max, float(np.abs(ref).max()))
        rows.append({"batch": n, "onnxruntime_vs_torch": float(np.abs(y[:, 0] - ref).max())})
    worst = max(r["onnxruntime_vs_torch"] for r in rows)
    tol = TOL.onnx_vs_torch(ref_max, weighted_layers(onnx_path))
    if worst > tol:
        raise NeuralaoError(f"onnxruntime differs from torch by {worst:.3g} > {tol:.3g}")
    return {
        "inputs": "positions in the bounding box grown by 10%, random unit normals",
        "checks": rows,
        "onnxruntime_vs_torch": worst,
        "tolerance": {"onnxruntime_vs_torch": tol},
        "opencv": "not checked: OpenCV dnn is the MLP's second consumer; the field's Sin/Cos graph is "
        "checked against torch and the generated GLSL",
    }


def write_glsl(proto: onnx.ModelProto, out_dir: Path, description: str) -> dict:
    shader = generate_vector_fragment(proto, bindings(), kind="field", description=description)
    for name, text in TEXTURES.items():
        shader.manifest["textures"][name]["semantics"] = text
    path = write_mlp_export(shader, out_dir)
    return json.loads(Path(path).read_text())


def export_checkpoint(ckpt_path: str | Path, out_dir: str | Path) -> dict:
    """model.onnx + glsl/ + manifest.json in ``out_dir`` from a field checkpoint. Returns the manifest."""
    t0 = time.perf_counter()
    ckpt_path, out_dir = Path(ckpt_path), Path(out_dir)
    ckpt = load_checkpoint(ckpt_path)
    model = model_from_checkpoint(ckpt)
    out_dir.mkdir(parents=True, exist_ok=True)
    onnx_path = out_dir / "model.onnx"
    metadata = onnx_metadata(model, ckpt)
    proto = onnx.load_from_string(onnx_bytes(model))
    save_onnx(proto, onnx_path, metadata)
    checks = check_backends(model, onnx_path)
    glsl_manifest = write_glsl(
        proto,
        out_dir / GLSL_DIR,
        f"neuralao AO field {size_name(model.hidden)} of {Path(str(ckpt.get('mesh') or '')).name}: "
        f"{encoding_description(model)}",
    )
    summary = glsl_summary_of(glsl_manifest)
    manifest = per_mesh_manifest(
        "field",
        out_dir,
        ckpt_path,
        ckpt,
        proto,
        GLSL_DIR,
        summary,
        ckpt.get("metrics", {}),
        t0,
        inputs=[
            {"name": POSITION, "shape": ["N", 3], "dtype": "float32", "texture": "position"},
            {"name": NORMAL, "shape": ["N", 3], "dtype": "float32", "texture": "normal"},
        ],
        output={"name": OUTPUT, "shape": ["N", 1], "dtype": "float32", "semantics": metadata["output"]},
        metadata=metadata,
        encoding=metadata["encoding"],
        octaves=model.octaves,
        model_size=size_name(model.hidden),
        parameters=count_parameters(model),
        parameter_bytes=parameter_bytes(model),
        checks=checks,
    )
    write_json(out_dir / "manifest.json", manifest)
    log.info(
        "exported %s: field %s, %d bytes, ort-vs-torch %.2g",
        out_dir,
        manifest["model_size"],
        manifest["parameter_bytes"],
        checks["onnxruntime_vs_torch"],
    )
    return manifest


# ----------------------------------------------------------------------------------------------- inference


def gbuffer_textures(frame: FrameLike) -> dict[str, np.ndarray]:
    """The shader's two RGBA32F inputs from a frame: position + mask, normal + 0."""
    p, n, mask = frame_inputs(frame)
    return {
        "position": np.concatenate([p, mask[..., None].astype(np.float32)], axis=-1),
        "normal": np.concatenate([n, np.zeros_like(n[..., :1])], axis=-1),
    }


# ----------------------------------------------------------------------------------------------- parity


def parity(export_dir, frames: list[FrameLike] | None = None, dialects: tuple[str, ...] = DIALECTS) -> dict:
    """Generated GLSL (from the export folder) vs onnxruntime on real G-buffer frames of the mesh.

    Raw outputs compared on every foreground pixel (gate TOL.parity_mlp_fp32); background must be
    exactly 1. No fp16 variant: half-float positions would move points by ~1e-3 of the box, which is
    a different input, not storage rounding. Returns figures with ``passed``."""
    export_dir = Path(export_dir)
    manifest, proto, glsl_dir = parity_export(export_dir, "field", "a field", check_field_onnx)
    frames, source = parity_frames(export_dir, manifest, frames)
    sess = ort_session(proto.SerializeToString())
    shaders = {d: load_mlp_export(glsl_dir, dialect=d) for d in dialects}
    rows = []
    for i, frame in enumerate(frames):
        _, _, mask = frame_inputs(frame)
        if not mask.any():
            continue
        ref = run_network(sess, frame)
        tex = gbuffer_textures(frame)
        for d in dialects:
            out = run_vector_fragment(shaders[d], tex, dialect=d)
            rows.append(
                {
                    "frame": i,
                    "dialect": d,
                    "size": [int(mask.shape[1]), int(mask.shape[0])],
                    **pixel_errors(out, ref, mask),
                }
            )
    if not rows:
        raise NeuralaoError("parity: no frame with foreground pixels to check")
    err = max(r["max_abs_err"] for r in rows)
    bg = max(r["background_max_abs_err"] for r in rows)
    return {
        "kind": "field",
        "model_size": manifest.get("model_size"),
        "frames": len(frames),
        "frame_source": source,
        "max_abs_err": err,
        **{f"max_abs_err_{d}": max(r["max_abs_err"] for r in rows if r["dialect"] == d) for d in dialects},
        "background_max_abs_err": bg,
        "tolerance": TOL.parity_mlp_fp32,
        "passed": bool(err <= TOL.parity_mlp_fp32 and bg == 0.0),
        "checks": rows,
    }
