"""`neuralao select`: per scene, the cheapest AO representation that meets an SSIM target.

The rule is :mod:`neuralao.pipeline.evaluation.selection`; the measurements are the report's
(:func:`neuralao.pipeline.evaluation.report.evaluate` without the traced references): pass ``--report
report.json`` to reuse a finished report's numbers, otherwise every representation is run here on the same
frames with the same ground truth (cached under ``--gt-cache``).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from neuralao.pipeline.evaluation.report import evaluate
from neuralao.pipeline.evaluation.report_settings import ReportSettings, check_settings
from neuralao.pipeline.evaluation.selection import DEFAULT_TARGET, candidate_families, select_from_results
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.foundation.paths import FILE, FOLDER
from neuralao.runtime.foundation.settings import add_set_option, load_settings

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other, and not inside the
# dataset or the exports folder, which are read whole: --out DATA/manifest.json would replace the manifest).
OUTPUTS = {"out": FILE, "gt_cache": FOLDER}
INPUTS = ("data", "exports", "report")
READ_FOLDERS = ("data", "exports")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, help="dataset folder (its held-back views are the test)")
    p.add_argument("--exports", help="folder of export folders (mlp-*, field-*, unet*)")
    p.add_argument("--out", required=True, help="select.json to write")
    p.add_argument(
        "--target", type=float, default=DEFAULT_TARGET, help=f"masked SSIM target (default {DEFAULT_TARGET})"
    )
    p.add_argument(
        "--report", help="reuse the measurements of this report.json instead of running the methods"
    )
    p.add_argument("--gt-cache", help="ground-truth cache folder (default: gt-cache next to --out)")
    add_set_option(p, "--set gt_rays=256 (a report setting for the measurement)")


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise NeuralaoError(f"--out must be a .json file, got {out.name!r}")
    if not (0.0 < args.target <= 1.0):
        raise NeuralaoError(f"--target must be in (0, 1], got {args.target}")
    if args.report:
        path = Path(args.report)
        result = read_json(path, "report")
        if not isinstance(result, dict) or result.get("format") != "neuralao-report":
            raise NeuralaoError(f"{path} is not a neuralao report.json")
    else:
        settings = load_settings(ReportSettings, None, list(args.set))
        check_settings(settings)
        cache = Path(args.gt_cache) if args.gt_cache else out.parent / "gt-cache"
        result = evaluate(
            args.data, args.exports, settings, cache, families=set(candidate_families()), keep_images=False
        )
        result.pop("_sheets", None)
    selection = select_from_results(result, args.target)
    write_json(out, selection)
    for scene, e in selection["scenes"].items():
        log.info(
            "%-16s %-14s ssim %.3f%s",
            scene,
            e["chosen"],
            e["ssim"],
            "" if e["met_target"] else " (target not met)",
        )
    if not selection["scenes"]:
        log.info("nothing measured: nothing to select")
    log.info("selection: %s", out)
    return 0
