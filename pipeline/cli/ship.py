"""`neuralao ship CONFIG.json`: train, export, check and install the release models under ``runtime/models/``.

The steps are :mod:`neuralao.pipeline.release.ship`; this module is its command line.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from neuralao.pipeline.release.ship import ShipSettings, check_settings, refresh_shipped, ship
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.settings import load_settings

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", help="ship config JSON (configs/models.json)")
    p.add_argument(
        "--only", nargs="+", metavar="NAME", help="ship only these models (their init checkpoints must exist)"
    )
    p.add_argument(
        "--shaders-only",
        action="store_true",
        help="retrain nothing: regenerate the installed models' shaders from their ONNX files, check "
        "them against onnxruntime and reinstall each folder",
    )


def run(args: argparse.Namespace) -> int:
    settings = load_settings(ShipSettings, args.config, [])
    try:  # the whole config before any model trains or any shader is written; a refusal names the file
        check_settings(settings, args.only, corpus=not args.shaders_only)
    except NeuralaoError as e:
        raise NeuralaoError(f"config file {args.config}: {e}") from None
    if args.shaders_only:
        for name, par in refresh_shipped(settings, args.only).items():
            log.info("%-14s shaders regenerated, GLSL vs onnxruntime %.2g", name, par["max_abs_err"])
        return 0
    index = ship(settings, args.only)
    for name, entry in index["models"].items():
        log.info("%-14s test SSIM %.4f RMSE %.4f", name, entry["test"]["ssim"], entry["test"]["rmse"])
    for name, entry in index.get("baselines", {}).items():
        log.info("%-14s test SSIM %.4f RMSE %.4f", name, entry["test"]["ssim"], entry["test"]["rmse"])
    log.info(
        "installed %s under %s (index: %s)",
        ", ".join(index["models"]) or "nothing",
        settings.out,
        Path(settings.out) / "index.json",
    )
    return 0
