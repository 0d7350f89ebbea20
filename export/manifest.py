"""Export manifests (read by :func:`neuralao.runtime.foundation.manifest.read_manifest`): the settings every
checkpoint exporter shares (:data:`OPSET`, :data:`DIALECTS`), and the top-level
manifest of a per-mesh export (baked MLP, AO field): files, hashes and provenance.

Both exporters write ``OUT/model.onnx``, ``OUT/glsl/`` and then ``OUT/manifest.json``; the keys that
record where the export came from (checkpoint hash, config, metrics, exporter, ONNX ops) are the same
for every kind and are built here; each exporter adds what describes its own inputs.
"""

from __future__ import annotations

import time
from pathlib import Path

import onnx
import torch

from neuralao.runtime.foundation.io import sha256_file

OPSET = 17  # ONNX opset of every checkpoint export (torch.onnx.export(dynamo=False))
# GLSL dialects of the per-mesh fragment shaders that parity runs (the runner executes the ES 3.0
# sources on the desktop context).
DIALECTS = ("glsl330", "es300")


def glsl_summary_of(glsl_manifest: dict, **extra) -> dict:
    """The ``glsl_summary`` of a per-mesh manifest from its GLSL export's manifest: format, dialects and
    uniform bytes, then ``extra`` as given."""
    return {
        "format": glsl_manifest.get("format"),
        "dialects": sorted(glsl_manifest.get("dialects", {})),
        "uniform_bytes": glsl_manifest.get("uniform_bytes"),
        **extra,
    }


def per_mesh_manifest(
    kind: str,
    out_dir: Path,
    ckpt_path: Path,
    ckpt: dict,
    proto: onnx.ModelProto,
    glsl_dir: str,
    glsl_summary: dict,
    metrics: dict,
    t0: float,
    **fields,
) -> dict:
    """The manifest of ``out_dir`` (model.onnx, exported at :data:`OPSET`, and ``glsl_dir`` already
    written); ``fields`` go in as given, after the common keys and before the provenance ones.
    ``t0``: perf_counter at the start."""
    return {
        "kind": kind,
        "format_version": 1,
        "onnx": "model.onnx",
        "onnx_sha256": sha256_file(out_dir / "model.onnx"),
        "glsl": glsl_dir,
        "glsl_manifest_sha256": sha256_file(out_dir / glsl_dir / "manifest.json"),
        "glsl_summary": glsl_summary,
        "exporter": f"torch.onnx.export(dynamo=False, opset={OPSET}) torch {torch.__version__}",
        "ops": sorted({n.op_type for n in proto.graph.node}),
        **fields,
        "model_args": ckpt["model_args"],
        "scene": ckpt.get("scene"),
        "mesh": ckpt.get("mesh"),
        "checkpoint": {"path": str(ckpt_path), "sha256": sha256_file(ckpt_path)},
        "config": ckpt.get("config", {}),
        "metrics": metrics,
        "training_time_s": ckpt.get("training_time_s"),
        "seconds": time.perf_counter() - t0,
    }
