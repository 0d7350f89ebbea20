"""`neuralao train mlp|unet|field`: dispatch to the model's own training module."""

from __future__ import annotations

import argparse
import importlib

TRAINERS = {
    "mlp": (
        "pipeline.models.mlp",
        "the baked MLP of Erra et al. (16 object-space normals -> AO), one network per mesh",
    ),
    "unet": ("pipeline.models.unet_train", "the DeepAO screen-space U-Net (depth + camera normal -> AO)"),
    "field": (
        "pipeline.models.field",
        "a per-mesh neural AO field (object-space position + normal -> AO), one network per mesh",
    ),
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="model", metavar="MODEL", required=True)
    for name, (module, help_) in TRAINERS.items():
        importlib.import_module(module).add_arguments(sub.add_parser(name, help=help_, description=help_))


def run(args: argparse.Namespace) -> int:
    return int(importlib.import_module(TRAINERS[args.model][0]).run(args) or 0)
