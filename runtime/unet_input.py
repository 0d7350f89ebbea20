"""The U-Net's input contract, numpy only: G-buffer preprocessing, the radius input, reflect padding.

    x : (4, H, W) float32, channels [depth, n_x, n_y, n_z]
        depth    linear camera-space depth (-z_cam) divided by the frame's MEAN foreground depth
                 (scene-scale invariant); 0 on background.
        n_x..z   camera-space unit normal, OpenGL convention (x right, y up, z towards the viewer),
                 flipped to face the viewer; 0 on background.
    radius   rho = R / (mean foreground depth * tan(yfov / 2)), (1, 1, 1, 1) float32.

The ONE preprocessing that training, export checks, parity and inference use (see
:mod:`neuralao.pipeline.models.unet` for the reasons behind it and the model); a consumer runs it without
torch. The ONNX graph needs H and W multiples of ``pad_multiple``: the consumer reflect-pads bottom/right
(:func:`pad_to_multiple`) and crops the output back.
"""

from __future__ import annotations

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.frame import FrameLike

# Bumped whenever ``preprocess`` changes meaning; exported models record it and ``infer`` checks it.
PREPROCESS_VERSION = 2
# The radius channel (see the module docstring): a floor on normalised depth and a cap on the value.
RADIUS_DEPTH_FLOOR = 1e-3
RADIUS_CAP = 8.0
RADIUS_INPUT = "radius"
INPUT_CHANNELS = ("depth", "normal_cam_x", "normal_cam_y", "normal_cam_z")
# The hybrid's input: the G-buffer channels and GTAO's AO at the same radius (1 on background).
HYBRID_CHANNELS = (*INPUT_CHANNELS, "gtao")
BACKGROUND_DEPTH = 0.0
PAD_MODE = "reflect"

# Written verbatim into the ONNX metadata and the export manifest (input semantics, units).
PREPROCESS_DESCRIPTION = {
    "preprocess_version": str(PREPROCESS_VERSION),
    "input_name": "gbuffer",
    "input_layout": "NCHW float32, N=1, C=4, H and W multiples of pad_multiple (pad, run, crop)",
    "input_channels": ",".join(INPUT_CHANNELS),
    "depth_units": "linear camera-space depth (-z_cam) divided by the mean depth over foreground pixels "
    "of the whole frame (dimensionless, scene-scale invariant)",
    "depth_normalisation": "depth / mean(depth[mask]); background 0",
    "normal_space": "camera space, OpenGL convention (x right, y up, z towards the viewer), unit length, "
    "flipped to face the viewer",
    "mask_convention": "foreground = depth > 0 (the G-buffer mask); background pixels have depth 0 and "
    "normal (0,0,0) in the input and AO 1 in the output (the network's value there is overwritten)",
    "radius_input": f"{RADIUS_INPUT}: (1,1,1,1) float32 rho = R / (mean foreground depth * tan(yfov/2)), "
    "R = AO radius in scene units (the distance beyond which nothing occludes); the graph feeds the network "
    f"clip(rho / max(depth, {RADIUS_DEPTH_FLOOR:g}), 0, {RADIUS_CAP:g}) as a fifth channel",
    "radius_glsl": "uniform float u_radius (the same rho), set per frame",
    "output_name": "ao",
    "output": "(1,1,H,W) accessibility in [0,1], 1 = open (sigmoid)",
    "pad_mode": PAD_MODE,
    "pad_side": "bottom,right",
}

# Added to the metadata of a hybrid (GTAO-input) U-Net.
HYBRID_DESCRIPTION = {
    "input_layout": "NCHW float32, N=1, C=5, H and W multiples of pad_multiple (pad, run, crop)",
    "input_channels": ",".join(HYBRID_CHANNELS),
    "gtao_channel": "channel 4: GTAO's AO at the same radius R (the engine's GTAO pass, run first), 1 on "
    "background; the network outputs clip(gtao + correction, 0, 1)",
    "output": "(1,1,H,W) accessibility in [0,1], 1 = open (GTAO + a learned correction, clipped)",
}


def depth_scale(depth: np.ndarray, mask: np.ndarray) -> float:
    """Mean foreground depth of a frame; 1.0 when there is no foreground.

    depth : (H, W) float32, mask : (H, W) bool. Returns a Python float (float64 accumulation).
    """
    fg = np.asarray(depth, dtype=np.float64)[np.asarray(mask, dtype=bool)]
    if fg.size == 0:
        return 1.0
    return float(fg.mean())


