"""`neuralao ship CONFIG.json`: train, export, check and install the release models under ``runtime/models/``.

The steps are :mod:`neuralao.pipeline.release.ship`; this module is its command line.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from neuralao.pipeline.release.ship import ShipSettings, ship
from neuralao.runtime.foundation.settings import load_settings

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", help="ship config JSON (configs/models.json)")
    p.add_argument(
        "--only", nargs="+", metavar="NAME", help="ship only these models (their init checkpoints must exist)"
    )


def run(args: argparse.Namespace) -> int:
    settings = load_settings(ShipSettings, args.config, [])
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
