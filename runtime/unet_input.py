"""The U-Net's input contract, numpy only: G-buffer preprocessing, the radius input, reflect padding.

Two versions of the contract exist; an exported model records its own (ONNX metadata
``preprocess_version``) and every consumer follows it.

Version 3, frame-local (models trained from now on). A pixel's input depends on that pixel alone, so
its AO depends only on its receptive field, nothing is read back to the CPU, and scaling the whole
scene (depth and R together) changes nothing:

    x : (4, H, W) float32, channels [depth, n_x, n_y, n_z]
        depth    log of linear camera-space depth (-z_cam, scene units); 0 on background.
        n_x..z   camera-space unit normal, OpenGL convention (x right, y up, z towards the viewer),
                 flipped to face the viewer; 0 on background.
    radius   rho = log(R / tan(yfov / 2)), (1, 1, 1, 1) float32: the AO radius R in scene units and
             the projection, as an engine has them per frame.
    Inside the graph the depth channel becomes log(z tan(yfov / 2) / R) = depth - rho (0 on background)
    and the radius channel R / (z tan(yfov / 2)) its exp(-.), clipped to [0, RADIUS_CAP].

Version 4, frame-local with the back layer: version 3's channels and a fifth, before GTAO's in a hybrid:

        thickness   log(depth_back / depth), clipped to [0, THICKNESS_CAP], where the G-buffer's back layer
                    (``depth_back``: the depth where the pixel's camera ray leaves the solid it entered,
                    0 where the visible surface is thin) lies behind the visible surface; 0 elsewhere and
                    on background. An engine renders the back layer with one more pass of the opaque
                    geometry (pipeline/gbuffers/rasterizer.py's second pass says how).

Version 5, frame-local at any resolution: version 3's channels and graph, with the radius input also
stating the pixel scale of the network's input:

    radius   rho = log(R / tan(yfov / 2) * H / REFERENCE_ROWS), H the rows of the network's input (the
             frame's, or the internal height it is resampled to): the graph's radius channel is then the
             radius on screen in units of REFERENCE_ROWS / 2 pixels, so one network learns and runs at
             any number of rows. At H = REFERENCE_ROWS the input is version 3's. A version-5 export's
             ``internal_height`` is the most rows it runs at: taller frames are point-sampled down to it,
             shorter ones run at their own size.

Version 2, whole-frame (the models shipped before): depth divided by the frame's MEAN foreground depth,
rho = R / (mean foreground depth * tan(yfov / 2)); the graph's radius channel is
clip(rho / max(depth, RADIUS_DEPTH_FLOOR), 0, RADIUS_CAP). The mean couples every pixel of a frame and
needs a reduction (or a read-back) before the network runs.

The ONE preprocessing that training, export checks, parity and inference use (see
:mod:`neuralao.pipeline.models.unet` for the model); a consumer runs it without torch. The ONNX graph
needs H and W multiples of ``pad_multiple``: the consumer reflect-pads bottom/right
(:func:`pad_to_multiple`) and crops the output back.
"""

from __future__ import annotations

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.metadata import PAD_MODE
from neuralao.runtime.frame import FrameLike

# Bumped whenever ``preprocess`` changes meaning; exported models record it and consumers follow it.
# New models are trained with PREPROCESS_VERSION; every version of VERSIONS still runs.
PREPROCESS_VERSION = 3
VERSIONS = (2, 3, 4, 5)
# The version whose input has the back layer's thickness channel.
BACK_LAYER_VERSION = 4
# The version whose radius input states the pixel scale of the network's input (rows over REFERENCE_ROWS).
PIXEL_SCALE_VERSION = 5
REFERENCE_ROWS = 256
# Version 4's thickness channel: log(depth_back / depth) clipped to [0, THICKNESS_CAP] (a slab 55 times
# the visible depth deep reads as one that deep).
THICKNESS_CAP = 4.0
# The radius channel (see the module docstring): a floor on normalised depth and a cap on the value.
RADIUS_DEPTH_FLOOR = 1e-3
RADIUS_CAP = 8.0
# Version 3's graph reads foreground as clip(|n|^2 * FOREGROUND_GAIN, 0, 1): 1 for any normal longer than
# 1e-3 (unit normals on foreground), 0 for the zero normal of background.
FOREGROUND_GAIN = 1e6
RADIUS_INPUT = "radius"
INPUT_CHANNELS = ("depth", "normal_cam_x", "normal_cam_y", "normal_cam_z")
# The hybrid's input: the G-buffer channels and GTAO's AO at the same radius (1 on background).
HYBRID_CHANNELS = (*INPUT_CHANNELS, "gtao")


