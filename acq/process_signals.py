"""Ctrl-C and SIGTERM held back over code that must not be cut short, for any acq command (no other dependency)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def signals_deferred() -> Iterator[None]:
    """A Ctrl-C or SIGTERM inside the block reaches this process's own handlers when the block has run to its end
    (acq's: a KeyboardInterrupt; an ignored signal stays ignored). For code that must not be cut short: a worker being
    started, Qt's import (shiboken's start-up interrupted is a fatal error, or swallows the Ctrl-C)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: caught.append(signum))
                for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    for signum in dict.fromkeys(caught):
        signal.raise_signal(signum)
