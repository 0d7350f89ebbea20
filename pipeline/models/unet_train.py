"""`neuralao train unet`: train the DeepAO U-Net with a masked 1 - SSIM loss; resumable, deterministic.

Data: frames of the dataset's ``train`` scenes (held-back views excluded), preprocessed ONCE per
whole frame with :func:`neuralao.pipeline.models.unet.preprocess` (so the depth normalisation of a crop is
that of its frame, exactly as at run time), then random square crops with horizontal / vertical flips (flips
negate n_x / n_y). Frames may differ in size (a corpus of several resolutions): crops are the same size
whatever the frame, so a batch mixes them. Validation: whole frames of the ``val`` scenes every epoch
(held-back views of the training scenes when the dataset has no val scene).

Loss: 1 - SSIM (Gaussian window 11, sigma 1.5, C1 = 1e-4, C2 = 9e-4) averaged over the pixels
whose label is valid; before SSIM the prediction is replaced by the label outside the mask, so
background never enters the statistics of a window. A constant crop gives SSIM = 1 (C1, C2 keep
the ratio finite); a batch without any valid pixel gives a zero loss. With ``mse_weight`` the masked
mean squared error is added, weighted (SSIM hardly sees a bias of the whole image; RMSE does).

Checkpoints: written atomically after every epoch to ``OUT.partial`` (model, optimizer, RNG
states, history); the final one is renamed onto ``OUT`` at the end, so an interrupted run leaves
no ``OUT`` (make reruns the target) and a rerun continues from the partial file. Every random
choice comes from one seeded generator whose state is checkpointed, so interrupted + resumed
equals uninterrupted bit for bit (same machine and thread count).
"""

from __future__ import annotations

import copy
import logging
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from neuralao.pipeline.models.checkpoint import (
    check_interval,
    check_parameters,
    check_threads,
    restore_model,
    save_checkpoint,
)
from neuralao.pipeline.models.checkpoint import load_checkpoint as _load_checkpoint
from neuralao.pipeline.models.unet import PaddedUNet, UNet, UNetArgs, build_model, flip_input, model_args_dict
from neuralao.pipeline.models.unet_frames import FrameSet, foreground, network_input
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import (
    MAX_CAP,
    check_count,
    check_finite_number,
    check_int_range,
    check_seed,
)
from neuralao.runtime.foundation.metadata import MAX_INTERNAL_HEIGHT, MIN_INTERNAL_HEIGHT
from neuralao.runtime.foundation.metrics import masked_rmse, masked_ssim
from neuralao.runtime.foundation.settings import settings_to_dict
from neuralao.runtime.unet_input import (
    DESCRIPTIONS,
    PREPROCESS_VERSION,
    check_version,
    input_channels,
)

log = logging.getLogger(__name__)

KIND = "unet"
FORMAT_VERSION = 1
# Bytes per pixel of a training crop per channel of the U-Net, a level at 2^-i of the resolution counting
# 4^-i: the float32 activations autograd keeps (conv, batch norm, LeakyReLU, concatenation: about ten per
# channel) and their gradients, generously.
ACTIVATION_BYTES = 96
# The same without gradients (validation runs whole frames under no_grad, a few layers alive at a time).
EVAL_ACTIVATION_BYTES = 16
# Bytes per pixel of a frame or crop outside the network: the prepared channels (input, labels and masks
# at every radius), the point-sampling temporaries, the SSIM statistics and their gradients.
FRAME_PIXEL_BYTES = 512
# Per crop of an epoch's plan: 8 candidate positions (int64 tops, lefts, float64 foreground fractions)
# and the chosen crop's frame, position, flips and radius.
PLAN_BYTES = 512
# Per epoch: one record of the history the checkpoint keeps.
HISTORY_BYTES = 512


