"""Apply an exported model to a G-buffer frame (the library side of ``neuralao infer``, whose command
line is :mod:`neuralao.pipeline.cli.infer`). Without a model the shipped U-Net (``runtime/models``, see
``runtime.models``) is used.

The model's kind comes from its ONNX metadata (``neuralao_kind``); :data:`neuralao.runtime.predict.PREDICTORS`
holds each kind's onnxruntime predictor, ``predict(frame, radius) -> ao (H, W) float32`` (AO in [0, 1],
1 on background):

* ``mlp``:  object-space normals, radius-zero input;
* ``unet``: depth + camera-space normals; the AO radius ``--radius`` in scene units, by default the
  largest radius the frame's labels were traced at;
* ``field``: object-space position + normal.

FRAME.npz is one frame as ``neuralao render`` writes it (``depth``, ``normal_cam``, ``normal_obj``,
``mask``, ``yfov`` in radians, ...) or as a user's exporter writes it from the keys docs/formats.md
lists (a U-Net needs ``depth`` and ``normal_cam``; ``mask`` defaults to ``depth > 0``; the field of view
comes from the frame or ``--yfov`` degrees / ``--yfov-rad``); a dataset shard (frames stacked on a first
axis) works with ``--index K``.

The composite is what a person looks at: a plain material lit by a headlight (Lambert, from the
frame's camera-space normals) plus ambient, multiplied by the AO, over a light grey background.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path, read_npz, write_exr, write_png
from neuralao.runtime.foundation.limits import check_finite_arrays
from neuralao.runtime.onnx_io import get_metadata, load_onnx
from neuralao.runtime.predict import PREDICTORS

log = logging.getLogger(__name__)

ALBEDO = np.array([0.82, 0.78, 0.72], dtype=np.float32)  # a light clay colour
BACKGROUND = np.array([0.93, 0.94, 0.96], dtype=np.float32)
LIGHT_CAM = np.array([-0.3, 0.4, 1.0]) / np.linalg.norm(
    [-0.3, 0.4, 1.0]
)  # headlight, slightly up-left (camera space)


def model_kind(onnx_path: str | Path) -> str:
    """``neuralao_kind`` from the ONNX metadata; missing or unknown -> one-line error."""
    kind = get_metadata(load_onnx(onnx_path)).get("neuralao_kind")
    if kind not in PREDICTORS:
        raise NeuralaoError(
            f"{onnx_path}: unknown model kind {kind!r} "
            f"(ONNX metadata neuralao_kind must be one of {sorted(PREDICTORS)})"
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


# G-buffer channels and their trailing shape after (H, W) (the frame format of pipeline/cli/render.py).
IMAGE_CHANNELS = {
    "depth": (),
    "mask": (),
    "tri_id": (),
    "ao": (),
    "valid": (),
    "normal_cam": (3,),
    "normal_obj": (3,),
    "position": (3,),
}


def complete_frame(frame: dict, kind: str, yfov: float | None, path: str | Path) -> dict:
    """The frame with what the command line supplies: ``yfov`` (radians; replaces the frame's, with a
    warning when they differ) and ``mask`` = ``depth > 0`` when the frame has none. A U-Net frame
    without a field of view is a one-line error naming ``--yfov``."""
    frame = dict(frame)
    if yfov is not None:
        if "yfov" in frame and not math.isclose(float(frame["yfov"]), yfov, rel_tol=1e-6):
            log.warning(
                "%s: using the given field of view %.4g deg, not the frame's %.4g deg",
                path,
                math.degrees(yfov),
                math.degrees(float(frame["yfov"])),
            )
        frame["yfov"] = yfov
    if "mask" not in frame and "depth" in frame and "tri_id" not in frame:
        frame["mask"] = np.asarray(frame["depth"]) > 0
    if kind == "unet" and "yfov" not in frame:
        raise NeuralaoError(
            f"{path} has no yfov: give the vertical field of view with --yfov DEG (or --yfov-rad RAD)"
        )
    return frame


def check_frame(frame: dict, path: str | Path) -> None:
    """Refuse a frame whose G-buffer channels disagree in shape, or whose floating channels hold NaN
    or inf (a model would turn them into finite-looking AO): one line naming the file and the channel."""
    shapes = {k: np.shape(v) for k, v in frame.items() if k in IMAGE_CHANNELS}
    full = [k for k in IMAGE_CHANNELS if k in shapes and len(shapes[k]) == 2 + len(IMAGE_CHANNELS[k])]
    ref = shapes[full[0]][:2] if full else None
    for k, shape in shapes.items():
        if ref is None or shape != (*ref, *IMAGE_CHANNELS[k]):
            want = "(H, W" + "".join(f", {n}" for n in IMAGE_CHANNELS[k]) + ")"
            raise NeuralaoError(
                f"{path}: G-buffer channel {k!r} has shape {shape}, expected {want}"
                + (f" with (H, W) = {ref}" if ref else "")
            )
    check_finite_arrays(frame, str(path), "G-buffer channel")


def infer(onnx_path: str | Path, frame: dict, radius: float | None = None) -> np.ndarray:
    """AO (H, W) float32 of ``frame`` with the model's own inference function (by ONNX metadata kind);
    ``radius`` (scene units) goes to the models that take the AO radius as an input."""
    kind = model_kind(onnx_path)
    if kind != "unet" and radius is not None:
        raise NeuralaoError(
            f"--radius applies to U-Net models; {onnx_path} is a {kind} model (its radius is baked in)"
        )
    ao = PREDICTORS[kind](Path(onnx_path))(frame, radius)
    ao = np.asarray(ao, dtype=np.float32)
    if ao.ndim != 2:
        raise NeuralaoError(f"model returned AO of shape {ao.shape}, expected (H, W)")
    if not np.isfinite(ao).all():
        bad = int((~np.isfinite(ao)).sum())
        raise NeuralaoError(f"{onnx_path}: the model's AO is not finite at {bad} pixel(s)")
    return ao


# Output formats by suffix: PNG (8-bit, clamped to [0, 1]), NumPy .npy and OpenEXR (float32 as computed).
OUTPUT_SUFFIXES = (".png", ".npy", ".exr")


def check_output(flag: str, path: str | Path) -> None:
    """``path`` must end in a supported suffix and not be a folder (checked before any work)."""
    p = Path(path)
    if p.suffix.lower() not in OUTPUT_SUFFIXES:
        raise NeuralaoError(f"{flag} {p.name!r}: unsupported format (use {', '.join(OUTPUT_SUFFIXES)})")
    if p.is_dir():
        raise NeuralaoError(f"{flag} {p} is a folder")


def write_image(path: str | Path, image: np.ndarray) -> None:
    """Write an (H, W) or (H, W, 3) float image in the format of ``path``'s suffix, atomically."""
    suffix = Path(path).suffix.lower()
    if suffix == ".png":
        write_png(path, image)
    elif suffix == ".exr":
        write_exr(path, image)
    else:
        with atomic_path(path) as tmp:
            np.save(tmp, np.asarray(image, dtype=np.float32))


def shaded(frame: dict) -> tuple[np.ndarray, np.ndarray]:
    """Plain render of a frame: (H, W, 3) float32 Lambert headlight + ambient, and mask (H, W) bool.

    Uses normal_cam (camera space; OpenGL: the viewer is along +z) when present, else flat grey.
    """
    mask = foreground(frame)
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


def foreground(frame: dict) -> np.ndarray:
    """(H, W) bool foreground of a frame: its mask, else tri_id >= 0, else depth > 0."""
    if "mask" in frame:
        return np.asarray(frame["mask"], dtype=bool)
    if "tri_id" in frame:
        return np.asarray(frame["tri_id"]) >= 0
    if "depth" in frame:
        return np.asarray(frame["depth"]) > 0
    raise NeuralaoError("frame has no mask, tri_id or depth to tell foreground from background")
