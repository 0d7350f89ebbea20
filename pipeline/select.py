"""`neuralao select`: per scene, the smallest model that meets an SSIM target on held-back views.

Candidates for a scene: every exported baked MLP trained for that scene (one network per mesh) and
the U-Net (one network for all scenes). They are tried from the smallest (float32 weight bytes)
up; the first whose masked SSIM on the scene's held-back frames is at least ``target`` (default
0.95) is chosen. ``select.json`` records, per scene, the order tried, the choice, whether the target
was met (if no candidate meets it the best-scoring one is recorded with ``met_target: false``), and
what the choice saves against the largest candidate: bytes and measured time per frame (GL, at the
report's timing size).

The measurements are the report's (:func:`pipeline.report.evaluate` restricted to the models): pass
``--report report.json`` to reuse a finished report's numbers, otherwise the models are run here on
the same frames with the same ground truth (cached under ``--gt-cache``).
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

from .config import add_set_option
from .errors import NeuralaoError
from .io import write_json

log = logging.getLogger(__name__)

DEFAULT_TARGET = 0.95
MODEL_FAMILIES = ("mlp", "unet")


def scene_candidates(result: dict) -> dict[str, list[dict]]:
    """Per scene: [{name, family, bytes, ssim, seconds, frames}] of the available models measured on it."""
    out: dict[str, list[dict]] = {}
    for name, e in result["methods"].items():
        if e.get("family") not in MODEL_FAMILIES or not e.get("available"):
            continue
        for scene, ps in e.get("per_scene", {}).items():
            out.setdefault(scene, []).append(
                {
                    "name": name,
                    "family": e["family"],
                    "bytes": e.get("bytes"),
                    "ssim": ps["ssim"],
                    "rmse": ps["rmse"],
                    "seconds": ps.get("seconds", e.get("seconds")),
                    "frames": ps["frames"],
                }  # fmt: skip
            )
    return out


def choose(candidates: list[dict], target: float) -> dict:
    """Smallest-first selection among ``candidates`` (dicts with name, bytes, ssim, seconds)."""
    if not candidates:
        raise NeuralaoError("no candidate model to choose from")
    ordered = sorted(
        candidates, key=lambda c: (c["bytes"] if c["bytes"] is not None else float("inf"), c["name"])
    )
    tried, chosen = [], None
    for c in ordered:
        tried.append(
            {"name": c["name"], "bytes": c["bytes"], "ssim": c["ssim"], "meets": c["ssim"] >= target}
        )
        if c["ssim"] >= target:
            chosen = c
            break
    met = chosen is not None
    if chosen is None:
        chosen = max(ordered, key=lambda c: c["ssim"])
    largest = max(ordered, key=lambda c: (c["bytes"] if c["bytes"] is not None else -1, c["name"]))
    entry = {
        "chosen": chosen["name"],
        "family": chosen["family"],
        "met_target": met,
        "ssim": chosen["ssim"],
        "rmse": chosen["rmse"],
        "bytes": chosen["bytes"],
        "seconds": chosen["seconds"],
        "frames": chosen["frames"],
        "tried": tried,
        "largest": largest["name"],
        "largest_bytes": largest["bytes"],
        "largest_seconds": largest["seconds"],
        "largest_ssim": largest["ssim"],
    }
    if chosen["bytes"] is not None and largest["bytes"]:
        entry["bytes_saved"] = largest["bytes"] - chosen["bytes"]
        entry["bytes_ratio"] = chosen["bytes"] / largest["bytes"]
    if chosen["seconds"] is not None and largest["seconds"]:
        entry["seconds_saved"] = largest["seconds"] - chosen["seconds"]
        entry["time_ratio"] = chosen["seconds"] / largest["seconds"]
    return entry


def select_from_results(result: dict, target: float = DEFAULT_TARGET) -> dict:
    """The selection document (select.json) from a report result (report.json content)."""
    per_scene = {}
    for scene, cands in sorted(scene_candidates(result).items()):
        per_scene[scene] = choose(cands, target)
    unavailable = {n: e.get("reason", "") for n, e in result["methods"].items()
                   if e.get("family") in MODEL_FAMILIES and not e.get("available")}  # fmt: skip
    return {
        "format": "neuralao-select",
        "version": 1,
        "target_ssim": target,
        "rule": "per scene, candidates (MLPs of that scene, the U-Net) sorted by float32 weight bytes; the first with "
        "masked SSIM >= target on held-back frames is chosen; savings against the largest candidate",
        "time_size": result.get("settings", {}).get("time_size"),
        "time_on": "GL (headless context of the report run)",
        "dataset_hash": result.get("dataset", {}).get("dataset_hash"),
        "scenes": per_scene,
        "unavailable_models": unavailable,
    }


def _kib(v) -> str:
    return "-" if v is None else (f"{v / 1024:.1f} KiB" if v >= 1024 else f"{v} B")


def _ms(v) -> str:
    return "-" if v is None else f"{v * 1e3:.2f} ms"


def render_markdown(selection: dict, heading: str = "# Model selection") -> str:
    t = selection["target_ssim"]
    lines = [
        heading,
        "",
        f"Smallest model per scene with masked SSIM >= {t} on held-back views (tried smallest first).",
        "",
    ]
    if not selection["scenes"]:
        lines.append("No model export is available, so nothing to select.")
    else:
        lines += [
            "| scene | chosen | SSIM | bytes | time | tried | largest | bytes saved | time saved |",
            "|---|---|---:|---:|---:|---|---|---:|---:|",
        ]
        for scene, e in selection["scenes"].items():
            tried = ", ".join(f"{c['name']} ({c['ssim']:.3f})" for c in e["tried"])
            chosen = e["chosen"] + ("" if e["met_target"] else " (target not met: best SSIM)")
            saved_b = f"{_kib(e.get('bytes_saved'))} ({e['bytes_ratio']:.2f}x)" if "bytes_ratio" in e else "-"
            saved_t = f"{_ms(e.get('seconds_saved'))} ({e['time_ratio']:.2f}x)" if "time_ratio" in e else "-"
            lines.append(
                f"| {scene} | {chosen} | {e['ssim']:.3f} | {_kib(e['bytes'])} | {_ms(e['seconds'])} | {tried} | "
                f"{e['largest']} | {saved_b} | {saved_t} |"
            )
    if selection.get("unavailable_models"):
        lines += [
            "",
            "Models not available: "
            + "; ".join(f"{n} ({r})" for n, r in selection["unavailable_models"].items()),
        ]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- command line


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, help="dataset folder (its held-back views are the test)")
    p.add_argument("--exports", help="folder of export folders (mlp-*, unet)")
    p.add_argument("--out", required=True, help="select.json to write")
    p.add_argument(
        "--target", type=float, default=DEFAULT_TARGET, help=f"masked SSIM target (default {DEFAULT_TARGET})"
    )
    p.add_argument(
        "--report", help="reuse the measurements of this report.json instead of running the models"
    )
    p.add_argument("--gt-cache", help="ground-truth cache folder (default: gt-cache next to --out)")
    add_set_option(p, "--set gt_rays=256 (a report setting for the measurement)")


def run(args: argparse.Namespace) -> int:
    from .config import load_settings
    from .report import ReportSettings, check_settings, evaluate  # lazy: report imports this module

    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise NeuralaoError(f"--out must be a .json file, got {out.name!r}")
    if not (0.0 < args.target <= 1.0):
        raise NeuralaoError(f"--target must be in (0, 1], got {args.target}")
    if args.report:
        path = Path(args.report)
        try:
            result = json.loads(path.read_text())
        except FileNotFoundError:
            raise NeuralaoError(f"report not found: {path}") from None
        except json.JSONDecodeError:
            raise NeuralaoError(f"{path} is not valid JSON") from None
        if result.get("format") != "neuralao-report":
            raise NeuralaoError(f"{path} is not a neuralao report.json")
    else:
        settings = load_settings(ReportSettings, None, list(args.set))
        check_settings(settings)
        cache = Path(args.gt_cache) if args.gt_cache else out.parent / "gt-cache"
        result = evaluate(
            args.data, args.exports, settings, cache, families=set(MODEL_FAMILIES), keep_images=False
        )
        result.pop("_sheets", None)
    selection = select_from_results(result, args.target)
    write_json(out, selection)
    for scene, e in selection["scenes"].items():
        log.info(
            "%-16s %-10s ssim %.3f%s",
            scene,
            e["chosen"],
            e["ssim"],
            "" if e["met_target"] else " (target not met)",
        )
    if not selection["scenes"]:
        log.info("no model export available: nothing to select")
    return 0
