"""Checkpoints of both models: plain-data dicts written atomically, read back with ``weights_only=True``.

A checkpoint is ``{"kind": "mlp" | "unet", "model_args", "state_dict", "config", ...}`` (nanoGPT's
self-describing habit): the file alone rebuilds the model. Only ``torch.load(weights_only=True)`` ever
reads one, so a file from elsewhere cannot run code.
"""

from __future__ import annotations

import os
import pickle
import re
import warnings
from collections.abc import Callable
from pathlib import Path

import torch
from torch import nn

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path
from neuralao.runtime.foundation.limits import check_count, check_finite_number, check_int_range

REQUIRED_KEYS = ("model_args", "state_dict", "config")
# Bytes per weight of a model being built or trained: the float32 weight, its gradient, Adam's two moments,
# the best-weights copy and the checkpoint's copies of weights and optimizer state, generously.
WEIGHT_BYTES = 64
# The largest learning rate any trainer takes: Adam moves every weight by about lr per step, so past 1 a
# step is larger than the weights it changes (the run diverges at once).
MAX_LR = 1.0


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


def check_interval(
    name: str, value: object, low: float, high: float, *, open_low: bool = False, open_high: bool = False
) -> float:
    """A finite number in [low, high] (an end excluded where ``open_low`` / ``open_high``), else one line
    naming ``name`` and the interval."""
    shown = f"{'(' if open_low else '['}{low:g}, {high:g}{')' if open_high else ']'}"
    number = check_finite_number(name, value)
    above = low < number if open_low else low <= number
    below = number < high if open_high else number <= high
    if not (above and below):
        raise NeuralaoError(f"{name} must be a number in {shown}, got {value!r}")
    return number


def check_lr(name: str, value: object) -> float:
    """An Adam learning rate: in (0, MAX_LR]."""
    return check_interval(name, value, 0.0, MAX_LR, open_low=True)


def check_threads(name: str, value: object) -> int:
    """A torch thread count: 0 (torch's default) up to the machine's CPUs (more only time-slice the same
    cores, and spin-waiting threads made training many times slower)."""
    return check_int_range(name, value, 0, os.cpu_count() or 1)


def check_parameters(name: str, model: nn.Module, shown: str) -> int:
    """The weights of ``model`` (built on the meta device: shapes only) within the memory, WEIGHT_BYTES
    each; ``shown`` is what the user gave (the widths, the model_args)."""
    weights = count_parameters(model) + sum(b.numel() for b in model.buffers())
    return check_count(
        name, weights, bytes_each=WEIGHT_BYTES, each="per weight", shown=f"{shown} ({weights} weights)"
    )


def save_checkpoint(path: str | Path, ckpt: dict) -> None:
    with atomic_path(path) as tmp:
        torch.save(ckpt, tmp)


