"""Image networks built from the ops beyond convolutions, exported by both torch exporters
(``dynamo=False`` and the default ``dynamo=True``, which writes different graphs: Gelu and Mish nodes,
ReduceMean with axes as an input, Reshape without Constant nodes) and run as GLSL against onnxruntime.

Four small seeded networks, static 1 x 3 x 16 x 16 input:

* ESPCN super-resolution (Conv / Tanh, PixelShuffle -> DepthToSpace CRD);
* a fast-style-transfer net (reflection padding, InstanceNorm2d with affine, a residual block, nearest
  upsampling);
* normalisation blocks: GroupNorm + GELU (erf), LayerNorm over channels by permute + Mish, ConvNeXt's
  channels-first LayerNorm written out (ReduceMean, Sub, Pow, Sqrt, Div) + GELU (tanh);
* attention: squeeze-excitation with x.mean((2, 3)), a ShuffleNet channel shuffle, PixelUnshuffle,
  softmax over channels.

onnxruntime vs torch at TOL.onnx_vs_torch's rule; GLSL vs onnxruntime at TOL.parity_unet_fp32 (whole
networks: a few convs and normalisations in float32, summed in another order).
"""

from __future__ import annotations

import io
import logging
import warnings

import numpy as np
import onnx
import pytest
import torch
from helpers import onnx_vs_torch_tol
from torch import nn

from neuralao.export.glsl import generate_compute
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute_all


class ESPCN(nn.Module):
    def __init__(self, scale: int = 2):
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(3, 16, 5, padding=2),
            nn.Tanh(),
            nn.Conv2d(16, 8, 3, padding=1),
            nn.Tanh(),
            nn.Conv2d(8, 3 * scale * scale, 3, padding=1),
            nn.PixelShuffle(scale),
        )

    def forward(self, x):
        return self.body(x)


def _conv_in(cin: int, cout: int, stride: int = 1) -> list[nn.Module]:
    return [nn.ReflectionPad2d(1), nn.Conv2d(cin, cout, 3, stride), nn.InstanceNorm2d(cout, affine=True)]


class StyleNet(nn.Module):
    """Johnson et al.'s fast style transfer, shrunk: down, one residual block, up."""

    def __init__(self):
        super().__init__()
        self.down = nn.Sequential(*_conv_in(3, 8), nn.ReLU(), *_conv_in(8, 8, 2), nn.ReLU())
        self.res = nn.Sequential(*_conv_in(8, 8), nn.ReLU(), *_conv_in(8, 8))
        self.up = nn.Sequential(
            nn.Upsample(scale_factor=2, mode="nearest"),
            *_conv_in(8, 8),
            nn.ReLU(),
            nn.ReflectionPad2d(1),
            nn.Conv2d(8, 3, 3),
        )

    def forward(self, x):
        y = self.down(x)
        return self.up(y + self.res(y))


class LayerNorm2d(nn.Module):
    """nn.LayerNorm over channels by permuting to channels-last (timm / ConvNeXt downsampling layers)."""

    def __init__(self, c: int):
        super().__init__()
        self.ln = nn.LayerNorm(c)

    def forward(self, x):
        return self.ln(x.permute(0, 2, 3, 1)).permute(0, 3, 1, 2)


class ChannelsFirstLN(nn.Module):
    """ConvNeXt's LayerNorm(data_format="channels_first"), written out."""

    def __init__(self, c: int):
        super().__init__()
        self.w, self.b = nn.Parameter(1 + 0.3 * torch.randn(c)), nn.Parameter(0.3 * torch.randn(c))

    def forward(self, x):
        u = x.mean(1, keepdim=True)
        s = (x - u).pow(2).mean(1, keepdim=True)
        return self.w[:, None, None] * ((x - u) / torch.sqrt(s + 1e-6)) + self.b[:, None, None]


