"""`neuralao export MODEL.pt --out DIR`: ONNX + generated GLSL + manifest, by checkpoint kind."""

from __future__ import annotations

import argparse
from pathlib import Path

from neuralao.pipeline.models.checkpoint import read_checkpoint
from neuralao.runtime import kinds
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_folder
from neuralao.runtime.foundation.paths import FOLDER, check_replaceable_folder

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FOLDER}
INPUTS = ("model",)


def checkpoint_kind(path: str | Path) -> str:
    """Read a checkpoint safely (weights_only=True) and return its 'kind'."""
    kind = read_checkpoint(path).get("kind")
    trained = kinds.trained()
    if kind not in trained or trained[kind].exporter is None:
        raise NeuralaoError(
            f"{path} is not a neuralao checkpoint (kind {kind!r}; expected one of {sorted(trained)})"
        )
    return kind


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", help="checkpoint written by `neuralao train` (MODEL.pt)")
    p.add_argument(
        "--out",
        required=True,
        help="export folder: model.onnx, GLSL shaders, manifest.json (replaced whole, never merged)",
    )
    p.add_argument("--force", action="store_true", help="replace --out even when it holds files of no export")


def run(args: argparse.Namespace) -> int:
    kind = checkpoint_kind(args.model)
    check_replaceable_folder("--out", args.out, kinds.KINDS, args.force, {"MODEL": args.model})
    with atomic_folder(args.out) as folder:  # written whole, then put in --out's place
        kinds.role(kind, "exporter")(Path(args.model), folder)
    return 0
