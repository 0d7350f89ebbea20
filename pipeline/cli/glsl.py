"""`neuralao glsl MODEL.onnx`: GLSL (compute or fragment) for a user's own ONNX model.

The export and its targets are :mod:`neuralao.export.onnx_glsl`; `neuralao parity DIR` checks the folder it
writes.
"""

from __future__ import annotations

import argparse
import logging

from neuralao.export.onnx_glsl import TARGETS, export_model
from neuralao.runtime import kinds
from neuralao.runtime.foundation.io import atomic_folder
from neuralao.runtime.foundation.paths import FOLDER, check_replaceable_folder

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FOLDER}
INPUTS = ("model",)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", help="an ONNX file within the op set (see README: GLSL from ONNX)")
    p.add_argument(
        "--target",
        required=True,
        choices=TARGETS,
        help=(
            "image: NCHW GLSL compute passes; wgsl: the same in WGSL (WebGPU); "
            "vector: per-pixel fragment pass"
        ),
    )
    p.add_argument(
        "--precision",
        default="fp32",
        choices=("fp32", "fp16"),
        help="image, wgsl: fp16 stores textures as RGBA16F and accumulates convs in fp16 where the GPU "
        "has a half type (default fp32)",
    )
    p.add_argument(
        "--preset",
        default="gpu",
        choices=("gpu", "cpu"),
        help="image, wgsl: gpu (default) many small invocations and fused passes for GPUs; cpu large "
        "per-invocation blocks for CPU rasterisers such as Mesa's llvmpipe (same outputs)",
    )
    p.add_argument(
        "--dialect",
        action="append",
        default=[],
        help="vector: keep only these of glsl330, es300, glsl430 (repeatable); "
        "image: vulkan writes Vulkan GLSL and its SPIR-V",
    )
    p.add_argument(
        "--bind",
        action="append",
        default=[],
        metavar="INPUT=TEXTURE.CHANNELS[xREPEATS]",
        help="vector: where an input comes from, e.g. normal=gbuffer.xyz or normals=gbuffer.xyzx16",
    )
    p.add_argument(
        "--hlsl-msl",
        action="store_true",
        help="image: also write HLSL and MSL of every pass beside its GLSL (SPIR-V + SPIRV-Cross)",
    )
    p.add_argument("--out", required=True, help="export folder (replaced whole, never merged)")
    p.add_argument("--force", action="store_true", help="replace --out even when it holds files of no export")


def run(args: argparse.Namespace) -> int:
    check_replaceable_folder("--out", args.out, kinds.KINDS, args.force, {"MODEL": args.model})
    with atomic_folder(args.out) as folder:  # written whole, then put in --out's place
        m = export_model(
            args.model,
            args.target,
            folder,
            args.precision,
            args.bind,
            args.dialect or None,
            args.hlsl_msl,
            preset=args.preset,
        )
    log.info("wrote %s: %s target, %s, ops %s", args.out, m["target"], m["precision"], ", ".join(m["ops"]))
    return 0
