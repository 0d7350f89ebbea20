"""DeepAO screen-space U-Net (Zhang et al. 2020): input preprocessing, the model, the pad/crop wrapper.

Input contract (``preprocess``; the ONE function that training, export checks, parity and
inference all use, and that the ONNX metadata states in words):

    x : (4, H, W) float32, channels [depth, n_x, n_y, n_z]
        depth    linear camera-space depth (-z_cam) divided by the frame's MEAN foreground depth,
                 so the input does not depend on scene scale (scaling a scene, or moving the camera
                 away proportionally, gives the same input); 0 on background.
        n_x..z   camera-space unit normal, OpenGL convention (x right, y up, z towards the viewer),
                 flipped to face the viewer; 0 on background.

Why the mean and not the median or the AO radius: a frame file carries no AO radius (it is a
labeller setting in scene units), so a per-frame statistic keeps ``infer`` self-contained; the mean
(not the median) because a GPU gets it from one mip-chain reduction of depth and mask
(``sum(depth) / sum(mask)``). It is computed on the whole frame BEFORE any crop, in training too.
Background depth is 0 because no real surface can have it (znear > 0), whereas any positive constant
could coincide with a real far wall; with the zero normal it marks background unambiguously.

Model (``UNet``): encoder level i = 3x3 conv (stride 1) + LeakyReLU(0.01), then 2x2 average pool;
decoder level i = bilinear x2 upsample, 3x3 conv halving the channels, batch norm, LeakyReLU,
concatenation with the encoder skip, then a 3x3 fusion conv back to the level's width + LeakyReLU
(so every decoder conv input has twice the width of its output, as in the classic U-Net);
last layer a 1x1 conv to one channel and a sigmoid, so the output lies in [0, 1] for any input
(Sigmoid exports as one ONNX op the GLSL generator supports). Widths default to 4/8/16/32
(``depth = len(widths) - 1`` pooling steps).

Any resolution: the ONNX graph needs H and W multiples of ``2 ** depth`` (``pad_multiple``). The
consumer reflect-pads bottom/right to that multiple and crops the output back (``pad_to_multiple`` /
``PaddedUNet`` here; the GLSL manifest carries the same pad/crop passes). Padding stays out of the
ONNX graph.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from .errors import NeuralaoError

# Bumped whenever ``preprocess`` changes meaning; exported models record it and ``infer`` checks it.
PREPROCESS_VERSION = 1
INPUT_CHANNELS = ("depth", "normal_cam_x", "normal_cam_y", "normal_cam_z")
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
    "mask_convention": "foreground = depth > 0 (the G-buffer mask); background pixels have depth 0 and normal "
    "(0,0,0) in the input and AO 1 in the output (the network's value there is overwritten)",
    "output_name": "ao",
    "output": "(1,1,H,W) accessibility in [0,1], 1 = open (sigmoid)",
    "pad_mode": PAD_MODE,
    "pad_side": "bottom,right",
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
            f"G-buffer shapes do not match: depth {depth.shape}, normal_cam {normal_cam.shape}, mask {mask.shape}"
        )
    scale = depth_scale(depth, mask)
    x = np.empty((4,) + depth.shape, dtype=np.float32)
    x[0] = np.where(mask, depth / np.float32(scale), np.float32(BACKGROUND_DEPTH))
    x[1:] = np.where(mask[None], np.moveaxis(normal_cam, -1, 0), np.float32(0.0))
    return x


def preprocess_frame(frame: dict) -> np.ndarray:
    """``preprocess`` on a frame dict (keys depth, normal_cam, mask). Returns (4, H, W) float32."""
    missing = [k for k in ("depth", "normal_cam", "mask") if k not in frame]
    if missing:
        raise NeuralaoError(f"frame lacks G-buffer channel(s) {', '.join(missing)}")
    return preprocess(frame["depth"], frame["normal_cam"], frame["mask"])


def flip_input(x: torch.Tensor, horizontal: bool) -> torch.Tensor:
    """Mirror network inputs (N, 4, H, W): a horizontal flip negates n_x, a vertical flip negates n_y.

    Mirroring the image about a camera axis mirrors the 3D scene, and the AO of a mirrored scene is
    the mirrored AO, so both flips are exact augmentations (labels are flipped with ``torch.flip``).
    """
    dim, channel = (-1, 1) if horizontal else (-2, 2)
    out = x.flip(dim)
    sign = torch.ones(x.shape[1], dtype=x.dtype, device=x.device)
    sign[channel] = -1.0
    return out * sign.view(1, -1, 1, 1)


def pad_amount(height: int, width: int, multiple: int) -> tuple[int, int]:
    """Rows and columns to add (bottom, right) so both sizes become multiples of ``multiple``."""
    return (-height) % multiple, (-width) % multiple


def check_padable(height: int, width: int, multiple: int) -> None:
    if height < multiple or width < multiple:
        raise NeuralaoError(
            f"image {width}x{height} is smaller than the U-Net's pad multiple {multiple} (reflect padding needs at least that)"
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


@dataclass
class UNetArgs:
    """Architecture (stored in checkpoints as ``model_args``; rebuilds the model alone)."""

    in_channels: int = 4  # depth + camera-space normal
    widths: list[int] = field(default_factory=lambda: [4, 8, 16, 32])  # channels per level (paper: 4/8/16/32)
    negative_slope: float = 0.01  # LeakyReLU slope (paper: 0.01)
    bn_eps: float = 1e-5  # batch-norm epsilon (keeps near-zero running variance finite)

    @property
    def depth(self) -> int:
        return len(self.widths) - 1

    @property
    def pad_multiple(self) -> int:
        return 2**self.depth


def _conv3x3(cin: int, cout: int) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, kernel_size=3, padding=1)


class UNet(nn.Module):
    """The raw network: x (N, 4, H, W) float32 with H, W multiples of ``pad_multiple`` -> (N, 1, H, W) in [0, 1].

    This is exactly what is exported to ONNX (no padding inside).
    """

    def __init__(self, args: UNetArgs | None = None):
        super().__init__()
        self.args = args = args or UNetArgs()
        if len(args.widths) < 2 or any(int(w) < 1 for w in args.widths):
            raise NeuralaoError(
                f"U-Net widths must list at least two positive channel counts, got {args.widths}"
            )
        w = [int(v) for v in args.widths]
        slope = args.negative_slope
        self.down = nn.ModuleList(
            nn.Sequential(_conv3x3(args.in_channels if i == 0 else w[i - 1], w[i]), nn.LeakyReLU(slope))
            for i in range(len(w))
        )
        # up[i] brings level i+1 (width w[i+1]) to level i: upsample, conv w[i+1] -> w[i], BN, LeakyReLU.
        self.up = nn.ModuleList(
            nn.Sequential(
                _conv3x3(w[i + 1], w[i]), nn.BatchNorm2d(w[i], eps=args.bn_eps), nn.LeakyReLU(slope)
            )
            for i in range(len(w) - 1)
        )
        # fuse[i]: after concatenation with the skip (2 w[i] channels) back to w[i].
        self.fuse = nn.ModuleList(
            nn.Sequential(_conv3x3(2 * w[i], w[i]), nn.LeakyReLU(slope)) for i in range(len(w) - 1)
        )
        self.out = nn.Conv2d(w[0], 1, kernel_size=1)

    @property
    def pad_multiple(self) -> int:
        return self.args.pad_multiple

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        depth = self.args.depth
        skips = []
        for i, block in enumerate(self.down):
            x = block(x)
            if i < depth:
                skips.append(x)
                x = F.avg_pool2d(x, 2)
        for i in reversed(range(depth)):
            x = F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)
            x = self.up[i](x)
            x = self.fuse[i](torch.cat([x, skips[i]], dim=1))
        return torch.sigmoid(self.out(x))


class PaddedUNet(nn.Module):
    """Any resolution: reflect-pad bottom/right to ``pad_multiple``, run the U-Net, crop back.

    x : (N, 4, H, W) float32 -> (N, 1, H, W) float32. Same padding as :func:`pad_to_multiple`.
    """

    def __init__(self, unet: UNet):
        super().__init__()
        self.unet = unet

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        m = self.unet.pad_multiple
        check_padable(h, w, m)
        ph, pw = pad_amount(h, w, m)
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="reflect")
        return self.unet(x)[..., :h, :w]


def build_model(model_args: dict | UNetArgs | None = None) -> UNet:
    """UNet from a ``model_args`` dict (as stored in checkpoints) or a :class:`UNetArgs`."""
    if isinstance(model_args, UNetArgs) or model_args is None:
        return UNet(model_args)
    from .config import from_dict

    return UNet(from_dict(UNetArgs, dict(model_args)))


def model_args_dict(args: UNetArgs) -> dict:
    return {
        k: (list(v) if isinstance(v, Sequence) and not isinstance(v, str) else v)
        for k, v in asdict(args).items()
    }


def count_parameters(model: nn.Module) -> int:
    return int(sum(p.numel() for p in model.parameters()))


def predict(model: UNet, x: np.ndarray) -> np.ndarray:
    """Torch reference inference at any size. x : (4, H, W) float32 -> (H, W) float32 (raw network output)."""
    model.eval()
    with torch.no_grad():
        y = PaddedUNet(model)(torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))[None])
    return y[0, 0].numpy()
