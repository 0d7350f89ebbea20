"""Apply an exported model to a G-buffer frame (the library side of ``neuralao infer``, whose command
line is :mod:`neuralao.pipeline.cli.infer`). Without a model the shipped U-Net (``runtime/models``, see
``runtime.models``) is used.

The model's kind comes from its ONNX metadata (``neuralao_kind``); its entry in :mod:`neuralao.runtime.kinds`
names its onnxruntime predictor, ``predict(frame, radius) -> ao (H, W) float32`` (AO in [0, 1],
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

from neuralao.runtime import kinds
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path, write_exr, write_png
from neuralao.runtime.frame import Frame, FrameLike, check_scene_length
from neuralao.runtime.onnx_io import get_metadata, load_onnx
from neuralao.runtime.predict import check_unet_frame
from neuralao.runtime.shipped import export_model

log = logging.getLogger(__name__)

ALBEDO = np.array([0.82, 0.78, 0.72], dtype=np.float32)  # a light clay colour
BACKGROUND = np.array([0.93, 0.94, 0.96], dtype=np.float32)
LIGHT_CAM = np.array([-0.3, 0.4, 1.0]) / np.linalg.norm(
    [-0.3, 0.4, 1.0]
)  # headlight, slightly up-left (camera space)


def model_file(path: str | Path) -> Path:
    """The ONNX file a model argument names: the file itself, or an export folder's model (the file its
    manifest names, see :func:`neuralao.runtime.shipped.export_model`)."""
    path = Path(path)
    return export_model(path) if path.is_dir() else path


def model_kind(onnx_path: str | Path) -> str:
    """``neuralao_kind`` from the ONNX metadata; missing or unknown -> one-line error."""
    kind = get_metadata(load_onnx(onnx_path)).get("neuralao_kind")
    if kind not in kinds.predicted():
        raise NeuralaoError(
            f"{onnx_path}: unknown model kind {kind!r} "
            f"(ONNX metadata neuralao_kind must be one of {sorted(kinds.predicted())})"
        )
    return kind


def complete_frame(frame: Frame, kind: str, yfov: float | None, path: str | Path) -> Frame:
    """The frame with what the command line supplies: ``yfov`` (radians; replaces the frame's, with a
    warning when they differ) and ``mask`` = ``depth > 0`` when the frame has none. A U-Net frame
    without a field of view is a one-line error naming ``--yfov``."""
    changes: dict = {}
    if yfov is not None:
        if frame.yfov is not None and not math.isclose(frame.yfov, yfov, rel_tol=1e-6):
            log.warning(
                "%s: using the given field of view %.4g deg, not the frame's %.4g deg",
                path,
                math.degrees(yfov),
                math.degrees(frame.yfov),
            )
        changes["yfov"] = yfov
    if frame.mask is None and frame.depth is not None and frame.tri_id is None:
        changes["mask"] = np.asarray(frame.depth) > 0
    if kind == "unet" and frame.yfov is None and yfov is None:
        raise NeuralaoError(
            f"{path} has no yfov: give the vertical field of view with --yfov DEG (or --yfov-rad RAD)"
        )
    frame = frame.replace(**changes) if changes else frame
    if kind == "unet":
        check_unet_frame(frame, path)
    return frame


# The most pixels an AO radius may span on screen (at the nearest foreground pixel). Screen-space passes
# (a hybrid U-Net's GTAO) step along the screen in float32 up to the radius in pixels; once it spans
# about 1e5 screen heights every step but the first lies off screen and the AO stops changing, and past
# 1e11 .. 1e13 pixels (measured at 48 to 768 rows) the steps lose their precision and the AO changes
# again. The bound lies between, 100 times below the loss: a larger radius could change nothing but precision.
MAX_RADIUS_PIXELS = 1e9


def check_radius(name: str, radius: float, frame: FrameLike) -> float:
    """``radius`` (scene units) within the depths' range (:func:`check_scene_length`) and spanning at most
    :data:`MAX_RADIUS_PIXELS` pixels at the frame's nearest foreground pixel (when the frame has depth,
    mask and yfov); one line naming ``name`` otherwise."""
    check_scene_length(name, radius)
    if not all(k in frame for k in ("depth", "mask", "yfov")):
        return radius
    depth = np.asarray(frame["depth"], np.float64)[np.asarray(frame["mask"], bool)]
    if depth.size == 0:
        return radius
    nearest = float(depth.min())
    per_unit = 0.5 * np.shape(frame["depth"])[0] / math.tan(0.5 * float(frame["yfov"]))  # as GTAO's
    pixels = radius * per_unit / nearest
    if pixels > MAX_RADIUS_PIXELS:
        raise NeuralaoError(
            f"{name} {radius:.6g} spans {pixels:.3g} pixels at the nearest foreground depth {nearest:.3g}, "
            f"past the {MAX_RADIUS_PIXELS:g} up to which screen-space AO is exact; give at most "
            f"{MAX_RADIUS_PIXELS * nearest / per_unit:.3g} for this frame (already far past its screen)"
        )
    return radius


def infer(onnx_path: str | Path, frame: FrameLike, radius: float | None = None) -> np.ndarray:
    """AO (H, W) float32 of ``frame`` with the model's own inference function (by ONNX metadata kind);
    ``radius`` (scene units) goes to the models that take the AO radius as an input."""
    kind = model_kind(onnx_path)
    if not kinds.KINDS[kind].radius_input and radius is not None:
        raise NeuralaoError(
            f"--radius applies to U-Net models; {onnx_path} is a {kind} model (its radius is baked in)"
        )
    if kinds.KINDS[kind].radius_input:
        if radius is not None:
            check_radius("--radius", float(radius), frame)
        elif "radii" in frame and np.size(frame["radii"]):
            check_radius("the frame's label radius ('radii')", float(np.max(frame["radii"])), frame)
    ao = kinds.role(kind, "predictor")(Path(onnx_path))(frame, radius)
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


def shaded(frame: FrameLike) -> tuple[np.ndarray, np.ndarray]:
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


def composite(frame: FrameLike, ao: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1]: the shaded render multiplied by AO on the foreground."""
    base, mask = shaded(frame)
    ao = np.clip(np.asarray(ao, dtype=np.float32), 0.0, 1.0)
    return np.where(mask[..., None], base * ao[..., None], base).astype(np.float32)


def foreground(frame: FrameLike) -> np.ndarray:
    """(H, W) bool foreground of a frame: its mask, else tri_id >= 0, else depth > 0."""
    if "mask" in frame:
        return np.asarray(frame["mask"], dtype=bool)
    if "tri_id" in frame:
        return np.asarray(frame["tri_id"]) >= 0
    if "depth" in frame:
        return np.asarray(frame["depth"]) > 0
    raise NeuralaoError("frame has no mask, tri_id or depth to tell foreground from background")