def input_channels(
    version: int = PREPROCESS_VERSION, gtao: bool = False, gtao_raw: bool = False
) -> tuple[str, ...]:
    """The network input's channels for a contract version (with GTAO's last for a hybrid, and before it
    with ``gtao_raw`` GTAO's pass before its blur)."""
    base = (*INPUT_CHANNELS, "thickness") if int(version) == BACK_LAYER_VERSION else INPUT_CHANNELS
    if not gtao:
        return base
    return (*base, "gtao_raw", "gtao") if gtao_raw else (*base, "gtao")


BACKGROUND_DEPTH = 0.0


_COMMON_DESCRIPTION = {
    "input_name": "gbuffer",
    "input_layout": "NCHW float32, N=1, C=4, H and W multiples of pad_multiple (pad, run, crop)",
    "input_channels": ",".join(INPUT_CHANNELS),
    "normal_space": "camera space, OpenGL convention (x right, y up, z towards the viewer), unit length, "
    "flipped to face the viewer",
    "radius_glsl": "uniform float u_radius (the same rho), set per frame",
    "output_name": "ao",
    "output": "(1,1,H,W) accessibility in [0,1], 1 = open (sigmoid)",
    "pad_mode": PAD_MODE,
    "pad_side": "bottom,right",
}
# Written verbatim into the ONNX metadata and the export manifest (input semantics, units), by version.
DESCRIPTIONS: dict[int, dict[str, str]] = {
    2: _COMMON_DESCRIPTION
    | {
        "preprocess_version": "2",
        "depth_units": "linear camera-space depth (-z_cam) divided by the mean depth over foreground pixels "
        "of the whole frame (dimensionless, scene-scale invariant)",
        "depth_normalisation": "depth / mean(depth[mask]); background 0",
        "mask_convention": "foreground = depth > 0 (the G-buffer mask); background pixels have depth 0 and "
        "normal (0,0,0) in the input and AO 1 in the output (the network's value there is overwritten)",
        "radius_input": f"{RADIUS_INPUT}: (1,1,1,1) float32 rho = R / (mean foreground depth * tan(yfov/2)), "
        "R = AO radius in scene units (the distance beyond which nothing occludes); the graph feeds the "
        f"network clip(rho / max(depth, {RADIUS_DEPTH_FLOOR:g}), 0, {RADIUS_CAP:g}) as a fifth channel",
    },
    3: _COMMON_DESCRIPTION
    | {
        "preprocess_version": "3",
        "depth_units": "natural log of linear camera-space depth (-z_cam, scene units); frame-local: no "
        "statistic of the frame, nothing read back",
        "depth_normalisation": "log(depth) on foreground; background 0",
        "mask_convention": "foreground = depth > 0 (the G-buffer mask); background pixels have depth 0 and "
        "normal (0,0,0) in the input and AO 1 in the output (the network's value there is overwritten); "
        "the graph finds foreground from the normal's length",
        "radius_input": f"{RADIUS_INPUT}: (1,1,1,1) float32 rho = log(R / tan(yfov/2)), R = AO radius in "
        "scene units (the distance beyond which nothing occludes), yfov the vertical field of view; the "
        "graph replaces the depth channel by depth - rho (log(z tan(yfov/2) / R), 0 on background) and adds "
        f"clip(exp(rho - depth), 0, {RADIUS_CAP:g}) (the radius on screen) as a fifth channel",
    },
}
DESCRIPTIONS[4] = DESCRIPTIONS[3] | {
    "preprocess_version": "4",
    "input_layout": "NCHW float32, N=1, C=5, H and W multiples of pad_multiple (pad, run, crop)",
    "input_channels": ",".join(input_channels(4)),
    "thickness": f"channel 4: clip(log(depth_back / depth), 0, {THICKNESS_CAP:g}) where the back layer lies "
    "behind the visible surface, else 0 (and on background); depth_back is the depth of the first surface "
    "behind the visible one (its own triangle excluded) when that surface faces the camera ray the other "
    "way, i.e. where the ray leaves the solid it entered: one more depth pass of the opaque geometry",
}
DESCRIPTIONS[5] = DESCRIPTIONS[3] | {
    "preprocess_version": "5",
    "radius_input": f"{RADIUS_INPUT}: (1,1,1,1) float32 rho = log(R / tan(yfov/2) * H / {REFERENCE_ROWS}), "
    "R = AO radius in scene units (the distance beyond which nothing occludes), yfov the vertical field "
    "of view, H the rows of the network's input; the graph replaces the depth channel by depth - rho and "
    f"adds clip(exp(rho - depth), 0, {RADIUS_CAP:g}) (the radius on screen, in units of "
    f"{REFERENCE_ROWS // 2} pixels) as a fifth channel",
    "internal_height_rule": "internal_height is the most rows the network runs at: taller frames are "
    "point-sampled down to it (the AO upsampled back), shorter ones run at their own size",
}
PREPROCESS_DESCRIPTION = DESCRIPTIONS[PREPROCESS_VERSION]


