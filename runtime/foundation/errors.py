"""One exception type for bad input: the CLI prints its message on one line and exits non-zero."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator


class NeuralaoError(Exception):
    """A user-facing error (bad input, unsupported op, wrong shape). Message is one line."""

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))


@contextlib.contextmanager
def reading(path: str | os.PathLike, what: str) -> Iterator[None]:
    """Turn the OS's errors of reading ``path`` (a ``what``, e.g. "glTF file") into one-line errors."""
    try:
        yield
    except FileNotFoundError:
        raise NeuralaoError(f"{what} not found: {path}") from None
    except IsADirectoryError:
        raise NeuralaoError(f"{path} is a folder, not a {what}") from None
    except OSError as e:
        raise NeuralaoError(f"cannot read {path}: {e.strerror or type(e).__name__}") from None
