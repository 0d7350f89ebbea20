"""Export-side ONNX plumbing: atomic save with metadata, checker, backend gate, OpenCV dnn runner.

Metadata values are stored as strings in ``metadata_props`` (JSON for anything structured), so
any ONNX consumer can read what the model expects without neuralao. Loading, metadata reading and
onnxruntime sessions are the consumer's (:mod:`neuralao.runtime.onnx_io`), re-exported here for the exporters.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import onnx

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.onnx_io import get_metadata as get_metadata  # re-exported (the exporters' one import)
from neuralao.runtime.onnx_io import load_onnx as load_onnx
from neuralao.runtime.onnx_io import ort_session as ort_session
from neuralao.runtime.onnx_io import run_onnxruntime as run_onnxruntime


def set_metadata(model: onnx.ModelProto, metadata: dict[str, Any]) -> None:
    """Replace ``metadata_props`` with ``metadata`` (non-strings JSON-encoded)."""
    del model.metadata_props[:]
    for k, v in sorted(metadata.items()):
        p = model.metadata_props.add()
        p.key = k
        p.value = v if isinstance(v, str) else json.dumps(v, sort_keys=True)


def save_onnx(
    model: onnx.ModelProto, path: str | os.PathLike, metadata: dict[str, Any] | None = None
) -> Path:
    """Check the model with ``onnx.checker`` (full check) and write it atomically."""
    if metadata is not None:
        set_metadata(model, metadata)
    try:
        onnx.checker.check_model(model, full_check=True)
    except onnx.checker.ValidationError as e:
        raise NeuralaoError(f"ONNX checker rejected the model: {str(e).splitlines()[0]}") from None
    path = Path(path)
    with atomic_path(path) as tmp:
        onnx.save(model, str(tmp))
    return path


# Ops whose outputs are long float32 sums (dot products over a fan-in): where rounding accumulates.
WEIGHTED_OPS = ("Conv", "ConvTranspose", "Gemm", "MatMul")


def weighted_layers(model: onnx.ModelProto | str | os.PathLike) -> int:
    """How many Conv / ConvTranspose / Gemm / MatMul nodes the graph has: the depth of the tolerance
    rule TOL.onnx_vs_torch (a count, so an upper bound on the longest chain of them)."""
    proto = model if isinstance(model, onnx.ModelProto) else onnx.load(str(model))
    return sum(n.op_type in WEIGHTED_OPS for n in proto.graph.node)


def backend_checks(rows: list[dict], ref_max: float, onnx_path: str | os.PathLike, **describe: Any) -> dict:
    """The export gate of a family's ``check_backends``: ``rows`` of per-input differences
    (``onnxruntime_vs_torch``, ``opencv_vs_onnxruntime``) -> the result dict (``describe`` entries, worst of
    each, their tolerances: TOL.onnx_vs_torch for ``ref_max`` and the graph's depth, TOL.opencv_vs_onnx);
    either difference over its tolerance is a one-line error."""
    result = {
        **describe,
        "onnxruntime_vs_torch": max(r["onnxruntime_vs_torch"] for r in rows),
        "opencv_vs_onnxruntime": max(r["opencv_vs_onnxruntime"] for r in rows),
        "tolerance": {
            "onnxruntime_vs_torch": TOL.onnx_vs_torch(ref_max, weighted_layers(onnx_path)),
            "opencv_vs_onnxruntime": TOL.opencv_vs_onnx,
        },
    }
    if result["onnxruntime_vs_torch"] > result["tolerance"]["onnxruntime_vs_torch"]:
        raise NeuralaoError(
            f"onnxruntime differs from torch by {result['onnxruntime_vs_torch']:.3g} > "
            f"{result['tolerance']['onnxruntime_vs_torch']:.3g}"
        )
    if result["opencv_vs_onnxruntime"] > TOL.opencv_vs_onnx:
        raise NeuralaoError(
            f"OpenCV dnn differs from onnxruntime by {result['opencv_vs_onnxruntime']:.3g} > "
            f"{TOL.opencv_vs_onnx:g}"
        )
    return result


def run_opencv(path: str | os.PathLike, inputs: dict[str, np.ndarray]) -> np.ndarray:
    """Second consumer: OpenCV's dnn module (its own importer and kernels). Returns the first output."""
    try:
        net = cv2.dnn.readNetFromONNX(str(path))
    except cv2.error as e:
        raise NeuralaoError(f"OpenCV dnn cannot import {path}: {str(e).strip().splitlines()[-1]}") from None
    net.setPreferableBackend(cv2.dnn.DNN_BACKEND_OPENCV)
    net.setPreferableTarget(cv2.dnn.DNN_TARGET_CPU)
    for name, arr in inputs.items():
        net.setInput(np.ascontiguousarray(arr, dtype=np.float32), name)
    return np.asarray(net.forward(), dtype=np.float32)