@dataclass
class UNetTrainSettings:
    """Settings of `neuralao train unet` (stored resolved in the checkpoint under "config")."""

    epochs: int = 30  # passes over the training frames (crops_per_frame crops of each frame per pass)
    batch_size: int = 16  # crops per Adam step (paper: 16)
    # Adam learning rate. The paper uses 1e-4; on the demo budget (a few minutes on 2 CPU cores) 1e-4
    # is still far from converged after 30 epochs, so the demo default is 1e-3 (see the report).
    lr: float = 1e-3
    weight_decay: float = 0.0  # Adam L2 weight decay
    crop: int = 64  # square crop side in pixels (a multiple of 2**depth; 0 = whole frames, all the same size)
    crops_per_frame: int = 2  # random crops drawn from each training frame per epoch
    min_foreground: float = 0.1  # a crop should have at least this fraction of valid pixels (best of 8 tries)
    hflip: bool = True  # random horizontal flips (negates camera-space n_x)
    vflip: bool = True  # random vertical flips (negates camera-space n_y)
    widths: list[int] = field(
        default_factory=lambda: [4, 8, 16, 32]
    )  # channels per U-Net level (paper 4/8/16/32)
    negative_slope: float = 0.01  # LeakyReLU slope (paper 0.01)
    ssim_window: int = 11  # SSIM Gaussian window side in pixels (paper 11)
    ssim_sigma: float = 1.5  # SSIM Gaussian window sigma (Wang et al. 2004)
    ssim_c1: float = 1e-4  # SSIM C1 = (0.01 L)^2 with L = 1
    ssim_c2: float = 9e-4  # SSIM C2 = (0.03 L)^2 with L = 1
    # Weight of the masked mean squared error added to 1 - SSIM (0 = the paper's SSIM loss alone). SSIM
    # is nearly blind to a bias of the whole image, which RMSE counts in full.
    mse_weight: float = 0.0
    seed: int = 0  # seeds weight init (torch.manual_seed) and the crop / flip / order / radius generator
    threads: int = 0  # torch intra-op threads (0 = torch's default); fixed for bitwise-reproducible runs
    # Architecture beyond the widths: the G-buffer resolution divisor of the variant (1, 2 or 4) and the
    # width of its full-resolution refinement (see neuralao.pipeline.models.unet.UNet).
    scale: int = 1
    refine_width: int = 4
    # Learning-rate schedule over all steps: "constant", or "cosine" (linear warm-up over warmup_steps,
    # then cosine decay to lr * min_lr_ratio at the last step).
    lr_schedule: str = "constant"
    warmup_steps: int = 0
    min_lr_ratio: float = 0.05
    # Wall-clock budget in minutes (0 = none: train `epochs` epochs). With a budget, a short calibration on
    # a copy of the model (10 steps, one validation pass) measures the cost of an epoch and fixes the epoch
    # count so the run ends within the budget; the plan is stored in the checkpoint, so a resumed run
    # follows the same plan and ends with the same weights as an uninterrupted one. `epochs` is then an upper
    # bound. A budget run's schedule should be "cosine" (the end is known in advance).
    budget_minutes: float = 0.0
    train_fraction: float = 1.0  # train on this fraction of the training scenes (the corpus-size study)
    val_frames: int = 0  # validate on at most this many frames, evenly spaced (0 = all)
    device: str = "auto"  # "auto" (CUDA when torch sees a device), "cpu" or "cuda"
    init: str = ""  # checkpoint to start from (weights whose shapes match are copied; e.g. the full-res
    # network for a reduced-resolution variant, whose refinement then starts from scratch)
    # Rows the network runs at: every frame is point-sampled to it (labels too; shorter frames up), as
    # inference does (neuralao.runtime.internal_resolution), so the radius input always means the same
    # number of pixels. 0 = every frame at its own size. Exported models declare it (metadata
    # internal_height).
    internal_height: int = 256
    # Hybrid: GTAO's AO at each label radius (neuralao.runtime.baselines, computed on the frame before any
    # point sampling, as an engine would) is a fifth input channel; the network learns a correction.
    gtao_input: bool = False
    # The hybrid's GTAO after its blur (True) or the GTAO pass alone (False: the network denoises it).
    gtao_blur: bool = True
    # The hybrid also reads GTAO's pass before its blur (a channel in front of the blurred GTAO, which stays
    # the base of the correction).
    gtao_raw_input: bool = False
    # The input contract the model is trained for (neuralao.runtime.unet_input): 3 = frame-local (log
    # depth, the radius through the projection); 2 = the whole frame's mean depth, as the earlier models.
    preprocess_version: int = PREPROCESS_VERSION


# ----------------------------------------------------------------------------------------------- loss


def gaussian_window(size: int, sigma: float) -> torch.Tensor:
    """(size,) float32 normalised 1-D Gaussian."""
    r = torch.arange(size, dtype=torch.float64) - (size - 1) / 2.0
    g = torch.exp(-(r**2) / (2.0 * sigma**2))
    return (g / g.sum()).to(torch.float32)


def ssim_map(
    x: torch.Tensor, y: torch.Tensor, window: int = 11, sigma: float = 1.5, c1: float = 1e-4, c2: float = 9e-4
) -> torch.Tensor:
    """Per-pixel SSIM of (N, 1, H, W) float32 images (Gaussian window, replicate padding) -> (N, 1, H, W)."""
    g = gaussian_window(window, sigma).to(x.device)
    stats = torch.cat([x, y, x * x, y * y, x * y], dim=1)
    p = window // 2
    stats = F.pad(stats, (p, p, p, p), mode="replicate")
    stats = F.conv2d(stats, g.view(1, 1, 1, -1).expand(5, 1, 1, window).contiguous(), groups=5)
    stats = F.conv2d(stats, g.view(1, 1, -1, 1).expand(5, 1, window, 1).contiguous(), groups=5)
    mx, my, exx, eyy, exy = stats.split(1, dim=1)
    vx, vy, cxy = exx - mx * mx, eyy - my * my, exy - mx * my
    return ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))


def masked_ssim_loss(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, **ssim_kw) -> torch.Tensor:
    """1 - mean SSIM over mask pixels. pred, target, mask : (N, 1, H, W) float32 (mask 0/1). Scalar.

    Outside the mask the prediction is replaced by the target (background is identical in both,
    so it never affects a window's statistics); no mask pixel at all -> 0 (still differentiable).
    """
    m = mask > 0.5
    total = m.sum()
    if int(total) == 0:
        return (pred * 0.0).sum()
    s = ssim_map(torch.where(m, pred, target), target, **ssim_kw)
    return 1.0 - s[m].sum() / total


