"""`neuralao dataset`: render and label a dataset from a config, :mod:`neuralao.pipeline.datasets.dataset`."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from neuralao.pipeline.cli.engine_options import add_engine_arguments, engine_from_args
from neuralao.pipeline.datasets.dataset import (
    build_dataset,
    check_config,
    check_counts,
    load_dataset_settings,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.paths import FOLDER
from neuralao.runtime.foundation.settings import add_set_option

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FOLDER}
INPUTS = ("config",)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", help="dataset config (JSON); see configs/demo.json")
    p.add_argument("--out", required=True, help="output folder (resumes if an interrupted run is there)")
    add_set_option(p, "--set labels.rays=64")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_engine_arguments(p)


def run(args: argparse.Namespace) -> int:
    settings = load_dataset_settings(args.config, args.set)
    config_dir = Path(args.config).resolve().parent
    try:  # every check of the config before anything is made; the refusal names the file
        check_config(settings, config_dir)
    except NeuralaoError as e:
        raise NeuralaoError(f"config file {args.config}{' with --set' if args.set else ''}: {e}") from None
    check_counts(settings, Path(args.out))
    with engine_from_args(args) as engine:
        manifest = build_dataset(settings, Path(args.out), config_dir, not args.no_progress, engine)
    log.info(
        "dataset %s: %d frames, %d shards, hash %s",
        args.out,
        manifest["frames"],
        len(manifest["shards"]),
        manifest["dataset_hash"][:16],
    )
    return 0