def preprocess(depth: np.ndarray, normal_cam: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """G-buffer channels -> network input.

    depth : (H, W) float32 linear depth, 0 on background; normal_cam : (H, W, 3) float32;
    mask : (H, W) bool foreground. Returns x : (4, H, W) float32 (see the module docstring).
    Non-finite G-buffer values pass through (training then stops on them naming the batch).
    """
    depth = np.asarray(depth, dtype=np.float32)
    normal_cam = np.asarray(normal_cam, dtype=np.float32)
    mask = np.asarray(mask, dtype=bool)
    if depth.ndim != 2 or normal_cam.shape != depth.shape + (3,) or mask.shape != depth.shape:
        raise NeuralaoError(
            f"G-buffer shapes do not match: depth {depth.shape}, normal_cam {normal_cam.shape}, "
            f"mask {mask.shape}"
        )
    scale = depth_scale(depth, mask)
    x = np.empty((4,) + depth.shape, dtype=np.float32)
    x[0] = np.where(mask, depth / np.float32(scale), np.float32(BACKGROUND_DEPTH))
    x[1:] = np.where(mask[None], np.moveaxis(normal_cam, -1, 0), np.float32(0.0))
    return x


def radius_param(radius: float, depth: np.ndarray, mask: np.ndarray, yfov: float) -> float:
    """rho = R / (mean foreground depth * tan(yfov / 2)) for AO radius R in scene units (> 0)."""
    if not (np.isfinite(radius) and radius > 0):
        raise NeuralaoError(f"the AO radius must be a positive number of scene units, got {radius}")
    if not (np.isfinite(yfov) and 0 < yfov < np.pi):
        raise NeuralaoError(f"yfov must lie in (0, pi) radians, got {yfov}")
    return float(radius) / (depth_scale(depth, mask) * float(np.tan(0.5 * float(yfov))))


def frame_radius(frame: FrameLike, radius: float | None = None) -> float:
    """The AO radius of a frame in scene units: ``radius`` if given, else the largest radius its labels
    were traced at (``radii``), else an error asking for one."""
    if radius is not None:
        return float(radius)
    if "radii" in frame and np.size(frame["radii"]):
        return float(np.max(frame["radii"]))
    raise NeuralaoError("the frame has no label radii; give the AO radius in scene units (--radius)")


def frame_radius_param(frame: FrameLike, radius: float | None = None) -> float:
    """rho of :func:`radius_param` for a frame dict (depth, mask, yfov) at ``frame_radius(frame, radius)``."""
    if "yfov" not in frame:
        raise NeuralaoError("frame lacks yfov (needed for the radius input)")
    return radius_param(frame_radius(frame, radius), frame["depth"], frame["mask"], float(frame["yfov"]))


def preprocess_frame(frame: FrameLike, gtao: np.ndarray | None = None) -> np.ndarray:
    """``preprocess`` on a frame dict (keys depth, normal_cam, mask). Returns (4, H, W) float32, or
    (5, H, W) with ``gtao`` (H, W) as the hybrid's fifth channel (1 on background)."""
    missing = [k for k in ("depth", "normal_cam", "mask") if k not in frame]
    if missing:
        raise NeuralaoError(f"frame lacks G-buffer channel(s) {', '.join(missing)}")
    x = preprocess(frame["depth"], frame["normal_cam"], frame["mask"])
    if gtao is None:
        return x
    gtao = np.asarray(gtao, np.float32)
    if gtao.shape != x.shape[1:]:
        raise NeuralaoError(f"GTAO image is {gtao.shape}, the G-buffer {x.shape[1:]}")
    mask = np.asarray(frame["mask"], bool)
    return np.concatenate([x, np.where(mask, gtao, np.float32(1.0))[None]], axis=0)


def pad_amount(height: int, width: int, multiple: int) -> tuple[int, int]:
    """Rows and columns to add (bottom, right) so both sizes become multiples of ``multiple``."""
    return (-height) % multiple, (-width) % multiple


def check_padable(height: int, width: int, multiple: int) -> None:
    if height < multiple or width < multiple:
        raise NeuralaoError(
            f"image {width}x{height} is smaller than the U-Net's pad multiple {multiple} "
            "(reflect padding needs at least that)"
        )


def pad_to_multiple(x: np.ndarray, multiple: int) -> np.ndarray:
    """Reflect-pad the last two axes at the bottom/right to multiples of ``multiple``.

    x : (..., H, W) float32 -> (..., H', W') float32; the original is ``out[..., :H, :W]``.
    Same as ``torch.nn.functional.pad(mode="reflect")`` (edge sample not repeated).
    """
    h, w = x.shape[-2:]
    check_padable(h, w, multiple)
    ph, pw = pad_amount(h, w, multiple)
    if ph == 0 and pw == 0:
        return np.ascontiguousarray(x, dtype=np.float32)
    widths = [(0, 0)] * (x.ndim - 2) + [(0, ph), (0, pw)]
    return np.pad(np.asarray(x, dtype=np.float32), widths, mode="reflect")