def training_loss(
    pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, mse_weight: float = 0.0, **ssim_kw
) -> torch.Tensor:
    """The masked 1 - SSIM loss, plus ``mse_weight`` times the mean squared error over the mask pixels
    when it is above 0 (SSIM barely sees a shift of the whole image: a bias of 0.05 at AO 0.8 costs 0.002
    of it, so RMSE is left to chance without the squared term)."""
    loss = masked_ssim_loss(pred, target, mask, **ssim_kw)
    m = mask > 0.5
    if mse_weight > 0.0 and int(m.sum()) > 0:
        loss = loss + mse_weight * ((pred - target)[m] ** 2).mean()
    return loss


def _loss_kw(settings: UNetTrainSettings) -> dict:
    return {
        "window": settings.ssim_window,
        "sigma": settings.ssim_sigma,
        "c1": settings.ssim_c1,
        "c2": settings.ssim_c2,
        "mse_weight": settings.mse_weight,
    }


# ----------------------------------------------------------------------------------------------- data


def _integral(m: torch.Tensor) -> torch.Tensor:
    """(N, H, W) bool mask -> (N, H+1, W+1) int32 summed-area table."""
    s = torch.zeros(m.shape[0], m.shape[1] + 1, m.shape[2] + 1, dtype=torch.int32)
    s[:, 1:, 1:] = m.to(torch.int32).cumsum(1).cumsum(2)
    return s


@dataclass
class Foreground:
    """Summed-area tables of every frame's foreground, end to end: entry (i, j) of frame f (0 <= i <= H_f,
    0 <= j <= W_f) is ``table[offset[f] + i * stride[f] + j]`` with stride W_f + 1. table : (T,) int32;
    offset, stride : (N,) int64. One flat table holds frames of any sizes with one gather per lookup."""

    table: torch.Tensor
    offset: torch.Tensor
    stride: torch.Tensor

    @classmethod
    def of(cls, data: FrameSet) -> Foreground:
        if isinstance(data.x, torch.Tensor):
            tables = [_integral(foreground(data.x))]
        else:
            tables = [_integral(foreground(x)[None]) for x in data.x]
        sizes = torch.tensor([(h + 1) * (w + 1) for h, w in data.sizes], dtype=torch.int64)
        offset = torch.cumsum(sizes, 0) - sizes
        stride = torch.tensor([w + 1 for _, w in data.sizes], dtype=torch.int64)
        return cls(torch.cat([t.reshape(-1) for t in tables]), offset, stride)

    def count(self, frame: torch.Tensor, top: torch.Tensor, left: torch.Tensor, c: int) -> torch.Tensor:
        """Foreground pixels in the c x c squares at (top, left) of ``frame`` (broadcast int64 tensors)."""
        base, row = self.offset[frame], self.stride[frame]

        def at(i, j):
            return self.table[base + i * row + j]

        return at(top + c, left + c) - at(top, left + c) - at(top + c, left) + at(top, left)


@dataclass
class EpochPlan:
    """Which crop of which frame, at which radius, each sample of an epoch uses. (S,) int64 / bool tensors."""

    frame: torch.Tensor
    top: torch.Tensor
    left: torch.Tensor
    hflip: torch.Tensor
    vflip: torch.Tensor
    radius: torch.Tensor


def plan_epoch(
    data: FrameSet, fg_table: Foreground, settings: UNetTrainSettings, gen: torch.Generator
) -> EpochPlan:
    """Draw the order, crops, flips and radii of one epoch from ``gen`` (the only randomness in training)."""
    n = len(data)
    sizes = sorted(set(data.sizes))
    h, w = sizes[0]
    if not settings.crop and len(sizes) > 1:
        raise NeuralaoError(f"crop 0 (whole frames) needs frames of one size, not {len(sizes)}: set a crop")
    c = settings.crop or min(h, w)
    small_h, small_w = min(sizes, key=min)  # the frame with the shortest side
    if settings.crop and settings.crop > min(small_h, small_w):
        raise NeuralaoError(
            f"crop {settings.crop} is larger than the frames ({small_w}x{small_h}); "
            f"set crop<= {min(small_h, small_w)} or 0"
        )
    frames = torch.cat([torch.randperm(n, generator=gen) for _ in range(settings.crops_per_frame)])
    s = len(frames)
    tries = 8
    if len(sizes) == 1:
        tops = torch.randint(0, h - c + 1, (s, tries), generator=gen)
        lefts = torch.randint(0, w - c + 1, (s, tries), generator=gen)
    else:  # each frame's own range: uniform draws scaled to it (float64: never reaches the range's end)
        hw = torch.tensor(data.sizes, dtype=torch.float64)[frames] - c + 1
        tops = (torch.rand((s, tries), generator=gen, dtype=torch.float64) * hw[:, :1]).long()
        lefts = (torch.rand((s, tries), generator=gen, dtype=torch.float64) * hw[:, 1:]).long()
    hflip = (torch.rand(s, generator=gen) < 0.5) & settings.hflip
    vflip = (torch.rand(s, generator=gen) < 0.5) & settings.vflip
    radius = torch.randint(0, data.rho.shape[1], (s,), generator=gen)
    if settings.crop:
        fi = frames[:, None].expand(s, tries)
        fg = fg_table.count(fi, tops, lefts, c).double() / float(c * c)
        ok = fg >= settings.min_foreground
        pick = torch.where(ok.any(1), ok.to(torch.int64).argmax(1), fg.argmax(1))
        top, left = tops[torch.arange(s), pick], lefts[torch.arange(s), pick]
    else:
        top = left = torch.zeros(s, dtype=torch.int64)
    return EpochPlan(frames, top, left, hflip, vflip, radius)


