"""`neuralao train mlp|unet|field`: the flags of each trainable kind and its training.

The subcommands are the kinds :func:`neuralao.runtime.kinds.trained` lists; each kind's entry names its
flags and run function (``train_flags``, ``train_run``), those of mlp, unet and field are here."""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

import numpy as np

from neuralao.pipeline.models import field, mlp, unet_frames, unet_train
from neuralao.runtime import kinds
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import check_count
from neuralao.runtime.foundation.paths import FILE
from neuralao.runtime.foundation.settings import add_set_option, load_settings

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other, and not inside the
# dataset, which is read whole: --out DATA/manifest.json or a shard's name would replace it with the
# checkpoint).
OUTPUTS = {"out": FILE}
INPUTS = ("mesh", "data", "config")
MESH_INPUTS = ("mesh",)  # mesh names: a file, a glTF folder or a bare name
READ_FOLDERS = ("data",)


def _log(kind: str) -> logging.Logger:
    """The lines a training writes keep the training module's logger name (the kind's ``trainer``)."""
    return logging.getLogger(kinds.KINDS[kind].trainer)


# ------------------------------------------------------------------------------------- per-mesh kinds


def add_checkpoint_arguments(p: argparse.ArgumentParser, preset: str, set_example: str) -> None:
    """The last flags of a per-mesh kind (mlp, field): the checkpoint, the settings and the progress bars.

    preset : the settings dataclass a --config file presets; set_example : the --set example in the help."""
    p.add_argument("--out", required=True, help="checkpoint to write (MODEL.pt)")
    p.add_argument("--config", help=f"JSON preset of {preset}")
    add_set_option(p, set_example)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def check_mesh_or_dataset(args: argparse.Namespace, neither: str) -> None:
    """A per-mesh kind trains on --mesh or on --data with --scene, not both; ``neither`` is the error
    when none is given."""
    if args.mesh and (args.data or args.scene):
        raise NeuralaoError("give either --mesh or --data/--scene, not both")
    if not args.mesh and not (args.data and args.scene):
        raise NeuralaoError(neither)


def figure(value: float | None) -> str:
    """A metric as the training line prints it: 4 decimals, or "-" where there was nothing to measure (no
    held-back view, an empty validation or test split)."""
    return f"{value:.4f}" if value is not None else "-"


def holdout_figures(metrics: dict) -> tuple[str, str]:
    """(SSIM, RMSE) on the held-back views as the training line prints them."""
    return figure(metrics["holdout_ssim"]), figure(metrics["holdout_rmse"])


# ----------------------------------------------------------------------------------------------- mlp


def add_mlp_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_argument_group("samples from a dataset, or directly from a mesh")
    src.add_argument("--data", help="dataset folder (with --scene): samples from its non-held-back views")
    src.add_argument("--scene", help="scene name in the dataset")
    src.add_argument(
        "--mesh", help="mesh file or name under the shared mesh folder: render and label only the samples"
    )
    d = mlp.MLPSettings()  # the help states the real defaults
    src.add_argument("--views", type=int, help=f"mesh source: orbit views to sample (default {d.views})")
    src.add_argument(
        "--resolution",
        type=int,
        nargs=2,
        metavar=("W", "H"),
        help=f"mesh source: view size in pixels (default {d.size[0]} {d.size[1]})",
    )
    src.add_argument("--rays", type=int, help=f"mesh source: AO rays per sample (default {d.labels.rays})")
    p.add_argument(
        "--size",
        default=None,
        help=f"hidden layer widths XxY, e.g. 16x8, 32x16, 64x32 (default {mlp.size_name(d.hidden)})",
    )
    add_checkpoint_arguments(p, "MLPSettings", "--set optimizer=adam")


def hidden_widths(size: str) -> list[int]:
    """``--size`` as hidden widths, each bounded by the memory its weights and activations take, so a
    width past the machine is refused naming ``--size`` (not the batch or sample count it would inflate)."""
    widths = mlp.parse_size(size)
    check_count(
        "--size", max(widths) ** 2 * len(widths), bytes_each=64, each="per weight of the network", shown=size
    )
    check_count("--size", sum(widths), bytes_each=64 * 1024, each="per unit of a hidden width", shown=size)
    return widths


def mlp_settings_from_args(args: argparse.Namespace) -> mlp.MLPSettings:
    overrides: list[str] = []
    if args.size is not None:
        overrides.append(f"hidden={hidden_widths(args.size)}")
    if getattr(args, "views", None) is not None:
        overrides.append(f"views={args.views}")
    if getattr(args, "resolution", None) is not None:
        overrides.append(f"size={list(args.resolution)}")
    if getattr(args, "rays", None) is not None:
        overrides.append(f"labels.rays={args.rays}")
    return load_settings(mlp.MLPSettings, args.config, overrides + list(args.set))


