"""The ``neuralao`` command. Each subcommand lives in its own module, imported lazily so
``neuralao --help`` stays fast; a module provides ``add_arguments(parser)`` and ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from typing import NoReturn

from neuralao.runtime.foundation.errors import NeuralaoError

# subcommand -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "render": (
        "neuralao.pipeline.cli.render",
        "render G-buffers + ray-traced AO for views of a mesh (.npz + PNG previews)",
    ),
    "bake": (
        "neuralao.pipeline.cli.bake",
        "bake per-vertex AO into a PLY/GLB (vertex colours + float 'ao' property), or a level with --config",
    ),
    "level": (
        "neuralao.pipeline.cli.level",
        "write a seeded synthetic game level (glTF + bake config) for tests and benchmarks",
    ),
    "dataset": (
        "neuralao.pipeline.cli.dataset",
        "render and label a dataset from a config (resumable shards + manifest)",
    ),
    "train": ("neuralao.pipeline.cli.train", "train the baked MLP, the DeepAO U-Net or a per-mesh AO field"),
    "export": ("neuralao.pipeline.cli.export", "export a checkpoint to ONNX + generated GLSL"),
    "glsl": (
        "neuralao.pipeline.cli.glsl",
        "generate GLSL (compute or fragment) from any ONNX model within the op set",
    ),
    "parity": (
        "neuralao.pipeline.cli.parity",
        "run generated GLSL against onnxruntime on real frames or seeded inputs",
    ),
    "infer": ("neuralao.pipeline.cli.infer", "apply an exported ONNX model to a G-buffer frame"),
    "report": ("neuralao.pipeline.cli.report", "speed-vs-error report of every method on held-back frames"),
    "evaluate": (
        "neuralao.pipeline.cli.evaluate",
        "score screen-space AO (U-Nets, SSAO, GTAO) by category and resolution on test meshes",
    ),
    "ship": (
        "neuralao.pipeline.cli.ship",
        "train, export, check and install the release models (runtime/models) from a config",
    ),
    "select": (
        "neuralao.pipeline.cli.select",
        "pick the cheapest AO representation that meets an error target per scene",
    ),
    "volumes": (
        "neuralao.pipeline.cli.volumes",
        "bake per-region volume AO models for dynamic objects (Sloan et al. 2013)",
    ),
    "probe": (
        "neuralao.pipeline.cli.probe",
        "evaluate volume AO models at points and normals (.npy in, .npy out)",
    ),
    "view": (
        "neuralao.pipeline.cli.view",
        "write a self-contained WebGL2 page showing bakes and ES 3.00 MLP / field shaders",
    ),
}


class _Parser(argparse.ArgumentParser):
    """argparse with the command's error contract: a usage error is one line on stderr, exit 2
    (the usage text stays in ``--help``). Subparsers are built with the same class."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def build_parser(load: str | None = None) -> argparse.ArgumentParser:
    parser = _Parser(
        prog="neuralao",
        description="Neural ambient occlusion: meshes -> AO labels -> models -> ONNX -> GLSL.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_) in COMMANDS.items():
        p = sub.add_parser(name, help=help_, description=help_)
        if name == load:
            importlib.import_module(module).add_arguments(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if a in COMMANDS), None)
    parser = build_parser(load=command)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO, format="%(levelname)s %(name)s: %(message)s"
    )
    for noisy in ("trimesh", "OpenGL"):  # library chatter (triangulating faces, accelerate module)
        logging.getLogger(noisy).setLevel(logging.DEBUG if args.verbose else logging.WARNING)
    if not args.command:
        sys.stderr.write(
            f"neuralao: error: no command given, one of {', '.join(COMMANDS)} (see neuralao --help)\n"
        )
        return 2
    module = importlib.import_module(COMMANDS[args.command][0])
    try:
        return int(module.run(args) or 0)
    except NeuralaoError as e:
        sys.stderr.write(f"neuralao {args.command}: error: {e}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write(f"neuralao {args.command}: interrupted\n")
        return 130
    except Exception as e:  # a bug, not bad input: still one line (the traceback with -v), exit 1
        if args.verbose:
            raise
        first = str(e).splitlines()[0][:300] if str(e) else ""
        sys.stderr.write(
            f"neuralao {args.command}: internal error: {type(e).__name__}: {first} (-v shows the traceback)\n"
        )
        return 1


if __name__ == "__main__":
    sys.exit(main())