def make_batch(
    data: FrameSet, plan: EpochPlan, idx: range, crop: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, list[str]]:
    """Crops + flips for samples ``idx`` of ``plan``: x (B, 4, c, c), rho (B, 1, 1, 1), y (B, 1, c, c)
    float32, m (B, 1, c, c) float32 0/1, names."""
    xs, rs, ys, ms, names = [], [], [], [], []
    for k in idx:
        f, t, l0, j = int(plan.frame[k]), int(plan.top[k]), int(plan.left[k]), int(plan.radius[k])
        ch, cw = (crop, crop) if crop else data.x[f].shape[-2:]
        x = network_input(data, f, j, (slice(t, t + ch), slice(l0, l0 + cw)))[None]
        y = data.y[f][None, j : j + 1, t : t + ch, l0 : l0 + cw].float()
        m = data.m[f][None, j : j + 1, t : t + ch, l0 : l0 + cw].float()
        if plan.hflip[k]:
            x, y, m = flip_input(x, horizontal=True), y.flip(-1), m.flip(-1)
        if plan.vflip[k]:
            x, y, m = flip_input(x, horizontal=False), y.flip(-2), m.flip(-2)
        xs.append(x)
        rs.append(data.rho[f, j].view(1, 1, 1, 1))
        ys.append(y)
        ms.append(m)
        names.append(data.names[f])
    return torch.cat(xs), torch.cat(rs), torch.cat(ys), torch.cat(ms), names


def lr_at(settings: UNetTrainSettings, step: int, total: int) -> float:
    """Learning rate of 0-based ``step`` of ``total`` under ``settings.lr_schedule``."""
    if settings.lr_schedule == "constant":
        return settings.lr
    if settings.lr_schedule != "cosine":
        raise NeuralaoError(f"lr_schedule must be 'constant' or 'cosine', got {settings.lr_schedule!r}")
    if step < settings.warmup_steps:
        return settings.lr * (step + 1) / settings.warmup_steps
    span = max(1, total - settings.warmup_steps - 1)
    t = min(1.0, (step - settings.warmup_steps) / span)
    low = settings.lr * settings.min_lr_ratio
    return low + 0.5 * (settings.lr - low) * (1.0 + math.cos(math.pi * t))


# ----------------------------------------------------------------------------------------------- metrics


def evaluate(model: UNet, data: FrameSet, device: str | torch.device = "cpu") -> dict:
    """Whole-frame validation at every radius: mean masked SSIM and RMSE over (frame, radius) pairs,
    per scene and per radius index.

    The prediction is composited like every consumer does (background -> 1) before scoring.
    """
    model.eval()
    wrapper = PaddedUNet(model)
    per = []  # (scene, radius index, ssim, rmse)
    with torch.no_grad():
        for i in range(len(data)):
            fg = foreground(data.x[i]).numpy()
            for j in range(data.rho.shape[1]):
                mask = data.m[i][j].numpy()
                if not mask.any():
                    continue
                x = network_input(data, i, j)[None]
                pred = wrapper(x.to(device), data.rho[i, j].view(1, 1, 1, 1).to(device))[0, 0].cpu().numpy()
                pred = np.where(fg, pred, 1.0).astype(np.float32)  # background -> 1
                ref = data.y[i][j].float().numpy()
                per.append(
                    (
                        data.scenes[i],
                        j,
                        float(masked_ssim(pred, ref, mask)),
                        float(masked_rmse(pred, ref, mask)),
                    )
                )
    if not per:
        return {}

    def mean(rows, k):
        return float(np.mean([r[k] for r in rows]))

    scenes = sorted({r[0] for r in per})
    radii = sorted({r[1] for r in per})
    return {
        "val_ssim": mean(per, 2),
        "val_rmse": mean(per, 3),
        "val_frames": len(data),
        "val_pairs": len(per),
        "per_scene": {
            s: {
                "ssim": mean([r for r in per if r[0] == s], 2),
                "rmse": mean([r for r in per if r[0] == s], 3),
            }
            for s in scenes
        },
        "per_radius": [
            {
                "index": j,
                "ssim": mean([r for r in per if r[1] == j], 2),
                "rmse": mean([r for r in per if r[1] == j], 3),
            }
            for j in radii
        ],
    }


def validation_subset(data: FrameSet | None, count: int) -> FrameSet | None:
    """At most ``count`` frames of ``data``, evenly spaced (all when count is 0 or larger than the set)."""
    if data is None or count <= 0 or count >= len(data):
        return data
    return data.subset([int(i * len(data) / count) for i in range(count)])


# ----------------------------------------------------------------------------------------------- checkpoints


