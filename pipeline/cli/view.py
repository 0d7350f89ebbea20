"""`neuralao view EXPORT_OR_BAKE... --out DIR [--mesh MESH] [--screen-space [MODEL]] [--size W H] [--serve]`:
write a self-contained WebGL2 page showing bakes and ES 3.00 MLP / field shaders, and optionally a
screen-space U-Net run in WebGPU on the page's own G-buffer (:mod:`neuralao.runtime.viewer`)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from neuralao.pipeline.bakes.viewer_inputs import (
    SCREEN_SPACE_RADIUS_REL,
    load_method,
    method_from_unet,
    screen_space_mesh,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.paths import FOLDER
from neuralao.runtime.viewer import serve, write_page

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FOLDER}
INPUTS = ("inputs", "mesh")
MESH_INPUTS = ("mesh",)  # mesh names: a file, a glTF folder or a bare name


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "inputs",
        nargs="*",
        metavar="EXPORT_OR_BAKE",
        help="vertex bakes (.ply/.glb), texture bakes (.glb), scene bakes (.glb) and MLP / field export "
        "folders: one method each",
    )
    p.add_argument(
        "--mesh",
        help="mesh of the export folders and of --screen-space (default: the mesh each export records; "
        "for --screen-space, the first input's)",
    )
    p.add_argument(
        "--screen-space",
        nargs="?",
        const="",
        metavar="MODEL",
        help="add a screen-space U-Net whose whole frame (GTAO for a hybrid, the network, upsampling) runs "
        "live in WebGPU on the page's G-buffer: an export folder or a shipped model's name (no value: the "
        "default shipped U-Net)",
    )
    p.add_argument(
        "--screen-space-radius",
        type=float,
        default=None,
        metavar="FRACTION",
        help=f"the U-Net's AO radius as a fraction of the mesh's bounding-box diagonal "
        f"(default {SCREEN_SPACE_RADIUS_REL})",
    )
    p.add_argument("--out", required=True, help="output folder: index.html, viewer.js, scene.js, scene.json")
    p.add_argument(
        "--size",
        type=int,
        nargs=2,
        default=[640, 480],
        metavar=("W", "H"),
        help="canvas size in pixels (default 640 480)",
    )
    p.add_argument("--serve", action="store_true", help="serve the page on http://127.0.0.1:PORT afterwards")
    p.add_argument(
        "--port", type=int, default=8000, help="port for --serve (default 8000; 0 = any free port)"
    )


def run(args: argparse.Namespace) -> int:
    w, h = args.size
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise NeuralaoError(f"--size must be in 1..8192, got {w} {h}")
    if not 0 <= args.port <= 65535:
        raise NeuralaoError(f"--port must be in 0..65535, got {args.port}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise NeuralaoError(f"--out {out} is a file")
    if not args.inputs and args.screen_space is None:
        raise NeuralaoError("nothing to view: give bakes or exports, or --screen-space with --mesh")
    if args.screen_space is None and args.screen_space_radius is not None:
        raise NeuralaoError("--screen-space-radius applies with --screen-space only")
    exports = any(Path(i).is_dir() for i in args.inputs)
    if args.mesh is not None and args.screen_space is None and not exports:
        raise NeuralaoError("--mesh applies to export folders and --screen-space (a bake carries its mesh)")
    radius = SCREEN_SPACE_RADIUS_REL if args.screen_space_radius is None else args.screen_space_radius
    methods = [load_method(i, args.mesh) for i in args.inputs]
    if args.screen_space is not None:
        pos, nrm = screen_space_mesh(methods, args.mesh)
        methods.append(method_from_unet(args.screen_space or None, pos, nrm, radius))
    page = write_page(methods, out, (w, h))
    log.info("viewer: %d method(s) -> %s", len(methods), page)
    if args.serve:
        serve(out, args.port)
    return 0