def read_checkpoint(path: str | Path) -> dict:
    """The raw checkpoint dict (``weights_only=True``); a missing, corrupt or unsafe file is a one-line
    error; torch's warnings about the file (an unusual pickle protocol) are not shown, the error says it."""
    p = Path(path)
    if not p.is_file():
        raise NeuralaoError(f"checkpoint not found: {p}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ckpt = torch.load(p, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        found = re.search(r"GLOBAL (\S+)", str(e))
        if found:
            raise NeuralaoError(
                f"cannot read checkpoint {p}: it is not a neuralao checkpoint: it holds Python objects "
                f"({found.group(1)}) that neuralao never unpickles (it reads tensors and plain data only, "
                "with torch's weights_only loader)"
            ) from None
        raise NeuralaoError(
            f"cannot read checkpoint {p}: it is not a neuralao checkpoint (not a file torch.save wrote; "
            "checked with torch's weights_only loader)"
        ) from None
    except Exception:
        raise NeuralaoError(
            f"cannot read checkpoint {p}: it is not a neuralao checkpoint, or one cut short or damaged "
            "(not a whole file torch.save wrote)"
        ) from None
    return ckpt if isinstance(ckpt, dict) else {}


def load_checkpoint(path: str | Path, kind: str, label: str, format_version: int = 1) -> dict:
    """A checkpoint of ``kind`` (``label`` names it in messages, e.g. "an MLP"), with its required keys of
    the right types, written in a format up to ``format_version`` (the newest this code reads)."""
    p = Path(path)
    ckpt = read_checkpoint(p)
    found = ckpt.get("kind")
    if found != kind:
        raise NeuralaoError(f"{p} is not {label} checkpoint (kind {found!r}, expected {kind!r})")
    what = f"{label.split(' ', 1)[1]} checkpoint {p}"
    for key in REQUIRED_KEYS:
        if key not in ckpt:
            raise NeuralaoError(f"{what} lacks {key!r}")
    version = ckpt.get("format_version", 1)
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= format_version:
        raise NeuralaoError(
            f"{what} is in checkpoint format {version!r}, which this neuralao does not read (it reads "
            f"format 1 to {format_version}): a newer neuralao wrote it, or it is not a neuralao checkpoint"
        )
    for key in ("model_args", "state_dict", "config"):
        if not isinstance(ckpt[key], dict):
            raise NeuralaoError(f"{what}: {key!r} must be a mapping, got {type(ckpt[key]).__name__}")
    for name, value in ckpt["state_dict"].items():
        if not isinstance(name, str) or not isinstance(value, torch.Tensor):
            raise NeuralaoError(f"{what}: state_dict entry {name!r} is not a named tensor")
    return ckpt


def check_finished(ckpt: dict, path: str | Path) -> None:
    """Refuse the checkpoint of a training that has not finished (a ``.partial`` progress file, or one
    whose ``complete`` is false): its weights are those of some epoch on the way, not the model."""
    p = Path(path)
    plan = ckpt.get("plan") if isinstance(ckpt.get("plan"), dict) else {}
    where = f" (epoch {ckpt['epoch']} of {plan['epochs']})" if "epoch" in ckpt and "epochs" in plan else ""
    if p.name.endswith(".partial") or ckpt.get("complete") is False:
        final = p.name.removesuffix(".partial")
        raise NeuralaoError(
            f"{p} is the checkpoint of a training that has not finished{where}: rerun the same "
            f"`neuralao train` command to finish it (it resumes), then use {final}"
        )


def _weights_mismatch(own: dict, given: dict) -> str | None:
    """The first difference between the tensors a model has (``own``: name -> tensor) and the ones given,
    in words; None when every name and shape matches."""
    for name, tensor in own.items():
        if name not in given:
            missing = [k for k in own if k not in given]
            more = f" (and {len(missing) - 1} more of {len(own)})" if len(missing) > 1 else ""
            return f"tensor {name!r} is missing{more}"
        if tuple(given[name].shape) != tuple(tensor.shape):
            return (
                f"tensor {name!r} has shape {tuple(given[name].shape)}, the model_args make it "
                f"{tuple(tensor.shape)}"
            )
    extra = [k for k in given if k not in own]
    if extra:
        more = f" (and {len(extra) - 1} more)" if len(extra) > 1 else ""
        return f"tensor {extra[0]!r} is not one of the model's{more}"
    return None


def restore_model(build: Callable[[dict], nn.Module], ckpt: dict) -> nn.Module:
    """``build(model_args)`` with the checkpoint's weights loaded, in eval mode.

    The model is first built on the meta device (shapes, nothing allocated): model_args that describe no
    model, a model past the memory, or weights of other names or shapes are one-line errors before any
    weight is allocated."""
    args = ckpt["model_args"]
    if not isinstance(args, dict):
        raise NeuralaoError(f"checkpoint model_args must be a mapping, got {type(args).__name__}")
    try:
        with torch.device("meta"):
            shapes = build(args)
    except NeuralaoError as e:
        raise NeuralaoError(f"checkpoint model_args {str(args)[:200]}: {e}") from None
    except (TypeError, ValueError, KeyError, RuntimeError) as e:
        raise NeuralaoError(f"checkpoint model_args {str(args)[:200]} describe no model: {e}") from None
    check_parameters("checkpoint model_args", shapes, str(args)[:200])
    mismatch = _weights_mismatch(shapes.state_dict(), ckpt["state_dict"])
    if mismatch:
        raise NeuralaoError(f"checkpoint weights do not fit its model_args: {mismatch}")
    model = build(args)
    try:
        model.load_state_dict(ckpt["state_dict"])
    except RuntimeError as e:
        raise NeuralaoError(
            f"checkpoint weights do not fit its model_args: {str(e).splitlines()[0]}"
        ) from None
    return model.eval()