def partial_path(out: Path) -> Path:
    return out.with_name(out.name + ".partial")


def load_checkpoint(path: str | Path) -> dict:
    """Load a U-Net checkpoint with ``weights_only=True``; another kind or a corrupt file is a one-line
    error."""
    return _load_checkpoint(path, KIND, "a U-Net", FORMAT_VERSION)


def model_from_checkpoint(ckpt: dict) -> UNet:
    return restore_model(build_model, ckpt)


def _resume_key(config: dict, dataset_hash: str | None) -> dict:
    """What must match for a checkpoint to be continued: everything but the device, and under a constant
    learning rate but the epoch count and the budget (a continued run may then add epochs: no step's rate
    depends on where the run ends)."""
    constant = config.get("lr_schedule", "constant") == "constant"
    free = {"device"} | ({"epochs", "budget_minutes"} if constant else set())
    return {"config": {k: v for k, v in config.items() if k not in free}, "dataset_hash": dataset_hash}


def extended_plan(plan_info: dict, settings: UNetTrainSettings) -> dict:
    """The plan of a constant-rate budget run continued with a larger budget: its epochs grow in
    proportion, at the step cost measured when the run started (so the epochs it already has, and the
    snapshots a learning curve takes of them, stay where they were). Any other run keeps its plan."""
    old = float(plan_info.get("budget_minutes") or 0.0)
    if settings.lr_schedule != "constant" or old <= 0 or settings.budget_minutes <= old:
        return plan_info
    epochs = int(plan_info["epochs"])
    grown = min(settings.epochs, max(epochs, math.floor(epochs * settings.budget_minutes / old)))
    return dict(plan_info, epochs=grown, budget_minutes=settings.budget_minutes, extended_from=epochs)


def _find_resumable(out: Path, key: dict, epochs: int) -> dict | None:
    for path in (partial_path(out), out):
        if not path.exists():
            continue
        ckpt = load_checkpoint(path)
        if _resume_key(ckpt["config"], ckpt.get("dataset", {}).get("dataset_hash")) != key:
            log.warning("%s was trained with another config or dataset; starting over", path)
            continue
        if "optimizer" not in ckpt or "rng" not in ckpt:
            continue
        if ckpt["epoch"] > epochs:
            log.warning(
                "%s has %d epochs, more than the %d asked; starting over", path, ckpt["epoch"], epochs
            )
            continue
        log.info("resuming from %s (epoch %d of %d)", path, ckpt["epoch"], epochs)
        return ckpt
    return None


# ----------------------------------------------------------------------------------------------- training


def pick_device(name: str) -> torch.device:
    """ "auto" -> CUDA when torch sees a device, else the CPU; "cuda" without one is an error."""
    if name not in ("auto", "cpu", "cuda"):
        raise NeuralaoError(f"device must be auto, cpu or cuda, got {name!r}")
    if name == "cuda" and not torch.cuda.is_available():
        raise NeuralaoError("device cuda asked but torch sees no CUDA device")
    return torch.device("cuda" if name != "cpu" and torch.cuda.is_available() else "cpu")


def model_args_of(settings: UNetTrainSettings) -> UNetArgs:
    return UNetArgs(
        in_channels=len(
            input_channels(
                int(settings.preprocess_version), bool(settings.gtao_input), bool(settings.gtao_raw_input)
            )
        ),
        widths=list(settings.widths),
        negative_slope=settings.negative_slope,
        radius_input=True,
        scale=int(settings.scale),
        refine_width=int(settings.refine_width),
        gtao_input=bool(settings.gtao_input),
        gtao_blur=bool(settings.gtao_blur),
        gtao_raw_input=bool(settings.gtao_raw_input),
        preprocess_version=int(settings.preprocess_version),
    )


def _init_weights(model: UNet, path: str) -> dict:
    """Copy every tensor of checkpoint ``path`` whose name and shape match; returns what was copied."""
    src = load_checkpoint(path)["state_dict"]
    own = model.state_dict()
    copied = {k: v for k, v in src.items() if k in own and own[k].shape == v.shape}
    own.update(copied)
    model.load_state_dict(own)
    return {"path": str(path), "tensors": len(copied), "of": len(own)}


def _step(model, opt, xb, rb, yb, mb, kw, where: str, lr: float) -> float:
    if not (torch.isfinite(xb).all() and torch.isfinite(yb).all()):
        raise NeuralaoError(f"non-finite (NaN/inf) input or label in {where}; fix the dataset")
    loss = training_loss(PaddedUNet(model)(xb, rb), yb, mb, **kw)
    if not torch.isfinite(loss):
        raise NeuralaoError(
            f"loss is {float(loss.detach())} in {where}; lower lr (now {lr:g}) or check the data"
        )
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
    return float(loss.detach())


