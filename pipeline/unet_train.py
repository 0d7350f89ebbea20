"""`neuralao train unet`: train the DeepAO U-Net with a masked 1 - SSIM loss; resumable, deterministic.

Data: frames of the dataset's ``train`` scenes (held-back views excluded), preprocessed ONCE per
whole frame with :func:`pipeline.unet.preprocess` (so the depth normalisation of a crop is that of
its frame, exactly as at run time), then random square crops with horizontal / vertical flips
(flips negate n_x / n_y). Validation: whole frames of the ``val`` scenes every epoch (held-back
views of the training scenes when the dataset has no val scene).

Loss: 1 - SSIM (Gaussian window 11, sigma 1.5, C1 = 1e-4, C2 = 9e-4) averaged over the pixels
whose label is valid; before SSIM the prediction is replaced by the label outside the mask, so
background never enters the statistics of a window. A constant crop gives SSIM = 1 (C1, C2 keep
the ratio finite); a batch without any valid pixel gives a zero loss.

Checkpoints: written atomically after every epoch to ``OUT.partial`` (model, optimizer, RNG
states, history); the final one is renamed onto ``OUT`` at the end, so an interrupted run leaves
no ``OUT`` (make reruns the target) and a rerun continues from the partial file. Every random
choice comes from one seeded generator whose state is checkpointed, so interrupted + resumed
equals uninterrupted bit for bit (same machine and thread count).
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from .checkpoint import load_checkpoint as _load_checkpoint
from .checkpoint import restore_model, save_checkpoint
from .config import add_set_option, load_settings, settings_to_dict
from .errors import NeuralaoError
from .unet import (
    PREPROCESS_DESCRIPTION,
    PaddedUNet,
    UNet,
    UNetArgs,
    build_model,
    model_args_dict,
    preprocess_frame,
)

log = logging.getLogger(__name__)

KIND = "unet"
FORMAT_VERSION = 1


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
    seed: int = 0  # seeds weight init (torch.manual_seed) and the crop / flip / order generator
    threads: int = 0  # torch intra-op threads (0 = torch's default); fixed for bitwise-reproducible runs


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


def _ssim_kw(settings: UNetTrainSettings) -> dict:
    return {
        "window": settings.ssim_window,
        "sigma": settings.ssim_sigma,
        "c1": settings.ssim_c1,
        "c2": settings.ssim_c2,
    }


# ----------------------------------------------------------------------------------------------- data


@dataclass
class FrameSet:
    """Preprocessed frames in memory.

    x : (N, 4, H, W) float32 network input; y : (N, 1, H, W) float32 AO labels;
    m : (N, 1, H, W) float32 valid mask (0/1); names : N strings "scene/view".
    """

    x: torch.Tensor
    y: torch.Tensor
    m: torch.Tensor
    names: list[str]
    scenes: list[str]

    def __len__(self) -> int:
        return len(self.names)


def frames_to_set(frames: list[dict]) -> FrameSet:
    """Frame dicts (COMMON.md format, with ao and valid) -> :class:`FrameSet` (all frames one size)."""
    if not frames:
        raise NeuralaoError("no frames to train or validate on")
    shapes = {f["depth"].shape for f in frames}
    if len(shapes) != 1:
        raise NeuralaoError(f"frames have different sizes {sorted(shapes)}; use one size per dataset")
    xs, ys, ms, names, scenes = [], [], [], [], []
    for i, f in enumerate(frames):
        if "ao" not in f or "valid" not in f:
            raise NeuralaoError(
                f"frame {f.get('scene', '?')}/{f.get('view', i)} has no AO labels ('ao', 'valid')"
            )
        xs.append(preprocess_frame(f))
        ys.append(np.asarray(f["ao"], dtype=np.float32)[None])
        ms.append(
            (np.asarray(f["valid"], dtype=bool) & np.asarray(f["mask"], dtype=bool)).astype(np.float32)[None]
        )
        scene = str(f.get("scene", "frames"))
        names.append(f"{scene}/{f.get('view', i)}")
        scenes.append(scene)
    return FrameSet(
        torch.from_numpy(np.stack(xs)),
        torch.from_numpy(np.stack(ys)),
        torch.from_numpy(np.stack(ms)),
        names,
        scenes,
    )


def load_dataset_frames(data: Path) -> tuple[FrameSet, FrameSet | None, dict]:
    """Train frames (train scenes, held-back views excluded), validation frames and dataset info."""
    from .dataset import open_dataset

    ds = open_dataset(data)
    train = list(ds.frames(split="train", holdout=False))
    if not train:
        raise NeuralaoError(f"dataset {data} has no training frames (no scene with split 'train')")
    val = list(ds.frames(split="val"))
    val_source = "val scenes"
    if not val:
        val = list(ds.frames(split="train", holdout=True))
        val_source = "held-back views of the training scenes (the dataset has no val scene)"
    info = {
        "path": str(data),
        "name": ds.manifest.get("name"),
        "dataset_hash": ds.manifest.get("dataset_hash"),
        "labels": ds.manifest.get("config", {}).get("labels"),
        "training_scenes": sorted({f["scene"] for f in train}),
        "val_scenes": sorted({f["scene"] for f in val}),
        "val_source": val_source,
        "train_frames": len(train),
        "val_frames": len(val),
    }
    return frames_to_set(train), (frames_to_set(val) if val else None), info


def _integral(m: torch.Tensor) -> torch.Tensor:
    """(N, 1, H, W) mask -> (N, H+1, W+1) float64 summed-area table."""
    s = torch.zeros(m.shape[0], m.shape[2] + 1, m.shape[3] + 1, dtype=torch.float64)
    s[:, 1:, 1:] = m[:, 0].double().cumsum(1).cumsum(2)
    return s


@dataclass
class EpochPlan:
    """Which crop of which frame each sample of an epoch uses. All (S,) int64 / bool tensors."""

    frame: torch.Tensor
    top: torch.Tensor
    left: torch.Tensor
    hflip: torch.Tensor
    vflip: torch.Tensor


def plan_epoch(
    data: FrameSet, sat: torch.Tensor, settings: UNetTrainSettings, gen: torch.Generator
) -> EpochPlan:
    """Draw the order, crops and flips of one epoch from ``gen`` (the only randomness in training)."""
    n, _, h, w = data.x.shape
    c = settings.crop or min(h, w)
    if settings.crop and (settings.crop > h or settings.crop > w):
        raise NeuralaoError(
            f"crop {settings.crop} is larger than the frames ({w}x{h}); set crop<= {min(h, w)} or 0"
        )
    frames = torch.cat([torch.randperm(n, generator=gen) for _ in range(settings.crops_per_frame)])
    s = len(frames)
    tries = 8
    tops = torch.randint(0, h - c + 1, (s, tries), generator=gen)
    lefts = torch.randint(0, w - c + 1, (s, tries), generator=gen)
    hflip = (torch.rand(s, generator=gen) < 0.5) & settings.hflip
    vflip = (torch.rand(s, generator=gen) < 0.5) & settings.vflip
    if settings.crop:
        fi = frames[:, None].expand(s, tries)
        fg = (
            sat[fi, tops + c, lefts + c]
            - sat[fi, tops, lefts + c]
            - sat[fi, tops + c, lefts]
            + sat[fi, tops, lefts]
        ) / float(c * c)
        ok = fg >= settings.min_foreground
        pick = torch.where(ok.any(1), ok.to(torch.int64).argmax(1), fg.argmax(1))
        top, left = tops[torch.arange(s), pick], lefts[torch.arange(s), pick]
    else:
        top = left = torch.zeros(s, dtype=torch.int64)
    return EpochPlan(frames, top, left, hflip, vflip)


def make_batch(
    data: FrameSet, plan: EpochPlan, idx: range, crop: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, list[str]]:
    """Crops + flips for samples ``idx`` of ``plan``: x (B, 4, c, c), y (B, 1, c, c), m (B, 1, c, c), names."""
    from .unet import flip_input

    xs, ys, ms, names = [], [], [], []
    h, w = data.x.shape[-2:]
    for k in idx:
        f, t, l0 = int(plan.frame[k]), int(plan.top[k]), int(plan.left[k])
        ch, cw = (crop, crop) if crop else (h, w)
        x = data.x[f : f + 1, :, t : t + ch, l0 : l0 + cw]
        y = data.y[f : f + 1, :, t : t + ch, l0 : l0 + cw]
        m = data.m[f : f + 1, :, t : t + ch, l0 : l0 + cw]
        if plan.hflip[k]:
            x, y, m = flip_input(x, horizontal=True), y.flip(-1), m.flip(-1)
        if plan.vflip[k]:
            x, y, m = flip_input(x, horizontal=False), y.flip(-2), m.flip(-2)
        xs.append(x)
        ys.append(y)
        ms.append(m)
        names.append(data.names[f])
    return torch.cat(xs), torch.cat(ys), torch.cat(ms), names


# ----------------------------------------------------------------------------------------------- metrics


def _metric_fns():
    """masked_ssim / masked_rmse from pipeline.metrics (shared with the MLP and the report)."""
    try:
        from .metrics import masked_rmse, masked_ssim
    except ImportError:  # TEMPORARY until pipeline/metrics.py lands

        def masked_ssim(pred, ref, mask):
            t = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))[None, None]  # noqa: E731
            return float(ssim_map(t(pred), t(ref))[t(mask) > 0.5].mean())

        def masked_rmse(pred, ref, mask):
            return float(np.sqrt(np.mean((pred[mask] - ref[mask]) ** 2)))

    return masked_ssim, masked_rmse


def evaluate(model: UNet, data: FrameSet) -> dict:
    """Whole-frame validation: mean masked SSIM and RMSE over frames, and per scene.

    The prediction is composited like every consumer does (background -> 1) before scoring.
    """
    masked_ssim, masked_rmse = _metric_fns()
    model.eval()
    wrapper = PaddedUNet(model)
    per_frame = []
    with torch.no_grad():
        for i in range(len(data)):
            pred = wrapper(data.x[i : i + 1])[0, 0].numpy()
            ref = data.y[i, 0].numpy()
            mask = data.m[i, 0].numpy() > 0.5
            if not mask.any():
                continue
            pred = np.where(data.x[i, 0].numpy() > 0, pred, 1.0).astype(np.float32)  # background -> 1
            per_frame.append(
                (data.scenes[i], float(masked_ssim(pred, ref, mask)), float(masked_rmse(pred, ref, mask)))
            )
    if not per_frame:
        return {}
    scenes = sorted({s for s, _, _ in per_frame})
    return {
        "val_ssim": float(np.mean([v for _, v, _ in per_frame])),
        "val_rmse": float(np.mean([v for _, _, v in per_frame])),
        "val_frames": len(per_frame),
        "per_scene": {
            s: {
                "ssim": float(np.mean([v for t, v, _ in per_frame if t == s])),
                "rmse": float(np.mean([v for t, _, v in per_frame if t == s])),
            }
            for s in scenes
        },
    }


# ----------------------------------------------------------------------------------------------- checkpoints


def partial_path(out: Path) -> Path:
    return out.with_name(out.name + ".partial")


def load_checkpoint(path: str | Path) -> dict:
    """Load a U-Net checkpoint with ``weights_only=True``; another kind or a corrupt file is a one-line error."""
    return _load_checkpoint(path, KIND, "a U-Net")


def model_from_checkpoint(ckpt: dict) -> UNet:
    return restore_model(build_model, ckpt)


def _resume_key(config: dict, dataset_hash: str | None) -> dict:
    """What must match for a checkpoint to be continued: everything but the epoch count."""
    return {"config": {k: v for k, v in config.items() if k != "epochs"}, "dataset_hash": dataset_hash}


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
    from tqdm import tqdm

    out = Path(out)
    if settings.epochs < 1 or settings.batch_size < 1 or settings.crops_per_frame < 1:
        raise NeuralaoError("epochs, batch_size and crops_per_frame must be >= 1")
    args = UNetArgs(in_channels=4, widths=list(settings.widths), negative_slope=settings.negative_slope)
    if settings.crop and settings.crop % args.pad_multiple:
        raise NeuralaoError(f"crop {settings.crop} must be a multiple of {args.pad_multiple} (2**depth)")
    if out.exists() and not restart:
        load_checkpoint(out)  # refuse to overwrite a checkpoint of another kind (raises)
    info = dict(dataset_info or {})
    info.setdefault("training_scenes", sorted(set(train_set.scenes)))
    info.setdefault("val_scenes", sorted(set(val_set.scenes)) if val_set is not None else [])
    config = settings_to_dict(settings)
    key = _resume_key(config, info.get("dataset_hash"))

    prev_det = torch.are_deterministic_algorithms_enabled()
    prev_threads = torch.get_num_threads()
    torch.use_deterministic_algorithms(True)
    if settings.threads:
        torch.set_num_threads(settings.threads)
    try:
        torch.manual_seed(settings.seed)
        model = UNet(args)
        opt = torch.optim.Adam(model.parameters(), lr=settings.lr, weight_decay=settings.weight_decay)
        gen = torch.Generator().manual_seed(settings.seed)
        history: list[dict] = []
        start = 0
        resumed = None if restart else _find_resumable(out, key, settings.epochs)
        if resumed is not None:
            model.load_state_dict(resumed["state_dict"])
            opt.load_state_dict(resumed["optimizer"])
            for g in opt.param_groups:  # a continued run may only change the epoch count
                g["lr"] = settings.lr
            gen.set_state(resumed["rng"]["data"])
            torch.set_rng_state(resumed["rng"]["torch"])
            history = list(resumed["history"])
            start = int(resumed["epoch"])
        sat = _integral(train_set.m)
        kw = _ssim_kw(settings)
        ckpt = resumed
        bar = tqdm(range(start, settings.epochs), desc="unet", unit="epoch", disable=not progress)
        for epoch in bar:
            t0 = time.perf_counter()
            model.train()
            plan = plan_epoch(train_set, sat, settings, gen)
            n = len(plan.frame)
            batches = [range(i, min(i + settings.batch_size, n)) for i in range(0, n, settings.batch_size)]
            losses = []
            for b, idx in enumerate(batches):
                xb, yb, mb, names = make_batch(train_set, plan, idx, settings.crop)
                where = (
                    f"epoch {epoch + 1} batch {b + 1}/{len(batches)} (frames {', '.join(sorted(set(names)))})"
                )
                if not (torch.isfinite(xb).all() and torch.isfinite(yb).all()):
                    raise NeuralaoError(f"non-finite (NaN/inf) input or label in {where}; fix the dataset")
                loss = masked_ssim_loss(PaddedUNet(model)(xb), yb, mb, **kw)
                if not torch.isfinite(loss):
                    raise NeuralaoError(
                        f"loss is {float(loss)} in {where}; lower lr (now {settings.lr:g}) or check the data"
                    )
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                losses.append(float(loss.detach()))
            train_seconds = time.perf_counter() - t0
            metrics = evaluate(model, val_set) if val_set is not None else {}
            record = {
                "epoch": epoch + 1,
                "train_loss": float(np.mean(losses)),
                "train_seconds": train_seconds,
                "seconds": time.perf_counter() - t0,
                **{k: v for k, v in metrics.items() if k != "per_scene"},
            }
            history.append(record)
            log.info(
                "epoch %d/%d  loss %.4f  val ssim %s  rmse %s  (%.1f s)",
                epoch + 1,
                settings.epochs,
                record["train_loss"],
                f"{metrics['val_ssim']:.4f}" if metrics else "-",
                f"{metrics['val_rmse']:.4f}" if metrics else "-",
                record["seconds"],
            )
            bar.set_postfix(
                loss=f"{record['train_loss']:.4f}", val_ssim=f"{metrics.get('val_ssim', float('nan')):.4f}"
            )
            ckpt = {
                "kind": KIND,
                "format_version": FORMAT_VERSION,
                "model_args": model_args_dict(args),
                "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
                "config": config,
                "preprocess": dict(PREPROCESS_DESCRIPTION),
                "dataset": info,
                "metrics": metrics,
                "history": history,
                "epoch": epoch + 1,
                "complete": epoch + 1 == settings.epochs,
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


# ----------------------------------------------------------------------------------------------- CLI


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--data",
        required=True,
        help="dataset folder (neuralao dataset): trains on 'train' scenes, validates on 'val'",
    )
    p.add_argument(
        "--out", required=True, help="checkpoint MODEL.pt (progress in MODEL.pt.partial; a rerun resumes)"
    )
    p.add_argument("--config", help="preset JSON of UNetTrainSettings fields")
    add_set_option(p, "--set epochs=3")
    p.add_argument(
        "--restart", action="store_true", help="ignore an existing checkpoint and train from scratch"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    settings = load_settings(UNetTrainSettings, args.config, args.set)
    train_set, val_set, info = load_dataset_frames(Path(args.data))
    log.info(
        "U-Net: %d training frames (%s), %d validation frames (%s)",
        len(train_set),
        ", ".join(info["training_scenes"]),
        len(val_set) if val_set is not None else 0,
        info["val_source"],
    )
    ckpt = train(
        settings,
        train_set,
        val_set,
        Path(args.out),
        info,
        restart=args.restart,
        progress=not args.no_progress,
    )
    hist = ckpt["history"]
    per_epoch = float(np.mean([h["seconds"] for h in hist])) if hist else math.nan
    log.info(
        "wrote %s: %d epochs, %.1f s/epoch, val SSIM %s",
        args.out,
        ckpt["epoch"],
        per_epoch,
        ckpt["metrics"].get("val_ssim"),
    )
    return 0
