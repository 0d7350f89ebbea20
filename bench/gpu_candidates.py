"""Architectures to time on a GPU before training them: a U-Net's GPU time does not depend on its weights,
so bench/gpu.sh times seeded untrained networks of each candidate width beside the shipped models.

    .venv/bin/python bench/gpu_candidates.py OUT NAME=WIDTHS[+gtao] ...

e.g. ``v3-fast-w6=6,12,24,48`` (a pure model) or ``v3-default=4,8,16,32+gtao`` (GTAO refined). Each NAME
becomes OUT/NAME/{model.onnx, manifest.json} in the layout of runtime/models/<name>/ that bench/gpu.sh
exports: the frame-local input contract, the release models' internal height (256 rows).
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

from neuralao.export.unet import export_onnx, onnx_metadata
from neuralao.pipeline.models.unet import UNet, UNetArgs
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json

INTERNAL_HEIGHT = 256
PREPROCESS_VERSION = 3


def parse(spec: str) -> tuple[str, list[int], bool]:
    """NAME=W1,W2,...[+gtao] -> (name, widths, gtao_input)."""
    name, sep, arch = spec.partition("=")
    widths, plus, extra = arch.partition("+")
    try:
        numbers = [int(w) for w in widths.split(",")]
    except ValueError:
        numbers = []
    if (
        not sep
        or not name
        or "/" in name
        or len(numbers) < 2
        or min(numbers) < 1
        or extra not in ("", "gtao")
    ):
        raise NeuralaoError(f"candidate {spec!r}: expected NAME=W1,W2,...[+gtao], e.g. v3-fast-w6=6,12,24,48")
    return name, numbers, bool(plus)


def write_candidate(out: Path, name: str, widths: list[int], gtao: bool, seed: int = 0) -> Path:
    torch.manual_seed(seed)
    args = UNetArgs(
        in_channels=5 if gtao else 4, widths=widths, gtao_input=gtao, preprocess_version=PREPROCESS_VERSION
    )
    model = UNet(args).eval()
    folder = out / name
    folder.mkdir(parents=True, exist_ok=True)
    meta = onnx_metadata(model, {"dataset": {"internal_height": INTERNAL_HEIGHT}})
    export_onnx(model, folder / "model.onnx", meta)
    manifest = {"kind": "unet", "internal_height": INTERNAL_HEIGHT, "onnx": "model.onnx", "metadata": meta}
    write_json(folder / "manifest.json", manifest)
    return folder


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    try:
        specs = [parse(s) for s in argv[1:]]
    except NeuralaoError as e:
        print(f"gpu_candidates: {e}", file=sys.stderr)
        return 2
    for name, widths, gtao in specs:
        print(write_candidate(Path(argv[0]), name, widths, gtao))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
