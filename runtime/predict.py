"""onnxruntime inference of an exported model on one G-buffer frame: one predictor per family.

Each family's predictor (named by its kind's ``predictor`` in :mod:`neuralao.runtime.kinds`), given the
ONNX path, loads and checks the export once and returns a :class:`Predictor`,
``predict(frame, radius) -> ao (H, W) float32`` in [0, 1], 1 on background:

* ``unet``:  depth + camera-space normals and the AO radius in scene units (None: the largest radius
  the frame's labels were traced at); runs at the export's declared internal height;
* ``mlp``:   object-space normals at radius zero (its radius is baked in; ``radius`` must be None);
* ``field``: object-space position + normal (radius baked in; ``radius`` must be None).

This is the ONE copy of each family's onnxruntime inference: ``neuralao infer``, the exporters'
checks and the evaluation all call it (through :mod:`neuralao.export.unet`, :mod:`neuralao.export.mlp`,
:mod:`neuralao.export.field`, which re-export these names).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import numpy as np
import onnx

from neuralao.runtime.baselines import hybrid_gtao
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import PIXEL_BYTES, available_memory, format_bytes
from neuralao.runtime.foundation.manifest import read_manifest
from neuralao.runtime.foundation.metadata import (
    metadata_internal_height,
    metadata_pad_mode,
    metadata_pad_multiple,
)
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.internal_resolution import at_internal_resolution, internal_size
from neuralao.runtime.onnx_io import get_metadata, load_onnx, ort_session
from neuralao.runtime.unet_input import (
    RADIUS_INPUT,
    check_version,
    frame_radius,
    frame_radius_param,
    hybrid_gtao_blur,
    pad_to_multiple,
    preprocess_frame,
    scales_up,
)


class Predictor(Protocol):
    def __call__(self, frame: FrameLike, radius: float | None = None) -> np.ndarray:
        """AO (H, W) float32 in [0, 1] (1 on background) of one G-buffer frame."""
        ...


def _clamped(raw: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Network output (H, W) clamped to [0, 1] on ``mask``, 1 elsewhere (and where NaN)."""
    return np.where(mask, np.clip(np.nan_to_num(raw, nan=1.0), 0.0, 1.0), 1.0).astype(np.float32)


def _baked_radius(kind: str, radius: float | None) -> None:
    if radius is not None:
        raise NeuralaoError(f"a {kind} model has its AO radius baked in; it takes no radius")


# ----------------------------------------------------------------------------------------------- U-Net

# ONNX input names of an exported U-Net: the (1, C, H, W) G-buffer input and the (1, 1, 1, 1) radius.
UNET_INPUT, UNET_RADIUS = "gbuffer", RADIUS_INPUT

# ``run(x (1, C, H', W') float32, rho) -> y (1, 1, H', W')``: one backend's forward pass.
Runner = Callable[[np.ndarray, float], np.ndarray]


def radius_array(rho: float) -> np.ndarray:
    """The radius input (1, 1, 1, 1) float32 of the exported graph."""
    return np.full((1, 1, 1, 1), rho, dtype=np.float32)


def run_padded(fn: Runner, x: np.ndarray, pad_multiple: int, rho: float) -> np.ndarray:
    """Pad x (4, H, W) float32 (reflect, bottom/right), run ``fn(x (1, 4, H', W'), rho)``,
    crop -> (H, W) float32."""
    h, w = x.shape[-2:]
    y = np.asarray(fn(pad_to_multiple(x, pad_multiple)[None], float(rho)), dtype=np.float32)
    return y.reshape(y.shape[-2:])[:h, :w]


def ort_runner(path_or_bytes) -> Runner:
    """A :data:`Runner` of a U-Net ONNX file or serialized model with onnxruntime."""
    sess = ort_session(path_or_bytes)
    return lambda xp, rho: sess.run(
        None, {UNET_INPUT: np.ascontiguousarray(xp, dtype=np.float32), UNET_RADIUS: radius_array(rho)}
    )[0]


def composite(y: np.ndarray, frame: FrameLike) -> np.ndarray:
    """Network output (H, W) -> AO (H, W) float32 with background 1 (DESIGN: ao = 1 where nothing is hit)."""
    return np.where(np.asarray(frame["mask"], dtype=bool), y, np.float32(1.0)).astype(np.float32)


