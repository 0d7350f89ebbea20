"""`neuralao parity EXPORT_DIR`: generated GLSL vs onnxruntime on real frames; non-zero exit above tolerance.

EXPORT_DIR is one export folder (with manifest.json) or a folder of them. Frames come from a
dataset when ``--data`` is given (held-back views of the MLP's mesh; validation scenes for the
U-Net), otherwise each model's parity function renders its own.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from neuralao.pipeline.datasets.dataset import open_dataset
from neuralao.runtime import kinds
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json
from neuralao.runtime.foundation.limits import check_seed
from neuralao.runtime.foundation.manifest import read_manifest
from neuralao.runtime.foundation.paths import FILE

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FILE}
INPUTS = ("exports", "data", "inputs")


def export_dirs(root: Path) -> list[Path]:
    if (root / "manifest.json").is_file():
        return [root]
    dirs = sorted(p.parent for p in root.glob("*/manifest.json"))
    if not dirs:
        raise NeuralaoError(f"no export (manifest.json) in {root} or its subfolders")
    return dirs


def parity_frames(data: Path | None, manifest: dict, limit: int = 4) -> list[dict] | None:
    """Dataset frames for one export: held-back views of a per-mesh model's scene, or validation-split
    frames."""
    if data is None:
        return None
    ds = open_dataset(data)
    if kinds.KINDS[manifest["kind"]].per_mesh and manifest.get("scene") in ds.scenes:
        it = ds.frames(scene=manifest["scene"], holdout=True)
    else:
        it = ds.frames(split="val")
    frames = []
    for f in it:
        frames.append(f)
        if len(frames) >= limit:
            break
    return frames or None


def check_exports(
    root: Path,
    data: Path | None = None,
    inputs: Path | None = None,
    seed: int = 0,
    size: tuple[int, int] | None = None,
) -> dict:
    """Parity of every export under ``root``. ``inputs``, ``seed`` and ``size`` (W, H; None: the
    export's own) apply to `neuralao glsl` exports, and are refused for the others, which run on frames."""
    dirs = export_dirs(root)
    manifests = {d: read_manifest(d) for d in dirs}
    for d, manifest in manifests.items():
        kind = manifest.get("kind")
        if kind not in kinds.KINDS:
            raise NeuralaoError(f"{d}: unknown export kind {kind!r}")
        if not kinds.KINDS[kind].parity_on_inputs and (size is not None or inputs is not None):
            raise NeuralaoError(
                f"{d} is a {kind} export, checked on rendered or --data frames: "
                "--size and --inputs apply to `neuralao glsl` exports only"
            )
        if kinds.KINDS[kind].parity_on_inputs and data is not None:
            raise NeuralaoError(
                f"{d} is a `neuralao glsl` export, checked on --inputs or seeded inputs: "
                "--data applies to the exports of trained models only"
            )
    results = {}
    for d, manifest in manifests.items():
        kind = manifest["kind"]
        parity = kinds.role(kind, "parity")
        log.info("parity: %s (%s)", d.name, kind)
        if kinds.KINDS[kind].parity_on_inputs:
            results[d.name] = parity(d, inputs=inputs, seed=seed, size=size)
        else:
            results[d.name] = parity(d, parity_frames(data, manifest))
    return results


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("exports", help="an export folder, or a folder of export folders")
    p.add_argument("--data", help="dataset folder whose frames to use (default: render frames)")
    p.add_argument("--out", help="write the figures as JSON here")
    p.add_argument(
        "--inputs",
        help="`neuralao glsl` exports: .npz of inputs (image: per graph input, scalar "
        "inputs included, by ONNX name; vector: per texture, (H, W, 4)); default: seeded random inputs "
        "of the declared shapes, scalars uniform in [0.1, 2]",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the random inputs (default 0)")
    p.add_argument(
        "--size",
        type=int,
        nargs=2,
        default=None,
        metavar=("W", "H"),
        help="size of symbolic image dimensions / vector textures (default 64 48, rounded up to the "
        "multiples an image program takes); must equal a static input size",
    )


def run(args: argparse.Namespace) -> int:
    # before any export is read: numpy refuses a negative seed with a traceback
    check_seed("--seed", args.seed)
    results = check_exports(
        Path(args.exports),
        Path(args.data) if args.data else None,
        Path(args.inputs) if args.inputs else None,
        args.seed,
        tuple(args.size) if args.size else None,
    )
    failed = [name for name, r in results.items() if not r.get("passed", False)]
    summary = {"exports": results, "passed": not failed}
    for name, r in results.items():
        log.info(
            "%-12s %s  %s",
            name,
            "PASS" if r.get("passed") else "FAIL",
            {k: v for k, v in r.items() if "err" in k},
        )
    if args.out:
        write_json(args.out, summary)
        log.info("figures: %s", args.out)
    if failed:
        raise NeuralaoError(f"parity above tolerance for: {', '.join(failed)}")
    return 0
