"""`neuralao evaluate CONFIG --models DIR... --out DIR`: screen-space AO judged where users run it.

The categories, resolutions and scores are :mod:`neuralao.pipeline.evaluation.categories`; this module is its
command line.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from neuralao.pipeline.evaluation.categories import EvalSettings, check_settings, evaluate, write_to_manifests
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.paths import FOLDER
from neuralao.runtime.foundation.settings import add_set_option, load_settings
from neuralao.runtime.shipped import default_export

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FOLDER}
INPUTS = ("config", "models")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", help="evaluation config (JSON): categories x resolutions; see configs/eval.json")
    p.add_argument(
        "--models", nargs="*", default=None, help="U-Net export folders (default: the shipped default model)"
    )
    p.add_argument(
        "--internal",
        default="model",
        help="comma-separated internal-resolution policies per U-Net: "
        "model (its manifest's), native, h<HEIGHT>",
    )
    p.add_argument("--out", required=True, help="output folder (frames are resumed from it)")
    p.add_argument("--no-flip", action="store_true", help="skip the FLIP metric")
    p.add_argument(
        "--write-manifest", action="store_true", help="store each U-Net's table in its manifest.json"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_set_option(p, "--set max_distance_rel=0.25")


def run(args: argparse.Namespace) -> int:
    settings = load_settings(EvalSettings, args.config, args.set)
    try:  # every rule that needs no frame, before any work: a refusal names the config file
        check_settings(settings)
    except NeuralaoError as e:
        raise NeuralaoError(f"config file {args.config}: {e}") from None
    if args.models is None:
        models = [default_export("unet")]
    else:
        models = [Path(m) for m in args.models]
    policies = [p.strip() for p in args.internal.split(",") if p.strip()]
    if not policies:
        raise NeuralaoError("--internal lists no policy")
    result = evaluate(
        settings,
        Path(args.out),
        models,
        policies,
        Path(args.config).resolve().parent,
        flip=not args.no_flip,
        progress=not args.no_progress,
    )
    if args.write_manifest:
        write_to_manifests(result, models)
    log.info("wrote %s and %s", Path(args.out) / "evaluation.json", Path(args.out) / "evaluation.md")
    return 0
