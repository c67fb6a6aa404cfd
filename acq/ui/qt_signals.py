"""Ctrl-C, SIGTERM and SIGHUP while a Qt event loop runs (``acq view``, ``acq view --trend``, ``acq record --live``).

Python runs a signal handler only when the interpreter gets control. Inside ``QApplication.exec()`` it has none
until Qt calls back into Python, so a Ctrl-C waited for the next timer or mouse event (``acq view`` of a session:
for ever), and the KeyboardInterrupt Python's own handler then raised went off inside Qt's C++ frames: a traceback,
and the loop went on (a new-user trial had to kill -9 both). Here the handler raises nothing: it tells a callback,
which asks the loop to end (or the recording to stop). Python's C-level handler also writes the signal's number to
a socket (:func:`signal.set_wakeup_fd`) that a ``QSocketNotifier`` watches, so the loop wakes at once and the
Python-level handler runs in the notifier's slot; the same socket pair and notifier as Qt's own documentation
suggests for Unix signals, which no library of ours wraps.
"""

from __future__ import annotations

import contextlib
import signal
import socket
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from pyqtgraph.Qt import QtCore

from acq.process_signals import STOP_SIGNALS, handled, repeated_hangup


@contextmanager
def signals_in_qt_loop(on_signal: Callable[[int], None]) -> Iterator[None]:
    """While the block runs (a Qt event loop in the main thread), the stop signals (:data:`STOP_SIGNALS`; one the
    process started with ignored stays ignored) call ``on_signal(signum)`` within milliseconds, in the main thread,
    between Qt's events; the previous handlers are restored after it.

    Parameters
    ----------
    on_signal : callable
        Told the signal's number; it must not raise (it runs in a Qt slot).
    """
    if threading.current_thread() is not threading.main_thread():
        yield  # handlers can only be set in the main thread, where Qt's loop runs (acq runs its windows there)
        return
    reader, writer = socket.socketpair()
    reader.setblocking(False)
    writer.setblocking(False)  # set_wakeup_fd needs a non-blocking fd: a full buffer never blocks the handler

    def drain() -> None:  # entering Python here is what runs the pending Python-level handler
        with contextlib.suppress(OSError):
            while reader.recv(512):
                pass

    notifier = QtCore.QSocketNotifier(reader.fileno(), QtCore.QSocketNotifier.Type.Read)
    notifier.activated.connect(drain)
    previous_fd = signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
    previous = {s: signal.signal(s, lambda signum, frame: None if repeated_hangup(signum) else on_signal(signum))
                for s in STOP_SIGNALS if handled(s)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        signal.set_wakeup_fd(previous_fd)
        notifier.setEnabled(False)
        reader.close()
        writer.close()



@contextmanager
def loop_ended_by_signals(app: QtCore.QCoreApplication) -> Iterator[list[int]]:
    """:func:`signals_in_qt_loop` that ends ``app``'s event loop; yields the list the signals caught are put in."""
    caught: list[int] = []

    def stop(signum: int) -> None:
        caught.append(signum)
        QtCore.QTimer.singleShot(0, app.quit)  # also when the loop has not started yet: it ends as it starts

    with signals_in_qt_loop(stop):
        yield caught
