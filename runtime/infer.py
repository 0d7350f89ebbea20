"""`neuralao infer [MODEL.onnx] FRAME.npz --out AO.png [--radius R] [--composite OUT.png]`: apply an exported
model to a G-buffer. Without MODEL.onnx the shipped U-Net (``runtime/models``, see ``runtime.models``) is used.

The model's kind comes from its ONNX metadata (``neuralao_kind``); each kind's module provides
``infer_frame(onnx_path, frame) -> ao (H, W) float32`` (AO in [0, 1], 1 on background):

* ``mlp``:  :func:`export.mlp.infer_frame` (object-space normals, radius-zero input);
* ``unet``: :func:`export.unet.infer_frame` (depth + camera-space normals; the AO radius ``--radius``
  in scene units, by default the largest radius the frame's labels were traced at);
* ``field``: :func:`export.field.infer_frame` (object-space position + normal).

FRAME.npz is one frame as ``neuralao render`` writes it (``depth``, ``normal_cam``, ``normal_obj``,
``mask``, ...); a dataset shard (frames stacked on a first axis) works with ``--index K``.

The composite is what a person looks at: a plain material lit by a headlight (Lambert, from the
frame's camera-space normals) plus ambient, multiplied by the AO, over a light grey background.
"""

from __future__ import annotations

import argparse
import importlib
import logging
from pathlib import Path

import numpy as np

from pipeline.errors import NeuralaoError
from pipeline.io import read_npz, write_png

log = logging.getLogger(__name__)

# neuralao_kind -> module with infer_frame(onnx_path, frame)
INFERERS = {"mlp": "export.mlp", "unet": "export.unet", "field": "export.field"}
ALBEDO = np.array([0.82, 0.78, 0.72], dtype=np.float32)  # a light clay colour
BACKGROUND = np.array([0.93, 0.94, 0.96], dtype=np.float32)
LIGHT_CAM = np.array([-0.3, 0.4, 1.0]) / np.linalg.norm(
    [-0.3, 0.4, 1.0]
)  # headlight, slightly up-left (camera space)


def model_kind(onnx_path: str | Path) -> str:
    """``neuralao_kind`` from the ONNX metadata; missing or unknown -> one-line error."""
    from export.onnx_io import get_metadata, load_onnx

    kind = get_metadata(load_onnx(onnx_path)).get("neuralao_kind")
    if kind not in INFERERS:
        raise NeuralaoError(
            f"{onnx_path}: unknown model kind {kind!r} (ONNX metadata neuralao_kind must be one of {sorted(INFERERS)})"
        )
    return kind


def load_frame(path: str | Path, index: int | None = None) -> dict[str, np.ndarray]:
    """One frame dict from an .npz: a single frame, or frame ``index`` of stacked frames (a dataset shard)."""
    arrays = read_npz(path)
    if "mask" not in arrays and "normal_obj" not in arrays and "depth" not in arrays:
        raise NeuralaoError(f"{path} is not a G-buffer frame (no mask / normal_obj / depth arrays)")
    ref = arrays.get("mask", arrays.get("depth"))
    stacked = ref is not None and np.ndim(ref) == 3
    if stacked:
        n = int(np.shape(ref)[0])
        if index is None:
            if n != 1:
                raise NeuralaoError(f"{path} holds {n} frames; pick one with --index K (0..{n - 1})")
            index = 0
        if not 0 <= index < n:
            raise NeuralaoError(f"--index {index} is outside 0..{n - 1} for {path}")
        return {k: (v[index] if np.ndim(v) >= 1 and np.shape(v)[0] == n else v) for k, v in arrays.items()}
    if index not in (None, 0):
        raise NeuralaoError(f"{path} holds one frame; --index {index} is out of range")
    return arrays


