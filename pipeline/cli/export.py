"""`neuralao export MODEL.pt --out DIR`: ONNX + generated GLSL + manifest, by checkpoint kind."""

from __future__ import annotations

import argparse
from pathlib import Path

from neuralao.pipeline.models.checkpoint import read_checkpoint
from neuralao.runtime import kinds
from neuralao.runtime.foundation.errors import NeuralaoError


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
    p.add_argument("--out", required=True, help="export folder: model.onnx, GLSL shaders, manifest.json")


def run(args: argparse.Namespace) -> int:
    kind = checkpoint_kind(args.model)
    kinds.role(kind, "exporter")(Path(args.model), Path(args.out))
    return 0