def scales_up(version: int) -> bool:
    """Whether a model of contract ``version`` runs frames shorter than its internal height point-sampled
    up to it (versions 2-4: the network knows one pixel scale) or at their own size (version 5)."""
    return int(version) != PIXEL_SCALE_VERSION


# Added to the metadata of a hybrid (GTAO-input) U-Net (:func:`hybrid_description`: by version).
HYBRID_DESCRIPTION = {
    "input_layout": "NCHW float32, N=1, C=5, H and W multiples of pad_multiple (pad, run, crop)",
    "input_channels": ",".join(HYBRID_CHANNELS),
    "gtao_channel": "channel 4: GTAO's AO at the same radius R (the engine's GTAO pass, run first), 1 on "
    "background; the network outputs clip(gtao + correction, 0, 1)",
    "output": "(1,1,H,W) accessibility in [0,1], 1 = open (GTAO + a learned correction, clipped)",
}


# A hybrid that reads GTAO before its blur says so in its metadata (``gtao_blur``: "false"); absent, or any
# other value, GTAO is blurred (the hybrids exported before the key existed).
RAW_GTAO_CHANNEL = (
    "GTAO's pass alone, without its 4x4 blur (the rotation pattern of its noise tile left in: the network "
    "denoises it)"
)


def hybrid_description(version: int, gtao_blur: bool = True, gtao_raw: bool = False) -> dict[str, str]:
    """The metadata a hybrid U-Net of contract ``version`` adds: its channels, GTAO's last, with
    ``gtao_blur`` False that its GTAO is the pass without its blur, and with ``gtao_raw`` the channel of
    GTAO's pass before its blur in front of the blurred GTAO (which stays the base of the correction)."""
    channels = input_channels(version, gtao=True, gtao_raw=gtao_raw)
    out = dict(HYBRID_DESCRIPTION)
    if gtao_raw:
        out["gtao_raw_channel"] = (
            f"channel {len(channels) - 2}: GTAO's pass at the same radius before its blur (the engine's "
            "f_gtao output, the rotation pattern of its noise tile in it), 1 on background: the detail the "
            "blur averages away; the correction is still added to the blurred GTAO of the last channel"
        )
    if channels != HYBRID_CHANNELS:
        layout = f"NCHW float32, N=1, C={len(channels)}, H and W multiples of pad_multiple (pad, run, crop)"
        gtao = HYBRID_DESCRIPTION["gtao_channel"].replace("channel 4", f"channel {len(channels) - 1}")
        out |= {"input_layout": layout, "input_channels": ",".join(channels), "gtao_channel": gtao}
    if not gtao_blur:
        out["gtao_channel"] = out["gtao_channel"].replace("the engine's GTAO pass", RAW_GTAO_CHANNEL)
        out["gtao_blur"] = "false"
    return out


