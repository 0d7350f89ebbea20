"""`neuralao infer [MODEL.onnx] FRAME.npz --out AO.png [--radius R] [--composite OUT.png]`: apply an exported
model (an .onnx file or an export folder) to a G-buffer. Without MODEL.onnx the shipped U-Net
(``runtime/models``) is used.

FRAME.npz is one frame as ``neuralao render`` writes it (``depth``, ``normal_cam``, ``normal_obj``,
``mask``, ``yfov`` in radians, ...) or as a user's exporter writes it from the keys docs/formats.md
lists; a dataset shard (frames stacked on a first axis) works with ``--index K``. The work is
:mod:`neuralao.runtime.infer`'s.
"""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import publish_together
from neuralao.runtime.foundation.paths import FILE
from neuralao.runtime.frame import check_scene_length, check_yfov, read_frame
from neuralao.runtime.infer import (
    check_output,
    complete_frame,
    composite,
    foreground,
    infer,
    model_file,
    model_kind,
    write_image,
)
from neuralao.runtime.onnx_io import load_onnx
from neuralao.runtime.shipped import default_model

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FILE, "composite": FILE}
INPUTS = ("inputs",)


def field_of_view(args: argparse.Namespace) -> float | None:
    """``--yfov`` (degrees) or ``--yfov-rad`` as radians, within a camera's range (:func:`check_yfov`);
    None when neither is given."""
    if args.yfov is not None and args.yfov_rad is not None:
        raise NeuralaoError("give the field of view once: --yfov DEG or --yfov-rad RAD")
    if args.yfov is not None:
        return math.radians(check_yfov("--yfov", args.yfov))
    if args.yfov_rad is not None:
        check_yfov("--yfov-rad", args.yfov_rad, radians=True)
        return float(args.yfov_rad)
    return None


def model_argument(path: str) -> Path:
    """The ONNX file of the first of two paths (MODEL FRAME.npz): an .onnx file or an export folder. A file
    of another suffix that is no ONNX model (a frame given first, say) is named as the model it was taken for.
    """
    model = model_file(path)
    if model.is_file() and model.suffix.lower() != ".onnx":
        try:
            load_onnx(model)
        except NeuralaoError:
            raise NeuralaoError(
                f"{path} was taken as the model, and it is not an ONNX model: given two paths, infer reads "
                "MODEL FRAME.npz (MODEL an .onnx file or an export folder); give one frame at a time"
            ) from None
    return model


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "inputs",
        nargs="+",
        metavar="[MODEL.onnx] FRAME.npz",
        help="exported ONNX model (an export folder or its model.onnx; default: the shipped U-Net) and a "
        "G-buffer frame .npz (as `neuralao render` writes), or a dataset shard with --index",
    )
    p.add_argument(
        "--radius", type=float, help="AO radius in scene units (U-Net; default: the frame's label radius)"
    )
    p.add_argument(
        "--yfov",
        type=float,
        metavar="DEG",
        help="vertical field of view in degrees, for frames that lack yfov (U-Net; replaces the frame's)",
    )
    p.add_argument("--yfov-rad", type=float, metavar="RAD", help="the same in radians")
    p.add_argument(
        "--out",
        required=True,
        help="AO image to write: .png (8-bit grey, 1 = white = open), .npy or .exr (float32 as computed)",
    )
    p.add_argument("--composite", help="also write AO over a simple shaded render (.png, .npy or .exr)")
    p.add_argument("--index", type=int, help="frame index inside a .npz of stacked frames (dataset shard)")


def run(args: argparse.Namespace) -> int:
    if len(args.inputs) > 2:
        raise NeuralaoError(f"expected [MODEL.onnx] FRAME.npz, got {len(args.inputs)} paths")
    if len(args.inputs) == 2:
        model, frame_path = model_argument(args.inputs[0]), args.inputs[1]
    elif Path(args.inputs[0]).suffix.lower() == ".onnx" or (Path(args.inputs[0]) / "manifest.json").is_file():
        raise NeuralaoError(f"{args.inputs[0]} is a model; give the frame after it: MODEL FRAME.npz")
    else:
        model, frame_path = default_model("unet"), args.inputs[0]
        log.info("model: %s (shipped default)", model)
    check_output("--out", args.out)
    if args.composite:
        check_output("--composite", args.composite)
    if args.radius is not None:
        check_scene_length("--radius", args.radius)
    yfov = field_of_view(args)
    frame = complete_frame(read_frame(frame_path, args.index), model_kind(model), yfov, frame_path)
    ao = infer(model, frame, args.radius)
    with publish_together():  # the AO and the composite, both or neither
        write_image(args.out, ao)
        if args.composite:
            write_image(args.composite, composite(frame, ao))
    fg = foreground(frame) if ao.shape == foreground(frame).shape else np.ones(ao.shape, bool)
    log.info(
        "wrote %s (%dx%d, mean foreground AO %.3f)%s",
        args.out,
        ao.shape[1],
        ao.shape[0],
        float(ao[fg].mean()) if fg.any() else 1.0,
        f" and {args.composite}" if args.composite else "",
    )
    return 0
