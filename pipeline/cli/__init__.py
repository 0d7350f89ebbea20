"""The ``neuralao`` command line: one module per command, dispatched by :mod:`pipeline.cli.main`."""

from pipeline.cli.main import main

__all__ = ["main"]