def check_unet_onnx(proto: onnx.ModelProto, where: str | Path) -> dict:
    """Metadata of a U-Net ONNX file, its padding contract checked (``pad_multiple`` an int, the ONE check
    `neuralao glsl` makes too, and ``pad_mode`` the padding this consumer does); another kind, another
    preprocessing version or a broken contract is a one-line error naming the file and the key."""
    meta = get_metadata(proto)
    if meta.get("neuralao_kind") != "unet":
        raise NeuralaoError(
            f"{where} is not a neuralao U-Net ONNX file (neuralao_kind {meta.get('neuralao_kind')!r})"
        )
    check_version(meta.get("preprocess_version"), str(where))
    text = raw_metadata(proto)  # numbers as the file spells them (JSON would show "1e3" as 1000.0)
    meta["pad_multiple"] = metadata_pad_multiple(text, str(where), needed="says how to pad the input")
    metadata_pad_mode(meta, str(where))
    return meta


def raw_metadata(proto: onnx.ModelProto) -> dict[str, str]:
    """``metadata_props`` as the file stores them (text, nothing decoded)."""
    return {p.key: p.value for p in proto.metadata_props}


def declared_internal_height(onnx_path: str | Path, proto: onnx.ModelProto | None = None) -> int | None:
    """The internal height a U-Net export declares: ONNX metadata ``internal_height``, else the
    ``internal_height`` of the manifest.json beside it; None (run at the frame's size) when neither."""
    height = metadata_internal_height(raw_metadata(proto or load_onnx(onnx_path)), str(onnx_path))
    folder = Path(onnx_path).parent
    if height is None and (folder / "manifest.json").is_file():
        height = metadata_internal_height(read_manifest(folder), str(folder / "manifest.json"))
    return height


def is_hybrid(meta: dict) -> bool:
    """True for a U-Net that refines GTAO (its input channels end with ``gtao``)."""
    return str(meta.get("input_channels", "")).split(",")[-1] == "gtao"


def reads_gtao_raw(meta: dict) -> bool:
    """True for a hybrid that also reads GTAO's pass before its blur (a ``gtao_raw`` channel)."""
    return "gtao_raw" in str(meta.get("input_channels", "")).split(",")


def unet_predictor(onnx_path: str | Path, internal_height: int | str | None = "model") -> Predictor:
    """``predict(frame, radius) -> ao (H, W) float32`` of a U-Net export with onnxruntime.

    frame: depth (H,W), normal_cam (H,W,3), mask (H,W), yfov; radius in scene units (None: the largest
    radius the frame's labels have). ``internal_height``: "model" (the height the export declares, see
    :func:`declared_internal_height`), None (the frame's own size) or a number of rows; frames taller
    than it are point-sampled down and the AO upsampled (:mod:`neuralao.runtime.internal_resolution`). A
    hybrid gets GTAO at the same radius (neuralao.runtime.baselines, at the frame's resolution) as its fifth
    channel, and at an internal resolution its correction to GTAO is what is upsampled.
    """
    proto = load_onnx(onnx_path)
    meta = check_unet_onnx(proto, onnx_path)
    if internal_height == "model":
        internal_height = declared_internal_height(onnx_path, proto)
    run = ort_runner(proto.SerializeToString())
    multiple = meta["pad_multiple"]
    hybrid = is_hybrid(meta)
    blur = hybrid_gtao_blur(meta, str(onnx_path))  # the GTAO the hybrid was trained on
    version = int(meta["preprocess_version"])

    raw = hybrid and reads_gtao_raw(meta)

    def predict(f: dict, r: float | None) -> np.ndarray:
        x = preprocess_frame(f, f["gtao"] if hybrid else None, version, f["gtao_raw"] if raw else None)
        return composite(run_padded(run, x, multiple, frame_radius_param(f, r, version)), f)

    up = scales_up(version)
    scaled = at_internal_resolution(predict, internal_height, residual_of="gtao" if hybrid else None, up=up)

    def predict_frame(frame: FrameLike, radius: float | None = None, gtao: dict | None = None) -> np.ndarray:
        """``gtao``: a hybrid's GTAO images at the frame's size (``gtao``, and ``gtao_raw`` where it reads
        the pass before the blur) made elsewhere, an engine's, instead of this runtime's GTAO."""
        check_unet_frame(frame)
        check_network_size(np.shape(frame["depth"]), internal_height, onnx_path, up)
        if not hybrid:
            return scaled(frame, radius)
        if gtao is None:
            gtao = hybrid_gtao(frame, frame_radius(frame, radius), blur, raw)
        else:  # an engine's images: the ones this model reads, at the frame's size
            needed = ("gtao", "gtao_raw") if raw else ("gtao",)
            if sorted(gtao) != sorted(needed) or any(
                np.shape(gtao[k]) != np.shape(frame["depth"]) for k in needed
            ):
                raise NeuralaoError(
                    f"{onnx_path} reads GTAO images {', '.join(needed)}, each of the frame's size"
                )
        return scaled(dict(frame) | gtao, radius)

    return predict_frame


