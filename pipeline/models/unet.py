"""DeepAO screen-space U-Net (Zhang et al. 2020): input preprocessing, the model, the pad/crop wrapper.

Input contract: :mod:`neuralao.runtime.unet_input` (numpy, the ONE preprocessing that training, export
checks, parity and inference use, stated in words in the ONNX metadata). Version 3, what new models
train with, is frame-local: channel 0 is log(-z_cam) (0 on background), the radius input is
rho = log(R / tan(yfov / 2)), and the graph makes the depth relative to the radius (depth - rho) and
adds the radius on screen, exp(rho - depth), as a channel. Every input of a pixel is the pixel's own, so
its AO depends only on the receptive field (no statistic of the frame, nothing read back), and scaling
the scene (depth and R together) leaves the input unchanged. Version 2 (the earlier shipped models)
divided depth by the frame's mean foreground depth. Labels exist at several radii per frame (one trace,
``ao_radii``), so one network serves any radius in the trained range. Background depth is 0 and its
normal zero, which marks it unambiguously (no unit normal is zero).

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

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.settings import from_dict
from neuralao.runtime.unet_input import (
    FOREGROUND_GAIN,
    PREPROCESS_VERSION,
    RADIUS_CAP,
    RADIUS_DEPTH_FLOOR,
    check_padable,
    check_version,
    input_channels,
    pad_amount,
)


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


@dataclass
class UNetArgs:
    """Architecture (stored in checkpoints as ``model_args``; rebuilds the model alone)."""

    in_channels: int = 4  # G-buffer channels: depth + camera-space normal
    widths: list[int] = field(default_factory=lambda: [4, 8, 16, 32])  # channels per level (paper: 4/8/16/32)
    negative_slope: float = 0.01  # LeakyReLU slope (paper: 0.01)
    bn_eps: float = 1e-5  # batch-norm epsilon (keeps near-zero running variance finite)
    radius_input: bool = True  # the AO radius is a run-time input (an extra per-pixel channel, see RADIUS_*)
    scale: int = 1  # 1 = full resolution; 2 / 4 = the U-Net runs at 1/2 / 1/4 resolution (see UNet)
    refine_width: int = 4  # channels of the full-resolution refinement of the reduced-resolution variants
    # Hybrid: GTAO's AO at the same radius is a fifth input channel and the network predicts a
    # correction to it: ao = clip(gtao + conv(x), 0, 1) (GTAO stays a GL pass the engine runs first).
    gtao_input: bool = False
    # The hybrid's GTAO: after its 4x4 blur (True, the classic pass) or the pass alone (False: the
    # network does the denoising, and sees the detail the blur smears across silhouettes).
    gtao_blur: bool = True
    # The hybrid also reads GTAO's pass before its blur, a channel in front of the (blurred) GTAO that stays
    # the base of its correction: the detail the blur averages away, and a smooth base at any resolution.
    gtao_raw_input: bool = False
    # The input contract (neuralao.runtime.unet_input): 3 = frame-local (log depth, rho =
    # log(R / tan(yfov/2))); 2 = the whole frame's mean depth. Checkpoints without it are version 2.
    preprocess_version: int = PREPROCESS_VERSION

    @property
    def depth(self) -> int:
        return len(self.widths) - 1

    @property
    def pad_multiple(self) -> int:
        return self.scale * 2**self.depth


def _conv3x3(cin: int, cout: int) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, kernel_size=3, padding=1)


class UNet(nn.Module):
    """The raw network: x (N, 4, H, W) float32 with H, W multiples of ``pad_multiple`` and the radius
    parameter rho (N, 1, 1, 1) float32 -> AO (N, 1, H, W) in [0, 1].

    This is exactly what is exported to ONNX (no padding inside). With ``radius_input`` the first
    operations build the radius channel, the screen-space radius R / (z tan(yfov / 2)) in units of half
    the screen height at the pixel's depth, clipped to [0, RADIUS_CAP], and concatenate it to x (version
    3 also makes the depth channel relative to the radius: log(z tan(yfov / 2) / R); see
    :mod:`neuralao.runtime.unet_input`); the depth channel is read by a fixed 1x1 channel-select
    convolution so the graph needs no Slice. With ``scale`` s > 1 the G-buffer is point-sampled to 1/s
    resolution (nearest, every s-th pixel), the U-Net runs there, its AO is upsampled bilinearly and a small
    full-resolution refinement (3x3 conv on [upsampled AO, full-resolution G-buffer, upsampled
    low-resolution depth] -> LeakyReLU -> 1x1 conv) adds a correction, clipped to [0, 1]: it sees
    where the full-resolution depth and normals differ from what the low-resolution pass saw, so
    AO does not bleed across depth and normal edges.
    """

    def __init__(self, args: UNetArgs | None = None):
        super().__init__()
        self.args = args = args or UNetArgs()
        if len(args.widths) < 2 or any(int(w) < 1 for w in args.widths):
            raise NeuralaoError(
                f"U-Net widths must list at least two positive channel counts, got {args.widths}"
            )
        check_version(args.preprocess_version, "this U-Net")
        if args.gtao_raw_input and not (args.gtao_input and args.gtao_blur):
            raise NeuralaoError(
                "gtao_raw_input adds GTAO before its blur beside the blurred GTAO of a hybrid: it needs "
                "gtao_input true and gtao_blur true"
            )
        hybrid = input_channels(args.preprocess_version, gtao=True, gtao_raw=bool(args.gtao_raw_input))
        if args.gtao_input and (int(args.scale) != 1 or int(args.in_channels) != len(hybrid)):
            raise NeuralaoError(
                f"a GTAO-input U-Net takes {len(hybrid)} channels ({', '.join(hybrid)}) at "
                f"scale 1, got in_channels {args.in_channels} and scale {args.scale}"
            )
        plain = input_channels(args.preprocess_version)
        if not args.gtao_input and int(args.preprocess_version) == 4 and int(args.in_channels) != len(plain):
            raise NeuralaoError(
                f"a version-{args.preprocess_version} U-Net takes {len(plain)} channels "
                f"({', '.join(plain)}), got in_channels {args.in_channels}"
            )
        if int(args.scale) not in (1, 2, 4) or int(args.refine_width) < 1:
            raise NeuralaoError(
                f"U-Net scale must be 1, 2 or 4 and refine_width >= 1, got {args.scale} and "
                f"{args.refine_width}"
            )
        w = [int(v) for v in args.widths]
        slope = args.negative_slope
        cin = args.in_channels + (1 if args.radius_input else 0)
        select = torch.zeros(1, args.in_channels, 1, 1)
        select[0, 0] = 1.0  # channel 0 = normalised depth
        self.register_buffer("select", select, persistent=False)
        # Version 3 reads foreground from the normal's squared length (1x1 conv over x * x) and replaces
        # the depth channel (x + a 1x1 conv spreading new - old into channel 0): no Slice, no Where.
        normal_sq = torch.zeros(1, args.in_channels, 1, 1)
        normal_sq[0, 1:4] = 1.0
        self.register_buffer("normal_sq", normal_sq, persistent=False)
        self.register_buffer("first", select.clone().view(-1, 1, 1, 1), persistent=False)
        if args.gtao_input:
            guide = torch.zeros(1, cin, 1, 1)  # _unet sees the radius channel appended after GTAO
            guide[0, len(hybrid) - 1] = (
                1.0  # the (blurred) GTAO channel, read like depth: no Slice in the graph
            )
            self.register_buffer("guide", guide, persistent=False)
        self.down = nn.ModuleList(
            nn.Sequential(_conv3x3(cin if i == 0 else w[i - 1], w[i]), nn.LeakyReLU(slope))
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
        if args.scale > 1:
            rw = int(args.refine_width)
            self.refine = nn.Sequential(
                _conv3x3(1 + args.in_channels + 1, rw), nn.LeakyReLU(slope), nn.Conv2d(rw, 1, kernel_size=1)
            )

    @property
    def pad_multiple(self) -> int:
        return self.args.pad_multiple

    def _depth(self, x: torch.Tensor) -> torch.Tensor:
        return F.conv2d(x, self.select)

    def _with_radius(self, x: torch.Tensor, radius: torch.Tensor | None) -> torch.Tensor:
        if not self.args.radius_input:
            return x
        if radius is None:
            raise NeuralaoError("this U-Net takes the AO radius as an input; pass radius (N, 1, 1, 1)")
        if int(self.args.preprocess_version) == 2:
            r = torch.clamp(radius / torch.clamp(self._depth(x), min=RADIUS_DEPTH_FLOOR), 0.0, RADIUS_CAP)
            return torch.cat([x, r], dim=1)
        # log(z tan(yfov/2) / R) on foreground, 0 on background; its exp(-.) is the radius on screen
        fg = torch.clamp(F.conv2d(x * x, self.normal_sq) * FOREGROUND_GAIN, 0.0, 1.0)
        depth = self._depth(x)
        relative = (depth - radius) * fg
        r = torch.clamp(torch.exp(-relative), 0.0, RADIUS_CAP) * fg
        return torch.cat([x + F.conv2d(relative - depth, self.first), r], dim=1)

    def _unet(self, x: torch.Tensor) -> torch.Tensor:
        gtao = F.conv2d(x, self.guide) if self.args.gtao_input else None
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
        if gtao is not None:
            return torch.clamp(gtao + self.out(x), 0.0, 1.0)
        return torch.sigmoid(self.out(x))

    def forward(self, x: torch.Tensor, radius: torch.Tensor | None = None) -> torch.Tensor:
        s = int(self.args.scale)
        if s == 1:
            return self._unet(self._with_radius(x, radius))
        low = F.interpolate(x, scale_factor=1.0 / s, mode="nearest")
        ao = F.interpolate(
            self._unet(self._with_radius(low, radius)),
            scale_factor=float(s),
            mode="bilinear",
            align_corners=False,
        )
        d_up = F.interpolate(self._depth(low), scale_factor=float(s), mode="bilinear", align_corners=False)
        return torch.clamp(ao + self.refine(torch.cat([ao, x, d_up], dim=1)), 0.0, 1.0)


class PaddedUNet(nn.Module):
    """Any resolution: reflect-pad bottom/right to ``pad_multiple``, run the U-Net, crop back.

    x : (N, 4, H, W) float32, radius : (N, 1, 1, 1) float32 -> (N, 1, H, W) float32. Same padding
    as :func:`pad_to_multiple`.
    """

    def __init__(self, unet: UNet):
        super().__init__()
        self.unet = unet

    def forward(self, x: torch.Tensor, radius: torch.Tensor | None = None) -> torch.Tensor:
        h, w = x.shape[-2:]
        m = self.unet.pad_multiple
        check_padable(h, w, m)
        ph, pw = pad_amount(h, w, m)
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="reflect")
        return self.unet(x, radius)[..., :h, :w]


def build_model(model_args: dict | UNetArgs | None = None) -> UNet:
    """UNet from a ``model_args`` dict (as stored in checkpoints) or a :class:`UNetArgs`."""
    if isinstance(model_args, UNetArgs) or model_args is None:
        return UNet(model_args)

    model_args = dict(model_args)
    model_args.setdefault("radius_input", False)  # checkpoints from before the radius input
    model_args.setdefault("preprocess_version", 2)  # checkpoints from before the frame-local contract
    return UNet(from_dict(UNetArgs, model_args))


def model_args_dict(args: UNetArgs) -> dict:
    return {
        k: (list(v) if isinstance(v, Sequence) and not isinstance(v, str) else v)
        for k, v in asdict(args).items()
    }


def radius_tensor(rho: float | None) -> torch.Tensor | None:
    """The radius parameter as the network's (1, 1, 1, 1) float32 input (None stays None)."""
    return None if rho is None else torch.full((1, 1, 1, 1), float(rho), dtype=torch.float32)


def predict(model: UNet, x: np.ndarray, rho: float | None = None) -> np.ndarray:
    """Torch reference inference at any size. x : (4, H, W) float32, rho : the radius parameter
    (:func:`radius_param`; required by radius-input models) -> (H, W) float32 (raw network output)."""
    model.eval()
    with torch.no_grad():
        y = PaddedUNet(model)(
            torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))[None], radius_tensor(rho)
        )
    return y[0, 0].numpy()