def calibrate(
    model: UNet,
    settings: UNetTrainSettings,
    train_set: FrameSet,
    val_set: FrameSet | None,
    sat: Foreground,
    device: torch.device,
    steps: int = 10,
) -> dict:
    """Seconds per training step and per validation pass, measured on a COPY of the model and optimizer
    with batches from a separate generator (the run's own state and randomness are untouched). A step's
    seconds are its batch's reading and cropping (``seconds_data``: page faults, where the prepared frames
    do not fit in memory) and its forward and backward pass (``seconds_compute``), each the median of the
    steps after the first two."""
    probe = copy.deepcopy(model)
    opt = torch.optim.Adam(probe.parameters(), lr=settings.lr, weight_decay=settings.weight_decay)
    plan = plan_epoch(train_set, sat, settings, torch.Generator().manual_seed(settings.seed + 7919))
    kw = _loss_kw(settings)
    data, compute = [], []
    for k in range(steps + 2):
        idx = range(k * settings.batch_size, min((k + 1) * settings.batch_size, len(plan.frame)))
        if not len(idx):
            break
        t0 = time.perf_counter()
        xb, rb, yb, mb, _ = make_batch(train_set, plan, idx, settings.crop)
        data.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        probe.train()
        _step(
            probe,
            opt,
            xb.to(device),
            rb.to(device),
            yb.to(device),
            mb.to(device),
            kw,
            "calibration",
            settings.lr,
        )
        compute.append(time.perf_counter() - t0)
    seconds_data = float(np.median(data[2:] or data))  # the first steps warm up allocators
    seconds_compute = float(np.median(compute[2:] or compute))
    t0 = time.perf_counter()
    if val_set is not None:
        evaluate(probe, val_set, device)
    return {
        "seconds_per_step": seconds_data + seconds_compute,
        "seconds_data": seconds_data,
        "seconds_compute": seconds_compute,
        "val_seconds": time.perf_counter() - t0,
    }