# The G-buffer channels a U-Net reads (``yfov`` too, checked where the radius is made).
UNET_CHANNELS = ("depth", "normal_cam", "mask")


def check_unet_frame(frame: FrameLike, where: str | Path = "frame") -> None:
    """Refuse a frame that lacks a channel the U-Net reads: one line naming ``where`` and the channel."""
    for key in UNET_CHANNELS:
        if key not in frame:
            raise NeuralaoError(
                f"{where} has no {key!r} channel, which the U-Net reads ({', '.join(UNET_CHANNELS)})"
            )


def check_network_size(
    shape: tuple[int, ...], internal_height: int | None, where: str | Path, up: bool = True
) -> None:
    """Refuse a frame of ``shape`` (H, W) whose network input (at the model's ``internal_height`` rows,
    the frame's aspect kept: a strip one row tall becomes as wide as it is scaled tall) this machine
    cannot hold, before anything is allocated."""
    h, w = shape[:2]
    lw, lh = internal_size(w, h, internal_height, up)
    need, avail = lw * lh * PIXEL_BYTES, available_memory()
    if need > avail:
        at = f"internal_height {internal_height}, the frame's aspect kept" if internal_height else "its size"
        raise NeuralaoError(
            f"a {w}x{h} frame runs {Path(where).name} at {lw}x{lh} pixels ({at}): about "
            f"{format_bytes(need)}, more than the {format_bytes(avail)} of memory available"
        )


def unet_infer_frame(
    onnx_path: str | Path,
    frame: FrameLike,
    radius: float | None = None,
    internal_height: int | str | None = "model",
) -> np.ndarray:
    """AO (H, W) float32 in [0, 1] (1 on background) of one G-buffer frame: :func:`unet_predictor`."""
    return unet_predictor(onnx_path, internal_height)(frame, radius)


# ----------------------------------------------------------------------------------------------- MLP

MLP_INPUT = "normals"  # ONNX input name: (N, MLP_INPUTS) float32
CIRCLE_SAMPLES = 16  # normals per input (paper: 16)
MLP_INPUTS = 3 * CIRCLE_SAMPLES  # 48 floats, xyz interleaved


def radius_zero_inputs(normals: np.ndarray, count: int = CIRCLE_SAMPLES) -> np.ndarray:
    """Deployed input: each (n, 3) normal repeated ``count`` times -> (n, 3 * count) float32."""
    return np.ascontiguousarray(np.tile(np.asarray(normals, dtype=np.float32), (1, count)))


def check_mlp_onnx(proto: onnx.ModelProto, where: str | Path) -> dict:
    """Metadata of an MLP ONNX file; another kind or another input layout is a one-line error."""
    meta = get_metadata(proto)
    if meta.get("neuralao_kind") != "mlp":
        raise NeuralaoError(
            f"{where} is not a neuralao MLP ONNX file (neuralao_kind {meta.get('neuralao_kind')!r})"
        )
    inputs = [i for i in proto.graph.input if i.name not in {t.name for t in proto.graph.initializer}]
    dims = (
        [d.dim_value or d.dim_param for d in inputs[0].type.tensor_type.shape.dim] if len(inputs) == 1 else []
    )
    if len(inputs) != 1 or inputs[0].name != MLP_INPUT or len(dims) != 2 or dims[1] != MLP_INPUTS:
        raise NeuralaoError(
            f"{where}: expected one input {MLP_INPUT!r} of shape (N, {MLP_INPUTS}), "
            f"found {[i.name for i in inputs]} {dims}"
        )
    return meta


def frame_normals(frame: FrameLike) -> tuple[np.ndarray, np.ndarray]:
    """normal_obj (H, W, 3) float32 and mask (H, W) bool of a frame; one-line errors for wrong shapes."""
    if "normal_obj" not in frame:
        raise NeuralaoError("frame has no 'normal_obj' channel (object-space normals), which the MLP reads")
    n = np.asarray(frame["normal_obj"], dtype=np.float32)
    if n.ndim != 3 or n.shape[2] != 3:
        raise NeuralaoError(f"frame normal_obj must be (H, W, 3), got {n.shape}")
    if "mask" in frame:
        mask = np.asarray(frame["mask"], dtype=bool)
    elif "tri_id" in frame:
        mask = np.asarray(frame["tri_id"]) >= 0
    else:
        mask = np.abs(n).sum(axis=-1) > 0  # background normals are 0 by the frame convention
    if mask.shape != n.shape[:2]:
        raise NeuralaoError(f"frame mask {mask.shape} does not match normal_obj {n.shape}")
    return n, mask