class NormNet(nn.Module):
    def __init__(self):
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(3, 8, 3, padding=1),
            nn.GroupNorm(2, 8),
            nn.GELU(),
            nn.Conv2d(8, 8, 3, padding=1),
            LayerNorm2d(8),
            nn.Mish(),
            nn.Conv2d(8, 8, 3, padding=1),
            ChannelsFirstLN(8),
            nn.GELU("tanh"),
            nn.Conv2d(8, 3, 1),
        )

    def forward(self, x):
        return self.body(x)


class AttentionNet(nn.Module):
    def __init__(self):
        super().__init__()
        self.stem = nn.Conv2d(3, 8, 3, padding=1)
        self.squeeze, self.excite = nn.Conv2d(8, 2, 1), nn.Conv2d(2, 8, 1)
        self.unshuffle = nn.PixelUnshuffle(2)
        self.mix = nn.Conv2d(32, 8, 1)
        self.head = nn.Conv2d(2, 3, 3, padding=1)

    def forward(self, x):
        x = self.stem(x)
        x = x * torch.sigmoid(self.excite(torch.relu(self.squeeze(x.mean((2, 3), keepdim=True)))))
        n, c, h, w = x.shape
        x = x.view(n, 2, c // 2, h, w).transpose(1, 2).reshape(n, c, h, w)  # channel shuffle, 2 groups
        x = torch.softmax(self.mix(self.unshuffle(x)), dim=1)
        return self.head(nn.functional.pixel_shuffle(x, 2))


def _seeded(cls) -> nn.Module:
    torch.manual_seed(0)
    net = cls().eval()
    with torch.no_grad():  # non-trivial affine parameters of the normalisations
        for m in net.modules():
            if isinstance(m, (nn.InstanceNorm2d, nn.GroupNorm, nn.LayerNorm)) and m.weight is not None:
                m.weight.copy_(1 + 0.3 * torch.randn_like(m.weight))
                m.bias.copy_(0.3 * torch.randn_like(m.bias))
    return net


def _export(net: nn.Module, x: torch.Tensor, dynamo: bool) -> onnx.ModelProto:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logging.disable(logging.WARNING)
        try:
            if dynamo:
                return torch.onnx.export(
                    net, (x,), dynamo=True, opset_version=18, input_names=["x"]
                ).model_proto
            buf = io.BytesIO()
            torch.onnx.export(net, (x,), buf, dynamo=False, opset_version=17, input_names=["x"])
            return onnx.load_from_string(buf.getvalue())
        finally:
            logging.disable(logging.NOTSET)


ARCHS = {"espcn": ESPCN, "style": StyleNet, "norms": NormNet, "attention": AttentionNet}


@pytest.mark.parametrize("dynamo", [False, True], ids=["legacy", "dynamo"])
@pytest.mark.parametrize("arch", sorted(ARCHS))
def test_arch_both_exporters(arch, dynamo):
    if dynamo:
        pytest.importorskip("onnxscript")
    net = _seeded(ARCHS[arch])
    x = torch.from_numpy(np.random.default_rng(1).normal(size=(1, 3, 16, 16)).astype(np.float32))
    model = _export(net, x, dynamo)
    with torch.no_grad():
        want = net(x).numpy()
    ref = run_onnxruntime(model.SerializeToString(), {model.graph.input[0].name: x.numpy()})[0]
    assert ref.shape == want.shape
    assert float(np.abs(ref - want).max()) <= onnx_vs_torch_tol(want, net)
    got = run_compute_all(generate_compute(model), x.numpy())[model.graph.output[0].name]
    assert got.shape == ref.shape and got.dtype == np.float32
    err = float(np.abs(got - ref).max())
    logging.getLogger(__name__).info(
        "%s %s: max |GLSL - onnxruntime| %.3g", arch, "dynamo" if dynamo else "legacy", err
    )
    assert err <= TOL.parity_unet_fp32, f"max abs err {err:.3g}"
