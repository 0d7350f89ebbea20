"""The ``neuralao`` command line: one module per command, dispatched by :mod:`neuralao.pipeline.cli.main`."""

from neuralao.pipeline.cli.main import main

__all__ = ["main"]