def epoch_steps(settings: UNetTrainSettings, frames: int) -> int:
    """Optimiser steps an epoch takes over ``frames`` training frames (the last batch may be short)."""
    return -(-frames * settings.crops_per_frame // settings.batch_size)


def plan_budget(settings: UNetTrainSettings, steps_per_epoch: int, cal: dict) -> int:
    """Epochs that fit ``budget_minutes`` at the calibrated cost (at least 1, at most ``epochs``)."""
    per_epoch = steps_per_epoch * cal["seconds_per_step"] + cal["val_seconds"]
    return int(max(1, min(settings.epochs, math.floor(settings.budget_minutes * 60.0 / per_epoch))))


def _pixel_bytes(args: UNetArgs, training: bool) -> float:
    """Bytes one pixel of a crop (``training``) or of a validation frame takes through the network."""
    channels = sum(int(w) / 4.0**i for i, w in enumerate(args.widths))
    return (ACTIVATION_BYTES if training else EVAL_ACTIVATION_BYTES) * channels + FRAME_PIXEL_BYTES


def check_crops(settings: UNetTrainSettings, args: UNetArgs, height: int, width: int, what: str) -> None:
    """The SSIM window within crops of ``height`` x ``width`` pixels (``what`` says what sets the size) and a
    batch of them within the memory."""
    side = min(height, width)
    if side < 3:
        raise NeuralaoError(f"{what} ({width}x{height}) is smaller than the smallest SSIM window, 3 pixels")
    window = settings.ssim_window
    if isinstance(window, bool) or not isinstance(window, int) or not 3 <= window <= side or window % 2 == 0:
        raise NeuralaoError(
            f"ssim_window must be an odd number of pixels in [3, {side}] ({what}: {width}x{height}), got "
            f"{window!r}"
        )
    check_count(
        "batch_size",
        settings.batch_size * height * width,
        bytes_each=_pixel_bytes(args, training=True),
        each=f"per pixel of a {width}x{height} crop through widths {list(args.widths)}",
        shown=f"{settings.batch_size} (crops of {width}x{height})",
    )


def check_settings(settings: UNetTrainSettings) -> None:
    """Every setting in its range, and the model, a batch and a frame at the internal height within the
    memory, before any frame is read or prepared: one line naming the setting otherwise."""
    s = settings
    check_count("epochs", s.epochs, bytes_each=HISTORY_BYTES, each="a record of the history")
    check_int_range("batch_size", s.batch_size, 1, MAX_CAP)
    check_count("crops_per_frame", s.crops_per_frame, bytes_each=PLAN_BYTES, each="per crop of the plan")
    # Any rate > 0: one that makes the run diverge ends it at the first non-finite loss, naming the epoch,
    # batch and frames (the guard's test trains at 1e20), so only its sign is refused here.
    check_finite_number("lr", s.lr, low=0.0)
    check_interval("weight_decay", s.weight_decay, 0.0, 1.0)
    check_interval("min_foreground", s.min_foreground, 0.0, 1.0)
    check_interval("negative_slope", s.negative_slope, 0.0, 1.0, open_high=True)
    check_finite_number("ssim_sigma", s.ssim_sigma, low=0.0)
    check_interval("ssim_c1", s.ssim_c1, 0.0, 1.0, open_low=True)
    check_interval("ssim_c2", s.ssim_c2, 0.0, 1.0, open_low=True)
    check_interval("mse_weight", s.mse_weight, 0.0, 1e6)
    check_seed("seed", s.seed)
    check_threads("threads", s.threads)
    lr_at(s, 0, 1)  # validates the schedule name
    check_int_range("warmup_steps", s.warmup_steps, 0, MAX_CAP)
    check_interval("min_lr_ratio", s.min_lr_ratio, 0.0, 1.0)
    check_interval("budget_minutes", s.budget_minutes, 0.0, 1e9)
    check_interval("train_fraction", s.train_fraction, 0.0, 1.0, open_low=True)
    check_int_range("val_frames", s.val_frames, 0, MAX_CAP)
    check_version(s.preprocess_version, "preprocess_version")
    args = model_args_of(s)
    with torch.device("meta"):  # the architecture checked and counted, nothing allocated
        check_parameters("widths", UNet(args), str(list(s.widths)))
    height = s.internal_height
    if isinstance(height, bool) or not isinstance(height, int):
        height = -1  # refused below, as any other height outside the range
    if height and not MIN_INTERNAL_HEIGHT <= height <= MAX_INTERNAL_HEIGHT:
        raise NeuralaoError(
            f"internal_height must be 0 (every frame at its own size) or an integer in "
            f"[{MIN_INTERNAL_HEIGHT}, {MAX_INTERNAL_HEIGHT}], got {s.internal_height!r}"
        )
    if height:
        check_count(
            "internal_height",
            height * height,
            bytes_each=_pixel_bytes(args, training=False),
            each="per pixel of a frame at that height, at least as wide",
            shown=str(height),
        )
    crop = check_int_range("crop", s.crop, 0, MAX_INTERNAL_HEIGHT)
    if crop % args.pad_multiple:
        raise NeuralaoError(f"crop {crop} must be a multiple of {args.pad_multiple} (scale * 2**depth)")
    if crop:
        check_crops(s, args, crop, crop, "the crop")
    elif height:
        check_crops(s, args, height, height, "whole frames at internal_height, at least")
    pick_device(s.device)


def check_frames(settings: UNetTrainSettings, args: UNetArgs, train_set: FrameSet) -> None:
    """What the loaded frames decide: whole frames (crop 0) all of one size, the SSIM window and a batch
    within them, and an epoch's plan within the memory."""
    sizes = sorted(set(train_set.sizes))
    if not settings.crop and sizes:
        if len(sizes) > 1:
            raise NeuralaoError(
                f"crop 0 (whole frames) needs frames of one size, not {len(sizes)}: set a crop"
            )
        check_crops(settings, args, *sizes[0], "whole frames")
    elif sizes:
        small_h, small_w = min(sizes, key=min)  # the frame with the shortest side
        if settings.crop > min(small_h, small_w):
            raise NeuralaoError(
                f"crop {settings.crop} is larger than the frames ({small_w}x{small_h}); "
                f"set crop<= {min(small_h, small_w)} or 0"
            )
    check_count(
        "crops_per_frame",
        len(train_set) * settings.crops_per_frame,
        bytes_each=PLAN_BYTES,
        each="per crop of an epoch's plan",
        shown=f"{settings.crops_per_frame} (of {len(train_set)} frames)",
    )


def check_run(settings: UNetTrainSettings, out: Path, restart: bool) -> None:
    """:func:`check_settings`, the checkpoint to start from, and ``out`` (never overwrite a checkpoint of
    another kind): what `neuralao train unet` checks before it reads the dataset."""
    check_settings(settings)
    if settings.init:
        load_checkpoint(settings.init)
    if Path(out).exists() and not restart:
        load_checkpoint(out)  # refuse to overwrite a checkpoint of another kind (raises)


def train(
    settings: UNetTrainSettings,
    train_set: FrameSet,
    val_set: FrameSet | None,
    out: Path,
    dataset_info: dict | None = None,
    restart: bool = False,
    progress: bool = False,
    on_epoch_end: Callable[[int, dict], None] | None = None,
) -> dict:
    """Train (or continue training) and write the final checkpoint to ``out``. Returns the checkpoint dict.

    ``on_epoch_end(epoch, ckpt)`` runs after each epoch's checkpoint is on disk (tests use it to
    simulate an interruption).
    """
    out = Path(out)
    check_run(settings, out, restart)
    args = model_args_of(settings)
    check_frames(settings, args, train_set)
    device = pick_device(settings.device)
    info = dict(dataset_info or {})
    loaded_for = info.get("preprocess_version", settings.preprocess_version)
    if int(loaded_for) != int(settings.preprocess_version):
        raise NeuralaoError(
            f"the frames were preprocessed for input contract {loaded_for}, the model is trained for "
            f"{settings.preprocess_version}; load them with version={settings.preprocess_version}"
        )
    info.setdefault("training_scenes", sorted(set(train_set.scenes)))
    info.setdefault("val_scenes", sorted(set(val_set.scenes)) if val_set is not None else [])
    config = settings_to_dict(settings)
    key = _resume_key(config, info.get("dataset_hash"))
    val_set = validation_subset(val_set, settings.val_frames)

    prev_det = torch.are_deterministic_algorithms_enabled()
    prev_threads = torch.get_num_threads()
    if device.type == "cuda":
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # deterministic cuBLAS
    torch.use_deterministic_algorithms(True)
    if settings.threads:
        torch.set_num_threads(settings.threads)
    try:
        torch.manual_seed(settings.seed)
        model = UNet(args)
        init_info = _init_weights(model, settings.init) if settings.init else None
        model.to(device)
        opt = torch.optim.Adam(model.parameters(), lr=settings.lr, weight_decay=settings.weight_decay)
        gen = torch.Generator().manual_seed(settings.seed)
        history: list[dict] = []
        start, wall = 0, 0.0
        plan_info: dict = {}
        resumed = None if restart else _find_resumable(out, key, settings.epochs)
        sat = Foreground.of(train_set)
        steps_per_epoch = epoch_steps(settings, len(train_set))
        if resumed is not None:
            model.load_state_dict(resumed["state_dict"])
            opt.load_state_dict(resumed["optimizer"])
            gen.set_state(resumed["rng"]["data"])
            torch.set_rng_state(resumed["rng"]["torch"])
            history = list(resumed["history"])
            start = int(resumed["epoch"])
            wall = float(resumed.get("wall_seconds", 0.0))
            planned = dict(resumed.get("plan", {}))
            if settings.budget_minutes > 0 and planned.get("budget_minutes"):
                # a budget run follows the plan it made when it started (grown with its budget)
                plan_info = extended_plan(planned, settings)
        if not plan_info:
            epochs = settings.epochs
            plan_info = {"epochs": epochs, "steps_per_epoch": steps_per_epoch}
            if settings.budget_minutes > 0:
                cal = calibrate(model, settings, train_set, val_set, sat, device)
                epochs = plan_budget(settings, steps_per_epoch, cal)
                plan_info = {
                    "epochs": epochs,
                    "steps_per_epoch": steps_per_epoch,
                    "budget_minutes": settings.budget_minutes,
                    **cal,
                }
                log.info(
                    "budget %.1f min: %.3f s/step, %.1f s/validation -> %d epochs of %d steps",
                    settings.budget_minutes,
                    cal["seconds_per_step"],
                    cal["val_seconds"],
                    epochs,
                    steps_per_epoch,
                )
        epochs = int(plan_info["epochs"])
        total_steps = epochs * steps_per_epoch
        kw = _loss_kw(settings)
        ckpt = resumed
        bar = tqdm(range(start, epochs), desc="unet", unit="epoch", disable=not progress)
        for epoch in bar:
            t0 = time.perf_counter()
            model.train()
            plan = plan_epoch(train_set, sat, settings, gen)
            n = len(plan.frame)
            batches = [range(i, min(i + settings.batch_size, n)) for i in range(0, n, settings.batch_size)]
            losses = []
            for b, idx in enumerate(batches):
                step = epoch * steps_per_epoch + b
                lr = lr_at(settings, step, total_steps)
                for g in opt.param_groups:
                    g["lr"] = lr
                xb, rb, yb, mb, names = make_batch(train_set, plan, idx, settings.crop)
                where = (
                    f"epoch {epoch + 1} batch {b + 1}/{len(batches)} (frames {', '.join(sorted(set(names)))})"
                )
                losses.append(
                    _step(
                        model, opt, xb.to(device), rb.to(device), yb.to(device), mb.to(device), kw, where, lr
                    )
                )
            train_seconds = time.perf_counter() - t0
            metrics = evaluate(model, val_set, device) if val_set is not None else {}
            seconds = time.perf_counter() - t0
            wall += seconds
            record = {
                "epoch": epoch + 1,
                "train_loss": float(np.mean(losses)),
                "lr": lr,
                "train_seconds": train_seconds,
                "seconds": seconds,
                "wall_seconds": wall,
                **{k: v for k, v in metrics.items() if k not in ("per_scene", "per_radius")},
            }
            history.append(record)
            log.info(
                "epoch %d/%d  loss %.4f  lr %.2g  val ssim %s  rmse %s  (%.1f s, %.1f min in all)",
                epoch + 1,
                epochs,
                record["train_loss"],
                lr,
                f"{metrics['val_ssim']:.4f}" if metrics else "-",
                f"{metrics['val_rmse']:.4f}" if metrics else "-",
                seconds,
                wall / 60.0,
            )
            bar.set_postfix(
                loss=f"{record['train_loss']:.4f}", val_ssim=f"{metrics.get('val_ssim', float('nan')):.4f}"
            )
            ckpt = {
                "kind": KIND,
                "format_version": FORMAT_VERSION,
                "model_args": model_args_dict(args),
                "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
                "config": config,
                "preprocess": dict(DESCRIPTIONS[int(args.preprocess_version)]),
                "dataset": info,
                "metrics": metrics,
                "history": history,
                "epoch": epoch + 1,
                "plan": plan_info,
                "init": init_info,
                "wall_seconds": wall,
                "device": device.type,
                "complete": epoch + 1 == epochs,
                "optimizer": opt.state_dict(),
                "rng": {"data": gen.get_state(), "torch": torch.get_rng_state()},
                "torch_version": str(torch.__version__),
            }
            save_checkpoint(partial_path(out), ckpt)
            if on_epoch_end is not None:
                on_epoch_end(epoch + 1, ckpt)
        bar.close()
    finally:
        torch.use_deterministic_algorithms(prev_det)
        torch.set_num_threads(prev_threads)
    assert ckpt is not None
    ckpt["complete"] = True
    save_checkpoint(out, ckpt)
    partial_path(out).unlink(missing_ok=True)
    return ckpt
