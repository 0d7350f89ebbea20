"""The signals a running command received, kept where every layer can ask.

A library that catches ``BaseException`` around an optional import (trimesh does) swallows the
``KeyboardInterrupt`` that Ctrl-C raised inside it, and the work would go on to publish its output. The
command's handler notes each signal here; :func:`raise_received` raises it again, and every atomic rename
calls it first, so an interrupted command never leaves a finished-looking output behind."""

from __future__ import annotations

import signal
import threading

RECEIVED: list[int] = []


def raise_received() -> None:
    """Act on the first signal this run received, once more, through the handler now installed (the
    command's raises its exception; one that only defers it returns; the default ends the process).
    Outside the main thread signals are not Python's to act on, and nothing happens."""
    if not RECEIVED or threading.current_thread() is not threading.main_thread():
        return
    signum = RECEIVED[0]
    handler = signal.getsignal(signum)
    if callable(handler):
        handler(signum, None)
    elif handler == signal.SIG_DFL:
        signal.raise_signal(signum)