def run_mlp(sess, normal_obj: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Raw (unclamped) MLP output at radius zero: (H, W) float32, NaN on background."""
    out = np.full(mask.shape, np.nan, dtype=np.float32)
    if mask.any():
        out[mask] = sess.run(None, {MLP_INPUT: radius_zero_inputs(normal_obj[mask])})[0][:, 0]
    return out


def mlp_predictor(onnx_path: str | Path) -> Predictor:
    """``predict(frame) -> ao`` of an MLP export with onnxruntime (radius-zero input, as deployed).

    frame : normal_obj (H, W, 3) and mask (H, W) (or tri_id).
    """
    proto = load_onnx(onnx_path)
    check_mlp_onnx(proto, onnx_path)
    sess = ort_session(proto.SerializeToString())

    def predict(frame: FrameLike, radius: float | None = None) -> np.ndarray:
        _baked_radius("MLP", radius)
        normal_obj, mask = frame_normals(frame)
        return _clamped(run_mlp(sess, normal_obj, mask), mask)

    return predict


def mlp_infer_frame(onnx_path: str | Path, frame: FrameLike) -> np.ndarray:
    """AO (H, W) float32 of one G-buffer frame: :func:`mlp_predictor`."""
    return mlp_predictor(onnx_path)(frame)


# ----------------------------------------------------------------------------------------------- field

# ONNX input names of an exported field: (N, 3) float32 object-space position and normal.
FIELD_POSITION, FIELD_NORMAL = "position", "normal"


def check_field_onnx(proto: onnx.ModelProto, where) -> dict:
    meta = get_metadata(proto)
    if meta.get("neuralao_kind") != "field":
        raise NeuralaoError(
            f"{where} is not a neuralao field ONNX file (neuralao_kind {meta.get('neuralao_kind')!r})"
        )
    names = sorted(
        i.name for i in proto.graph.input if i.name not in {t.name for t in proto.graph.initializer}
    )
    if names != sorted([FIELD_POSITION, FIELD_NORMAL]):
        raise NeuralaoError(
            f"{where}: expected inputs {FIELD_POSITION!r} and {FIELD_NORMAL!r}, found {names}"
        )
    return meta


def frame_inputs(frame: FrameLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """position (H, W, 3), normal_obj (H, W, 3) float32 and mask (H, W) bool; one-line errors."""
    for key in ("position", "normal_obj"):
        if key not in frame:
            raise NeuralaoError(f"frame has no {key!r} channel, which the field reads")
    p = np.asarray(frame["position"], np.float32)
    n = np.asarray(frame["normal_obj"], np.float32)
    if p.ndim != 3 or p.shape[2] != 3 or n.shape != p.shape:
        raise NeuralaoError(f"frame position / normal_obj must both be (H, W, 3), got {p.shape}, {n.shape}")
    mask = np.asarray(frame["mask"], bool) if "mask" in frame else np.abs(n).sum(axis=-1) > 0
    if mask.shape != p.shape[:2]:
        raise NeuralaoError(f"frame mask {mask.shape} does not match position {p.shape}")
    return p, n, mask


def run_field(sess, frame: FrameLike) -> np.ndarray:
    """Raw field output (H, W) float32 through onnxruntime, NaN on background."""
    p, n, mask = frame_inputs(frame)
    out = np.full(mask.shape, np.nan, np.float32)
    if mask.any():
        out[mask] = sess.run(None, {FIELD_POSITION: p[mask], FIELD_NORMAL: n[mask]})[0][:, 0]
    return out


def field_predictor(onnx_path: str | Path) -> Predictor:
    """``predict(frame) -> ao`` of a field export with onnxruntime: position + normal_obj (+ mask)."""
    proto = load_onnx(onnx_path)
    check_field_onnx(proto, onnx_path)
    sess = ort_session(proto.SerializeToString())

    def predict(frame: FrameLike, radius: float | None = None) -> np.ndarray:
        _baked_radius("field", radius)
        raw = run_field(sess, frame)
        return _clamped(raw, ~np.isnan(raw))

    return predict


def field_infer_frame(onnx_path: str | Path, frame: FrameLike) -> np.ndarray:
    """AO (H, W) float32 of one G-buffer frame: :func:`field_predictor`."""
    return field_predictor(onnx_path)(frame)
