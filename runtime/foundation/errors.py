"""One exception type for bad input: the CLI prints its message on one line and exits non-zero."""


class NeuralaoError(Exception):
    """A user-facing error (bad input, unsupported op, wrong shape). Message is one line."""

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))
