"""The signals that stop acq cleanly, and those signals held back over code that must not be cut short, for any acq
command (no other dependency)."""

from __future__ import annotations

import _thread
import contextlib
import os
import signal
import stat
import threading
from collections.abc import Iterator
from contextlib import contextmanager

#: The signals that stop an acq command as Ctrl-C does — a recording finishes its file and stops the drive, a batch
#: cancels and tidies up — with the stop reason each gives: Ctrl-C at the terminal; kill, timeout or a service
#: manager; a terminal that closed (an ssh connection dropped, the window shut: the kernel hangs up its session).
#: A signal the process started with ignored (``nohup`` ignores SIGHUP) stays ignored.
STOP_REASONS: dict[int, str] = {
    signal.SIGINT: "interrupted by user (Ctrl-C)",
    signal.SIGTERM: "stopped by SIGTERM",
    signal.SIGHUP: "stopped by SIGHUP (a hang-up: its terminal closed, or kill -HUP)",
}
STOP_SIGNALS: tuple[int, ...] = tuple(STOP_REASONS)


class StopSignal(KeyboardInterrupt):
    """The KeyboardInterrupt a stop signal other than Ctrl-C raises (SIGTERM, SIGHUP): it carries the signal's number,
    so the reason a file stores and a line prints names that signal, not Ctrl-C."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def signal_of(e: BaseException | None) -> int:
    """The stop signal that raised ``e``: its ``signum`` (:class:`StopSignal`, or an exception of acq's that carries
    one), else SIGINT (Python's own KeyboardInterrupt is Ctrl-C's)."""
    signum = getattr(e, "signum", signal.SIGINT)
    return signum if signum in STOP_REASONS else signal.SIGINT


def stop_reason(e: BaseException | None) -> str:
    """The stop reason (:data:`STOP_REASONS`) of the stop signal that raised ``e``."""
    return STOP_REASONS[signal_of(e)]


_hung_up = False
_hangup_again = False


def deliver_again(signum: int) -> None:
    """Deliver stop signal ``signum`` once more to the main thread's handler of that signal (from another thread:
    where it was raised, Python lost it). It used to go to SIGINT's handler, whatever the signal: a SIGTERM or SIGHUP
    then stopped a recording as "interrupted by user (Ctrl-C)". A SIGHUP delivered again is not taken for the
    terminal's second (:func:`repeated_hangup`). Nothing happens where Python has no handler of ``signum``."""
    global _hangup_again
    if signum == signal.SIGHUP:
        _hangup_again = True
    _thread.interrupt_main(signum)


def repeated_hangup(signum: int) -> bool:
    """For a stop signal's handler: True for a SIGHUP after the first, which the handler ignores — a closed terminal
    sends two (the kernel hangs up its foreground group, the shell forwards one more to its jobs), not a second Ctrl-C
    that quits at once (the review: a recording's file finished, then a KeyboardInterrupt in the drain). On the first,
    standard output and error on a terminal that hung up go to /dev/null: a write to it fails (EIO), and acq ended
    "Input/output error", exit 1, instead of its stop's line and 130. A SIGHUP sent to acq on a terminal still open
    (``kill -HUP``) keeps its output: the stop's line is printed."""
    global _hung_up, _hangup_again
    if signum != signal.SIGHUP:
        return False
    if _hung_up:
        if _hangup_again:  # the first, delivered again (:func:`deliver_again`)
            _hangup_again = False
            return False
        return True
    _hung_up = True
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in (1, 2):
            with contextlib.suppress(OSError):  # a descriptor already closed stays so
                # a terminal that hung up (its files' operations fail with EIO: isatty is False — the kernel swaps them
                # before it sends the SIGHUP); a pipe, a file (a log) or a terminal still open (kill -HUP) keeps the lines
                if stat.S_ISCHR(os.fstat(fd).st_mode) and not os.isatty(fd):
                    os.dup2(devnull, fd)
    finally:
        os.close(devnull)
    return False


def handled(signum: int) -> bool:
    """Whether acq may take ``signum`` over: not when the process was started with it ignored (``nohup``)."""
    return signal.getsignal(signum) is not signal.SIG_IGN


@contextmanager
def signals_deferred() -> Iterator[None]:
    """A stop signal (:data:`STOP_SIGNALS`) inside the block reaches this process's own handlers when the block has run to its end
    (acq's: a KeyboardInterrupt; an ignored signal stays ignored). For code that must not be cut short: a worker being
    started, Qt's import (shiboken's start-up interrupted is a fatal error, or swallows the Ctrl-C)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: caught.append(signum))
                for s in STOP_SIGNALS if handled(s)}
    try:
        yield
    finally:  # also when the block raised: a stop asked for meanwhile is never lost (its KeyboardInterrupt wins)
        # blocked while the handlers are put back: one arriving between two restores would raise from the first
        # restored handler and leave the others deferring for good; held pending, it reaches its own handler after
        # (this thread's mask: where another thread leaves them unblocked, a handler already put back can still raise
        # between two restores — the loop then puts back the rest and raises it after)
        old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, previous) if previous else None
        raised: BaseException | None = None
        for s, handler in previous.items():
            while True:  # a restored handler raising in the next call leaves none of the others deferring for good
                try:
                    signal.signal(s, handler)
                    break
                except Exception as e:  # noqa: BLE001 - the call itself refused: raised after the rest are put back
                    raised = raised or e
                    break
                except BaseException as e:  # a stop (KeyboardInterrupt) from a handler already put back: put this
                    raised = raised or e  # one back again, raise it after
        if old_mask is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)  # a stop held pending reaches its handler here
        if raised is not None:
            raise raised
        for signum in dict.fromkeys(caught):  # the first's handler raises: the rest were the same request
            signal.raise_signal(signum)
