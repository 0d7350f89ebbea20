"""`neuralao export MODEL.pt --out DIR`: ONNX + generated GLSL + manifest, by checkpoint kind."""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

from neuralao.pipeline.models.checkpoint import check_finished, read_checkpoint
from neuralao.runtime import kinds
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_folder
from neuralao.runtime.foundation.limits import check_int_range
from neuralao.runtime.foundation.metadata import MAX_INTERNAL_HEIGHT, MIN_INTERNAL_HEIGHT
from neuralao.runtime.foundation.paths import FOLDER, check_replaceable_folder

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FOLDER}
INPUTS = ("model",)


def checkpoint_kind(path: str | Path) -> str:
    """Read a checkpoint safely (weights_only=True) and return its 'kind', once its kind's trainer has
    checked it whole (format version, keys, the model its model_args build and its weights, within the
    memory) and it is the checkpoint of a finished training: all before the export folder is made."""
    ckpt = read_checkpoint(path)
    kind = ckpt.get("kind")
    trained = kinds.trained()
    if kind not in trained or trained[kind].exporter is None:
        raise NeuralaoError(
            f"{path} is not a neuralao checkpoint (kind {kind!r}; expected one of {sorted(trained)})"
        )
    check_finished(ckpt, path)
    trainer = importlib.import_module(trained[kind].trainer) if trained[kind].trainer else None
    if hasattr(trainer, "model_from_checkpoint"):  # the kind's own loader: version, keys, model, weights
        trainer.model_from_checkpoint(trainer.load_checkpoint(path))
    return kind


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "model",
        help="checkpoint written by `neuralao train` (MODEL.pt), or a U-Net's export folder (with "
        "--internal-height: the same model written again at other rows, e.g. runtime/models/unet-gtao)",
    )
    p.add_argument(
        "--out",
        required=True,
        help="export folder: model.onnx, GLSL shaders, manifest.json (replaced whole, never merged)",
    )
    p.add_argument("--force", action="store_true", help="replace --out even when it holds files of no export")
    p.add_argument(
        "--internal-height",
        type=int,
        metavar="ROWS",
        help="screen-space U-Net: run the network at ROWS rows instead of the rows it trained at (more rows "
        "cost the network's passes in proportion; see docs/results.md for what they change)",
    )


def run(args: argparse.Namespace) -> int:
    rows = (
        None
        if args.internal_height is None
        else check_int_range(
            "--internal-height", args.internal_height, MIN_INTERNAL_HEIGHT, MAX_INTERNAL_HEIGHT
        )
    )
    if Path(args.model).is_dir():  # an export (a shipped model's folder): written again at other rows
        if rows is None:
            raise NeuralaoError(
                f"{args.model} is an export folder: give --internal-height to write it again at other rows "
                "(a checkpoint, MODEL.pt, is exported whole)"
            )
        check_replaceable_folder("--out", args.out, kinds.KINDS, args.force, {"MODEL": args.model})
        from neuralao.export.unet import export_folder_at_height

        with atomic_folder(args.out) as folder:
            export_folder_at_height(Path(args.model), folder, rows)
        return 0
    kind = checkpoint_kind(args.model)
    if rows is not None and kind != "unet":
        raise NeuralaoError(f"--internal-height is for screen-space U-Nets; {args.model} is a {kind}")
    check_replaceable_folder("--out", args.out, kinds.KINDS, args.force, {"MODEL": args.model})
    extra = {} if rows is None else {"internal_height": rows}
    with atomic_folder(args.out) as folder:  # written whole, then put in --out's place
        kinds.role(kind, "exporter")(Path(args.model), folder, **extra)
    return 0