def run_mlp(args: argparse.Namespace) -> int:
    check_mesh_or_dataset(args, "give --data DIR --scene NAME, or --mesh PATH_OR_NAME")
    if args.data and (args.views is not None or args.resolution is not None or args.rays is not None):
        raise NeuralaoError("--views/--resolution/--rays apply to --mesh only (a dataset fixes them)")
    settings = mlp_settings_from_args(args)
    ckpt = mlp.train(
        settings, args.out, data=args.data, scene=args.scene, mesh=args.mesh, progress=not args.no_progress
    )
    m = ckpt["metrics"]
    _log("mlp").info(
        "wrote %s: %s, %d parameters, %.1f s, test RMSE %s (constant %s), held-back SSIM %s RMSE %s",
        args.out,
        mlp.size_name(ckpt["model_args"]["hidden"]),
        ckpt["parameters"],
        ckpt["training_time_s"],
        figure(m["test_rmse"]),
        figure(m["constant_test_rmse"]),
        *holdout_figures(m),
    )
    return 0


# ----------------------------------------------------------------------------------------------- field


def add_field_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_argument_group("the mesh: a file, or a dataset's scene (its label settings are used)")
    src.add_argument("--mesh", help="mesh file or name under the shared mesh folder")
    src.add_argument("--data", help="dataset folder (with --scene)")
    src.add_argument("--scene", help="scene name in the dataset")
    d = field.FieldSettings()  # the help states the real defaults
    p.add_argument(
        "--size",
        default=None,
        help=f"hidden tanh widths XxY, e.g. 16x8, 32x16, 64x32 (default {mlp.size_name(d.hidden)})",
    )
    p.add_argument("--octaves", type=int, help=f"position-encoding frequency bands (default {d.octaves})")
    p.add_argument("--rays", type=int, help=f"AO rays per surface sample (default {d.labels.rays})")
    add_checkpoint_arguments(p, "FieldSettings", "--set steps=3000")


def field_settings_from_args(args: argparse.Namespace) -> field.FieldSettings:
    overrides: list[str] = []
    if args.size is not None:
        overrides.append(f"hidden={hidden_widths(args.size)}")
    if args.octaves is not None:
        overrides.append(f"octaves={args.octaves}")
    if args.rays is not None:
        overrides.append(f"labels.rays={args.rays}")
    return load_settings(field.FieldSettings, args.config, overrides + list(args.set))


def run_field(args: argparse.Namespace) -> int:
    check_mesh_or_dataset(args, "give --mesh PATH_OR_NAME, or --data DIR --scene NAME")
    settings = field_settings_from_args(args)
    ckpt = field.train(
        settings, args.out, data=args.data, scene=args.scene, mesh=args.mesh, progress=not args.no_progress
    )
    m = ckpt["metrics"]
    _log("field").info(
        "wrote %s: field %s (%d octaves), %d bytes, %.1f s, val RMSE %s (constant %s), "
        "held-back SSIM %s RMSE %s",
        args.out,
        mlp.size_name(ckpt["model_args"]["hidden"]),
        ckpt["model_args"]["octaves"],
        ckpt["parameter_bytes"],
        ckpt["training_time_s"],
        figure(m["val_rmse"]),
        figure(m["constant_val_rmse"]),
        *holdout_figures(m),
    )
    return 0


# ----------------------------------------------------------------------------------------------- unet


def add_unet_arguments(p: argparse.ArgumentParser) -> None:
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
        "--budget",
        type=float,
        metavar="MINUTES",
        help="wall-clock budget (sets budget_minutes; use with lr_schedule=cosine)",
    )
    p.add_argument(
        "--restart", action="store_true", help="ignore an existing checkpoint and train from scratch"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run_unet(args: argparse.Namespace) -> int:
    overrides = list(args.set) + ([f"budget_minutes={args.budget}"] if args.budget is not None else [])
    settings = load_settings(unet_train.UNetTrainSettings, args.config, overrides)
    unet_train.check_run(settings, Path(args.out), args.restart)  # before any frame is read or prepared
    train_set, val_set, info = unet_frames.load_dataset_frames(
        Path(args.data),
        settings.train_fraction,
        internal_height=settings.internal_height,
        gtao=settings.gtao_input,
        version=settings.preprocess_version,
        gtao_blur=settings.gtao_blur,
        gtao_raw=settings.gtao_raw_input,
    )
    log = _log("unet")
    log.info(
        "U-Net: %d training frames (%s), %d validation frames (%s)",
        len(train_set),
        ", ".join(info["training_scenes"]),
        len(val_set) if val_set is not None else 0,
        info["val_source"],
    )
    ckpt = unet_train.train(
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


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="model", metavar="MODEL", required=True)
    for name, kind in kinds.trained().items():
        flags = kinds.role(name, "train_flags")
        flags(sub.add_parser(name, help=kind.train_help, description=kind.train_help))


def run(args: argparse.Namespace) -> int:
    return int(kinds.role(args.model, "train_run")(args) or 0)
