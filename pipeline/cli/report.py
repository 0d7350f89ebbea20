"""`neuralao report`: every AO method on the same held-back frames, speed against error.

What is measured is :mod:`neuralao.pipeline.evaluation.report` and what is written
:mod:`neuralao.pipeline.evaluation.report_writing`; this module is its command line.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

from neuralao.pipeline.evaluation.plots import shipped_note
from neuralao.pipeline.evaluation.report import evaluate
from neuralao.pipeline.evaluation.report_settings import SHIPPED_PICKS, ReportSettings, check_settings
from neuralao.pipeline.evaluation.report_writing import method_order, write_report
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.foundation.paths import FOLDER
from neuralao.runtime.foundation.settings import add_set_option, load_settings, parse_override
from neuralao.runtime.shipped import MODELS_DIR

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FOLDER}
INPUTS = ("data", "exports", "models", "config")
# The flags that set a report setting: (argparse dest, setting, the flag as typed).
SETTING_FLAGS = (
    ("gt_rays", "gt_rays", "--gt-rays"),
    ("frames_per_scene", "frames_per_scene", "--frames-per-scene"),
    ("time_size", "time_size", "--time-size"),
    ("repeats", "repeats", "--repeats"),
    ("target", "target_ssim", "--target"),
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, help="dataset folder (neuralao dataset)")
    p.add_argument(
        "--exports",
        help="folder of export folders (mlp-16x8, mlp-32x16, mlp-64x32, unet); "
        "missing ones are listed as not available",
    )
    shipped = p.add_mutually_exclusive_group()
    shipped.add_argument(
        "--shipped",
        nargs="?",
        const=",".join(SHIPPED_PICKS),
        default=None,
        metavar="WHICH",
        help="also report shipped U-Nets (runtime/models) when --exports is given (without "
        "--exports they are included by default): a comma list of roles (default, fast) "
        "and model names, or all (default: default,fast)",
    )
    shipped.add_argument(
        "--no-shipped", dest="shipped", action="store_false", help="leave the shipped U-Nets out"
    )
    p.add_argument(
        "--models",
        help="folder of shipped models with index.json (default runtime/models), where shipped models are "
        "reported (not with --no-shipped, nor with --exports unless --shipped is given)",
    )
    p.add_argument("--out", required=True, help="output folder: report.md, report.json, PNG figures, caches")
    p.add_argument("--config", help="JSON preset of report settings")
    p.add_argument("--gt-rays", type=int, help="ground-truth rays per pixel (default 1024)")
    p.add_argument("--frames-per-scene", type=int, help="evaluation frames per scene (default 4)")
    p.add_argument(
        "--time-size", type=int, nargs=2, metavar=("W", "H"), help="timing resolution (default 512 512)"
    )
    p.add_argument("--repeats", type=int, help="timed repetitions per GL measurement (default 10)")
    p.add_argument("--target", type=float, help="model-selection SSIM target (default 0.95)")
    add_set_option(p, "--set trace_rays=[4,16] --set ssao.samples=32 (any report setting)")


def settings_from_args(args: argparse.Namespace) -> ReportSettings:
    """The report settings of the preset, ``--set`` and the flags (in that order, the later winning),
    every one checked before any work; a refusal names the flag, the ``--set`` key or the file that gave
    the value."""
    overrides = list(args.set)
    flags = {}
    for dest, key, flag in SETTING_FLAGS:
        v = getattr(args, dest, None)
        if v is not None:
            overrides.append(f"{key}={json.dumps(list(v) if isinstance(v, list | tuple) else v)}")
            flags[key] = flag
    settings = load_settings(ReportSettings, args.config, overrides)
    check_settings(settings, setting_names(args, flags))
    return settings


def setting_names(args: argparse.Namespace, flags: dict[str, str]):
    """How a refusal names the setting ``key`` (dotted, ``ssao.samples``): by the flag that set it, else by
    the key when ``--set`` gave it, else as the ``--config`` file that holds it."""
    from_set = [parse_override(o)[0] for o in args.set]
    preset = read_json(Path(args.config), "config file") if getattr(args, "config", None) else {}

    def name(key: str) -> str:
        if key in flags:
            return flags[key]
        if any(key == k or key.startswith(k + ".") for k in from_set):
            return key
        node = preset
        for part in key.split("."):
            if not isinstance(node, dict) or part not in node:
                return key
            node = node[part]
        return f"{key} (config file {args.config})"

    return name


def shipped_folder(args: argparse.Namespace) -> Path | None:
    """The shipped-models folder to report on: by default only when no --exports is given. ``--models``
    names it, so it is refused where no shipped model is reported, and where it is not a folder."""
    include = getattr(args, "shipped", None)
    if include is None:
        include = not getattr(args, "exports", None)
    models = getattr(args, "models", None)
    if not include:
        if models:
            why = (
                "--no-shipped leaves them out: drop one of the two"
                if args.shipped is False
                else "with --exports they are left out unless --shipped asks for them: drop --models or "
                "add --shipped"
            )
            raise NeuralaoError(f"--models applies only where shipped models are reported; {why}")
        return None
    if models:
        check_folder("--models", Path(models))
    return Path(models) if models else MODELS_DIR


def check_folder(flag: str, path: Path) -> None:
    """A folder the user named, to read: it must exist (a missing one is not taken as empty)."""
    if not path.exists():
        raise NeuralaoError(f"{flag} {path}: no such folder")
    if not path.is_dir():
        raise NeuralaoError(f"{flag} {path} is a file, not a folder")


def shipped_picks(args: argparse.Namespace) -> list[str]:
    """The shipped rows asked for (``--shipped WHICH``): roles and names; default and fast by default."""
    which = getattr(args, "shipped", None)
    picks = [p.strip() for p in (which if isinstance(which, str) else ",".join(SHIPPED_PICKS)).split(",")]
    if not all(picks):
        raise NeuralaoError(
            f"--shipped {which!r}: expected a comma list of default, fast, all or model names"
        )
    return picks


def run(args: argparse.Namespace) -> int:
    # Every flag and setting checked here, before any work; the report makes --out only once it has read
    # its inputs (a refused run leaves none behind).
    settings = settings_from_args(args)
    if args.exports:
        check_folder("--exports", Path(args.exports))
    shipped, picks = shipped_folder(args), shipped_picks(args)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise NeuralaoError(f"--out {out} exists and is not a folder")
    result = evaluate(
        args.data, args.exports, settings, out, progress=True, shipped=shipped, shipped_picks=picks
    )
    write_report(result, out, settings)
    ms = result["methods"]
    for n in method_order(ms):
        e = ms[n]
        if e.get("available"):
            log.info(
                "%-15s ssim %.3f rmse %.4f  %8.2f ms",
                n,
                e["ssim"],
                e["rmse"],
                (e.get("seconds") or float("nan")) * 1e3,
            )
        else:
            log.info("%-15s not available: %s", n, e.get("reason"))
    if result.get("shipped") is not None and not result["shipped"]["models"]:
        log.info("%s", shipped_note(result["shipped"]))
    log.info("report: %s", out / "report.md")
    return 0