def infer(onnx_path: str | Path, frame: dict, radius: float | None = None) -> np.ndarray:
    """AO (H, W) float32 of ``frame`` with the model's own inference function (by ONNX metadata kind);
    ``radius`` (scene units) goes to the models that take the AO radius as an input."""
    kind = model_kind(onnx_path)
    module = importlib.import_module(INFERERS[kind])
    if kind == "unet":
        ao = module.infer_frame(Path(onnx_path), frame, radius)
    elif radius is not None:
        raise NeuralaoError(f"--radius applies to U-Net models; {onnx_path} is a {kind} model (its radius is baked in)")
    else:
        ao = module.infer_frame(Path(onnx_path), frame)
    ao = np.asarray(ao, dtype=np.float32)
    if ao.ndim != 2:
        raise NeuralaoError(f"model returned AO of shape {ao.shape}, expected (H, W)")
    return ao


def shaded(frame: dict) -> tuple[np.ndarray, np.ndarray]:
    """Plain render of a frame: (H, W, 3) float32 Lambert headlight + ambient, and mask (H, W) bool.

    Uses normal_cam (camera space; OpenGL: the viewer is along +z) when present, else flat grey.
    """
    mask = _mask(frame)
    if "normal_cam" in frame and np.shape(frame["normal_cam"]) == (*mask.shape, 3):
        n = np.asarray(frame["normal_cam"], dtype=np.float64)
        lambert = np.clip(n @ LIGHT_CAM, 0.0, 1.0)
    else:
        lambert = np.full(mask.shape, 0.8)
    light = (0.35 + 0.65 * lambert)[..., None] * ALBEDO
    return np.where(mask[..., None], light, BACKGROUND).astype(np.float32), mask


def composite(frame: dict, ao: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1]: the shaded render multiplied by AO on the foreground."""
    base, mask = shaded(frame)
    ao = np.clip(np.asarray(ao, dtype=np.float32), 0.0, 1.0)
    return np.where(mask[..., None], base * ao[..., None], base).astype(np.float32)


def _mask(frame: dict) -> np.ndarray:
    if "mask" in frame:
        return np.asarray(frame["mask"], dtype=bool)
    if "tri_id" in frame:
        return np.asarray(frame["tri_id"]) >= 0
    if "depth" in frame:
        return np.asarray(frame["depth"]) > 0
    raise NeuralaoError("frame has no mask, tri_id or depth to tell foreground from background")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("inputs", nargs="+", metavar="[MODEL.onnx] FRAME.npz",
                   help="exported ONNX model (model.onnx of an export folder; default: the shipped U-Net) and a "
                   "G-buffer frame .npz (as `neuralao render` writes), or a dataset shard with --index")  # fmt: skip
    p.add_argument("--radius", type=float, help="AO radius in scene units (U-Net; default: the frame's label radius)")
    p.add_argument("--out", required=True, help="AO image to write (PNG, 8-bit grey, 1 = white = open)")
    p.add_argument("--composite", help="also write AO multiplied over a simple shaded render (PNG)")
    p.add_argument("--index", type=int, help="frame index inside a .npz of stacked frames (dataset shard)")


def run(args: argparse.Namespace) -> int:
    if len(args.inputs) > 2:
        raise NeuralaoError(f"expected [MODEL.onnx] FRAME.npz, got {len(args.inputs)} paths")
    if len(args.inputs) == 2:
        model, frame_path = args.inputs
    else:
        from .shipped import default_model

        model, frame_path = default_model("unet"), args.inputs[0]
        log.info("model: %s (shipped default)", model)
    frame = load_frame(frame_path, args.index)
    ao = infer(model, frame, args.radius)
    write_png(args.out, ao)
    if args.composite:
        write_png(args.composite, composite(frame, ao))
    fg = _mask(frame) if ao.shape == _mask(frame).shape else np.ones(ao.shape, bool)
    log.info("wrote %s (%dx%d, mean foreground AO %.3f)%s", args.out, ao.shape[1], ao.shape[0],
             float(ao[fg].mean()) if fg.any() else 1.0, f" and {args.composite}" if args.composite else "")  # fmt: skip
    return 0
