"""Checkpoints of both models: plain-data dicts written atomically, read back with ``weights_only=True``.

A checkpoint is ``{"kind": "mlp" | "unet", "model_args", "state_dict", "config", ...}`` (nanoGPT's
self-describing habit): the file alone rebuilds the model. Only ``torch.load(weights_only=True)`` ever
reads one, so a file from elsewhere cannot run code.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import torch
from torch import nn

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path

REQUIRED_KEYS = ("model_args", "state_dict", "config")


def count_parameters(model: nn.Module) -> int:
    return int(sum(p.numel() for p in model.parameters()))


def per_mesh_checkpoint(
    kind: str,
    format_version: int,
    model: nn.Module,
    model_args: dict,
    config: dict,
    samples_info: dict,
    metrics: dict,
    train_info: dict,
    parameter_bytes: int,
) -> dict:
    """The checkpoint of a per-mesh network (baked MLP, AO field): model, settings, samples, metrics."""
    return {
        "kind": kind,
        "format_version": format_version,
        "model_args": model_args,
        "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
        "config": config,
        "metrics": metrics,
        "scene": samples_info.get("scene"),
        "mesh": samples_info.get("mesh"),
        "samples": samples_info,
        "training": {k: v for k, v in train_info.items() if k != "seconds"},
        "training_time_s": float(train_info["seconds"]),
        "parameters": count_parameters(model),
        "parameter_bytes": int(parameter_bytes),
        "torch_version": str(torch.__version__),
    }


def save_checkpoint(path: str | Path, ckpt: dict) -> None:
    with atomic_path(path) as tmp:
        torch.save(ckpt, tmp)


def read_checkpoint(path: str | Path) -> dict:
    """The raw checkpoint dict (``weights_only=True``); a missing, corrupt or unsafe file is a one-line
    error."""
    p = Path(path)
    if not p.is_file():
        raise NeuralaoError(f"checkpoint not found: {p}")
    try:
        ckpt = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as e:
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()] or [type(e).__name__]
        reason = next((ln for ln in lines if "Unsupported global" in ln), lines[0])
        raise NeuralaoError(f"cannot read checkpoint {p} (weights_only): {reason[:200]}") from None
    return ckpt if isinstance(ckpt, dict) else {}


def load_checkpoint(path: str | Path, kind: str, label: str) -> dict:
    """A checkpoint of ``kind`` (``label`` names it in messages, e.g. "an MLP"), with its required keys."""
    p = Path(path)
    ckpt = read_checkpoint(p)
    found = ckpt.get("kind")
    if found != kind:
        raise NeuralaoError(f"{p} is not {label} checkpoint (kind {found!r}, expected {kind!r})")
    for key in REQUIRED_KEYS:
        if key not in ckpt:
            raise NeuralaoError(f"{label.split(' ', 1)[1]} checkpoint {p} lacks {key!r}")
    return ckpt


def restore_model(build: Callable[[dict], nn.Module], ckpt: dict) -> nn.Module:
    """``build(model_args)`` with the checkpoint's weights loaded, in eval mode."""
    model = build(ckpt["model_args"])
    try:
        model.load_state_dict(ckpt["state_dict"])
    except RuntimeError as e:
        raise NeuralaoError(
            f"checkpoint weights do not fit its model_args: {str(e).splitlines()[0]}"
        ) from None
    return model.eval()
