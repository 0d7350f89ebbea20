"""The ``neuralao`` command. Each subcommand lives in its own module, imported lazily so
``neuralao --help`` stays fast; a module provides ``add_arguments(parser)`` and ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import logging
import signal
import sys
import threading
from typing import NoReturn

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.signals import RECEIVED as _RECEIVED
from neuralao.runtime.foundation.signals import raise_received

# What the system answers when it refuses to store a file (a full disk or quota, a read-only or failing
# disk, a permission): bad circumstances, not a bug, even where the write names no file.
_REFUSALS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS, errno.EACCES, errno.EPERM}

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


class Terminated(BaseException):
    """SIGTERM, raised in the main thread like KeyboardInterrupt is for SIGINT, so both unwind the same way:
    every ``finally`` runs (temporaries removed, nothing half-written) and the command ends in one line."""


def _on_signal(signum, frame) -> NoReturn:
    _RECEIVED.append(signum)
    raise KeyboardInterrupt() if signum == signal.SIGINT else Terminated()


def _unraisable(hook):
    """``sys.unraisablehook`` that sends a signal again when its exception could not be raised (it came
    while a finalizer ran, which swallows it and prints a traceback): Python runs the handler once more at
    the next chance, where the command can act on it. Anything else goes to ``hook``."""

    def resend(unraisable) -> None:
        exc = unraisable.exc_value
        if isinstance(exc, KeyboardInterrupt | Terminated):
            signal.raise_signal(signal.SIGINT if isinstance(exc, KeyboardInterrupt) else signal.SIGTERM)
        else:
            hook(unraisable)

    return resend


def _flags(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, argparse.Action]:
    """dest -> action of every argument the parsed command line went through (the command's, and a
    nested subcommand's such as ``train field``): how a message names each, by its flag or metavar."""
    out: dict[str, argparse.Action] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            chosen = action.choices.get(getattr(args, action.dest, None) or "")
            if chosen is not None:
                out.update(_flags(chosen, args))
        else:
            out[action.dest] = action
    return out


def _name(action: argparse.Action | None, dest: str) -> str:
    if action is None:
        return dest
    if action.option_strings:
        return max(action.option_strings, key=len)
    return str(action.metavar or dest.upper())


def _mesh_file(name: object) -> list:
    """The file a mesh argument names (a glTF folder's or a bare name's), as the command's reader finds it;
    none where it finds none (the reader refuses that later, in its own words)."""
    from neuralao.pipeline.geometry.scene import resolve_mesh_path

    try:
        return [resolve_mesh_path(name)] if isinstance(name, str) and name else []
    except (NeuralaoError, OSError):
        return []


def check_arguments(parser: argparse.ArgumentParser, module, args: argparse.Namespace) -> None:
    """What holds for every command, checked before it runs: each float flag is a finite number within
    float32's range (every value here ends up in float32 somewhere, where a larger one is inf), and the
    paths the command writes (its module's ``OUTPUTS``: dest -> FILE or FOLDER, or a function of the
    arguments giving them, where a file no flag names, such as a secondary output, is name -> (path, kind))
    can be written and are distinct from each other and from its ``INPUTS`` (a glTF's buffers and images
    beside it included, an OBJ's material library and textures; those of its ``MESH_INPUTS`` are first
    resolved as a mesh name is, a glTF folder or a bare name to its file), and none lies inside a folder of
    its ``READ_FOLDERS`` (inputs it reads whole, such as a dataset)."""
    # here, not at the top: the module stays light, so Ctrl-C meets main's handler as early as possible
    import os

    from neuralao.runtime.foundation.limits import check_float32
    from neuralao.runtime.foundation.paths import check_outputs

    actions = _flags(parser, args)
    for dest, action in actions.items():
        value = getattr(args, dest, None)
        if action.type is float and value is not None:
            for v in value if isinstance(value, list) else [value]:
                check_float32(_name(action, dest), v)
    outputs = getattr(module, "OUTPUTS", {})
    outputs = outputs(args) if callable(outputs) else outputs
    outputs = {
        d: spec if isinstance(spec, tuple) else (getattr(args, d, None), spec) for d, spec in outputs.items()
    }
    inputs = {d: getattr(args, d, None) for d in getattr(module, "INPUTS", ())}
    for d in getattr(module, "MESH_INPUTS", ()):
        inputs[d] = [inputs[d], *_mesh_file(inputs[d])]
    check_outputs(
        {_name(actions.get(d), d): spec for d, spec in outputs.items()},
        {_name(actions.get(d), d): value for d, value in inputs.items()},
    )
    for d in getattr(module, "READ_FOLDERS", ()):
        folder = getattr(args, d, None)
        if not folder or not os.path.isdir(folder):
            continue
        for o, (path, _) in outputs.items():
            if path and os.path.realpath(path).startswith(os.path.join(os.path.realpath(folder), "")):
                flag, source = _name(actions.get(o), o), _name(actions.get(d), d)
                raise NeuralaoError(
                    f"{flag} {path} is inside {source} {folder}, a folder the command reads: writing there "
                    "could replace what it reads; choose a path outside it"
                )


def _close_progress_bars() -> None:
    """End the line a progress bar left open, so the message of a signal or an error starts a line of its own.

    tqdm draws a bar as a line it never ends (each redraw starts with '\\r') until the bar is closed: then a
    bar that stays is drawn once more and ended, one that goes is cleared. A bar whose loop the signal cut
    short is closed on the way out where the command closes it itself; otherwise it is still open here (the
    exception holds its frame) and would be closed, and drawn again after the message, when collected. So
    the bars still open are closed now, innermost first; with none open (none shown, as with
    --no-progress or before any work, or all closed already) nothing is written and the message is the one
    line on stderr."""
    std = sys.modules.get("tqdm.std")  # not imported yet: no bar was ever drawn
    if std is None:
        return
    bars = [b for b in list(std.tqdm._instances) if not getattr(b, "disable", True)]
    try:
        for bar in sorted(bars, key=lambda b: -abs(getattr(b, "pos", 0))):
            bar.close()
    except Exception:  # a bar that cannot be drawn (its file closed): end its line by hand
        sys.stderr.write("\n")


def main(argv: list[str] | None = None) -> int:
    """Run one command. Bad input ends in one line and exit 2; Ctrl-C (SIGINT) in one line and 130, SIGTERM
    in one line and 143, whenever it comes (an import, the parse, the work): never a traceback."""
    command, previous, hook = "neuralao", {}, None
    _RECEIVED.clear()
    try:
        if threading.current_thread() is threading.main_thread():  # inside the try: a signal may come now
            sys.unraisablehook = _unraisable(hook := sys.unraisablehook)
            for s in (signal.SIGINT, signal.SIGTERM):
                previous[s] = signal.signal(s, _on_signal)
        argv = list(sys.argv[1:] if argv is None else argv)
        load = next((a for a in argv if a in COMMANDS), None)
        command = f"neuralao {load}" if load else command
        parser = build_parser(load=load)
        raise_received()  # one a library swallowed during the imports (trimesh catches BaseException)
        args = parser.parse_args(argv)
        return _run(parser, args, f"neuralao {args.command}" if args.command else command)
    except (KeyboardInterrupt, Terminated, Exception) as e:
        if isinstance(e, KeyboardInterrupt) or _RECEIVED[:1] == [signal.SIGINT]:
            _close_progress_bars()
            sys.stderr.write(f"{command}: interrupted (Ctrl-C)\n")
            return 130
        if isinstance(e, Terminated) or _RECEIVED:
            _close_progress_bars()
            sys.stderr.write(f"{command}: terminated (SIGTERM)\n")
            return 143
        if {"-v", "--verbose"} & set(argv or []):
            raise
        first = str(e).splitlines()[0][:300] if str(e) else ""
        sys.stderr.write(f"{command}: internal error: {type(e).__name__}: {first} (-v shows the traceback)\n")
        return 1
    finally:
        _RECEIVED.clear()  # this run's: a later call in the same process starts with none
        for s, handler in previous.items():
            signal.signal(s, handler)
        if hook is not None:
            sys.unraisablehook = hook


def _run(parser: argparse.ArgumentParser, args: argparse.Namespace, command: str) -> int:
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
    try:
        module = importlib.import_module(COMMANDS[args.command][0])
        raise_received()
        check_arguments(parser, module, args)
        code = int(module.run(args) or 0)
        raise_received()
        return code
    except NeuralaoError as e:
        _close_progress_bars()  # a refusal mid-run: the bar's line ends before the message, never after
        sys.stderr.write(f"{command}: error: {e}\n")
        return 2
    except OSError as e:  # the system refused a file (no space left, permissions): named, in one line
        if args.verbose or _RECEIVED or (e.filename is None and e.errno not in _REFUSALS):
            raise
        where = f"{str(e.filename)[:200]}: " if e.filename is not None else ""
        _close_progress_bars()
        sys.stderr.write(f"{command}: error: {where}{e.strerror or type(e).__name__}\n")
        return 2
    except Exception as e:  # a bug, not bad input: still one line (the traceback with -v), exit 1
        if args.verbose or _RECEIVED:  # with -v the traceback; after a signal, main reports the signal
            raise
        first = str(e).splitlines()[0][:300] if str(e) else ""
        _close_progress_bars()
        sys.stderr.write(f"{command}: internal error: {type(e).__name__}: {first} (-v shows the traceback)\n")
        return 1


if __name__ == "__main__":
    sys.exit(main())