def hybrid_gtao_blur(meta: dict, where: str = "model") -> bool:
    """Whether a hybrid's GTAO channel is GTAO after its blur: metadata ``gtao_blur`` "true" (or absent:
    the hybrids exported before the key existed) or "false"; anything else is a one-line error."""
    value = str(meta.get("gtao_blur", "true")).strip().lower()
    if value not in ("true", "false"):
        raise NeuralaoError(f"{where}: metadata gtao_blur must be true or false, got {meta['gtao_blur']!r}")
    return value == "true"


def depth_scale(depth: np.ndarray, mask: np.ndarray) -> float:
    """Mean foreground depth of a frame; 1.0 when there is no foreground.

    depth : (H, W) float32, mask : (H, W) bool. Returns a Python float (float64 accumulation).
    """
    fg = np.asarray(depth, dtype=np.float64)[np.asarray(mask, dtype=bool)]
    if fg.size == 0:
        return 1.0
    return float(fg.mean())


def check_version(version: object, where: str = "the model") -> int:
    """``version`` as an int of :data:`VERSIONS`; another is a one-line error naming ``where``."""
    if str(version) not in {str(v) for v in VERSIONS}:
        raise NeuralaoError(
            f"{where} expects preprocessing version {version}, this neuralao runs "
            + " and ".join(str(v) for v in VERSIONS)
        )
    return int(str(version))


def preprocess(
    depth: np.ndarray,
    normal_cam: np.ndarray,
    mask: np.ndarray,
    version: int = PREPROCESS_VERSION,
    depth_back: np.ndarray | None = None,
) -> np.ndarray:
    """G-buffer channels -> network input.

    depth : (H, W) float32 linear depth, 0 on background; normal_cam : (H, W, 3) float32;
    mask : (H, W) bool foreground; depth_back : (H, W) float32 back layer (version 4 needs it).
    Returns x : (4, H, W) float32, (5, H, W) for version 4 (see the module docstring).
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
    version = check_version(version)
    if version == BACK_LAYER_VERSION:
        if depth_back is None:
            raise NeuralaoError(
                "this model reads the G-buffer's back layer (depth_back); render the frames with it "
                "(`neuralao render --back-layer`, or a dataset built with gbuffer.back_layer)"
            )
        depth_back = np.asarray(depth_back, dtype=np.float32)
        if depth_back.shape != depth.shape:
            raise NeuralaoError(
                f"G-buffer shapes do not match: depth {depth.shape}, depth_back {depth_back.shape}"
            )
    x = np.empty((len(input_channels(version)),) + depth.shape, dtype=np.float32)
    if version == 2:
        x[0] = np.where(mask, depth / np.float32(depth_scale(depth, mask)), np.float32(BACKGROUND_DEPTH))
    else:
        fg = mask & (depth > 0)  # a foreground pixel at depth 0 has no logarithm: it reads as background
        with np.errstate(divide="ignore", invalid="ignore"):
            x[0] = np.where(fg, np.log(np.where(fg, depth, np.float32(1.0))), np.float32(BACKGROUND_DEPTH))
        mask = fg
    x[1:4] = np.where(mask[None], np.moveaxis(normal_cam, -1, 0), np.float32(0.0))
    if version == BACK_LAYER_VERSION:
        x[4] = thickness_channel(depth, depth_back, mask)
    return x


def thickness_channel(depth: np.ndarray, depth_back: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Version 4's thickness channel (H, W) float32: clip(log(depth_back / depth), 0, THICKNESS_CAP) where
    the back layer lies behind a foreground pixel, else 0."""
    depth = np.asarray(depth, np.float32)
    depth_back = np.asarray(depth_back, np.float32)
    slab = np.asarray(mask, bool) & (depth > 0) & (depth_back > depth)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = np.log(np.where(slab, depth_back, np.float32(1.0)) / np.where(slab, depth, np.float32(1.0)))
    return np.where(slab, np.clip(t, np.float32(0.0), np.float32(THICKNESS_CAP)), np.float32(0.0)).astype(
        np.float32
    )


