"""Consumer-side ONNX plumbing: load and check a model file, read its metadata, run it with onnxruntime.

Metadata values are stored as strings in ``metadata_props`` (JSON for anything structured), so any
ONNX consumer can read what the model expects without neuralao; :mod:`neuralao.export.onnx_io` writes them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import onnxruntime as ort

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.manifest import parse_json


def get_metadata(model: onnx.ModelProto) -> dict[str, Any]:
    """``metadata_props`` as a dict, JSON values decoded (other strings kept as they are)."""
    out: dict[str, Any] = {}
    for p in model.metadata_props:
        try:
            out[p.key] = parse_json(p.value, f"ONNX metadata {p.key!r}", "value")
        except NeuralaoError as e:
            if "not valid JSON" not in str(e):
                raise  # too deep or too big: not a plain string either
            out[p.key] = p.value
        except ValueError:  # a number of more digits than Python converts: its text, for the reader to judge
            out[p.key] = p.value
    return out


def load_onnx(path: str | os.PathLike) -> onnx.ModelProto:
    """Load and check an ONNX file; a missing or corrupt file is a one-line error."""
    p = Path(path)
    if not p.is_file():
        raise NeuralaoError(f"ONNX file not found: {p}")
    try:
        model = onnx.load(str(p))
        onnx.checker.check_model(model)
    except Exception as e:
        raise NeuralaoError(
            f"cannot load ONNX file {p}: {str(e).splitlines()[0] if str(e) else type(e).__name__}"
        ) from None
    newest = onnx.defs.onnx_opset_version()
    for o in model.opset_import:
        if o.domain in ("", "ai.onnx") and o.version > newest:
            raise NeuralaoError(
                f"{p} declares ONNX opset {o.version}; this installation's ONNX knows opsets up to {newest}"
            )
    return model


def ort_session(path_or_bytes: str | os.PathLike | bytes) -> ort.InferenceSession:
    """A CPU onnxruntime session (2 threads, quiet) of a model file or serialized model."""
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 2
    opts.log_severity_level = 3
    src = path_or_bytes if isinstance(path_or_bytes, bytes) else str(path_or_bytes)
    try:
        return ort.InferenceSession(src, sess_options=opts, providers=["CPUExecutionProvider"])
    except Exception as e:
        raise NeuralaoError(f"onnxruntime cannot load the model: {str(e).splitlines()[0]}") from None


def run_onnxruntime(
    path_or_bytes: str | os.PathLike | bytes, inputs: dict[str, np.ndarray]
) -> list[np.ndarray]:
    """Run every output of the model on ``inputs`` (float32 arrays by input name)."""
    sess = ort_session(path_or_bytes)
    return sess.run(None, {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in inputs.items()})