def radius_param(
    radius: float, depth: np.ndarray, mask: np.ndarray, yfov: float, version: int = PREPROCESS_VERSION
) -> float:
    """rho for AO radius R in scene units (> 0): log(R / tan(yfov / 2)) (versions 3 and 4, the frame's
    depth unused), that plus log(H / REFERENCE_ROWS) (version 5, H the rows of ``depth``, the network's
    input), or R / (mean foreground depth * tan(yfov / 2)) (version 2)."""
    if not (np.isfinite(radius) and radius > 0):
        raise NeuralaoError(f"the AO radius must be a positive number of scene units, got {radius}")
    if not (np.isfinite(yfov) and 0 < yfov < np.pi):
        raise NeuralaoError(f"yfov must lie in (0, pi) radians, got {yfov}")
    if check_version(version) == 2:
        return float(radius) / (depth_scale(depth, mask) * float(np.tan(0.5 * float(yfov))))
    return float(np.log(float(radius)) - np.log(np.tan(0.5 * float(yfov)))) + pixel_scale(depth, version)


def pixel_scale(depth: np.ndarray, version: int) -> float:
    """log(H / REFERENCE_ROWS) for version 5 (H: the rows of ``depth``), 0 for the others."""
    if int(version) != PIXEL_SCALE_VERSION:
        return 0.0
    return float(np.log(np.shape(depth)[0] / REFERENCE_ROWS))


def radius_of_param(rho: float, depth: np.ndarray, mask: np.ndarray, yfov: float, version: int) -> float:
    """The AO radius R in scene units whose parameter is ``rho`` (the inverse of :func:`radius_param`)."""
    tan = float(np.tan(0.5 * float(yfov)))
    if check_version(version) == 2:
        return float(rho) * depth_scale(depth, mask) * tan
    return float(np.exp(float(rho) - pixel_scale(depth, version))) * tan


def frame_radius(frame: FrameLike, radius: float | None = None) -> float:
    """The AO radius of a frame in scene units: ``radius`` if given, else the largest radius its labels
    were traced at (``radii``), else an error asking for one."""
    if radius is not None:
        return float(radius)
    if "radii" in frame and np.size(frame["radii"]):
        return float(np.max(frame["radii"]))
    raise NeuralaoError("the frame has no label radii; give the AO radius in scene units (--radius)")


def frame_radius_param(
    frame: FrameLike, radius: float | None = None, version: int = PREPROCESS_VERSION
) -> float:
    """rho of :func:`radius_param` for a frame (depth, mask, yfov) at ``frame_radius(frame, radius)``."""
    if "yfov" not in frame:
        raise NeuralaoError("frame lacks yfov (needed for the radius input)")
    r = frame_radius(frame, radius)
    return radius_param(r, frame["depth"], frame["mask"], float(frame["yfov"]), version)


def preprocess_frame(
    frame: FrameLike,
    gtao: np.ndarray | None = None,
    version: int = PREPROCESS_VERSION,
    gtao_raw: np.ndarray | None = None,
) -> np.ndarray:
    """``preprocess`` on a frame (keys depth, normal_cam, mask; depth_back for version 4). Returns
    (C, H, W) float32, with ``gtao`` (H, W) as the hybrid's last channel (1 on background), and
    ``gtao_raw`` (H, W), GTAO before its blur, before it."""
    missing = [k for k in ("depth", "normal_cam", "mask") if k not in frame]
    if missing:
        raise NeuralaoError(f"frame lacks G-buffer channel(s) {', '.join(missing)}")
    x = preprocess(frame["depth"], frame["normal_cam"], frame["mask"], version, frame.get("depth_back"))
    if gtao is None:
        return x
    mask = np.asarray(frame["mask"], bool)
    extra = []
    for name, image in (("GTAO image before its blur", gtao_raw), ("GTAO image", gtao)):
        if image is None:
            continue
        image = np.asarray(image, np.float32)
        if image.shape != x.shape[1:]:
            raise NeuralaoError(f"{name} is {image.shape}, the G-buffer {x.shape[1:]}")
        extra.append(np.where(mask, image, np.float32(1.0))[None])
    return np.concatenate([x, *extra], axis=0)


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
