"""A widget built and drawn offscreen into a PNG, Qt imported only here and Ctrl-C / SIGTERM held back meanwhile: the
one path of ``acq trend --png`` and ``acq fleet --png``."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from acq.process_signals import signals_deferred


def render_offscreen_png(build_widget: Callable[[], Any], path: Path | str, size: tuple[int, int]) -> Path:
    """Draw the widget ``build_widget()`` returns offscreen into the PNG ``path`` at ``size`` (width, height) px
    (:func:`acq.ui.qt_app.grab_png`: atomic, a failed write one line naming ``path``). Ctrl-C and SIGTERM wait until Qt
    returns (:func:`~acq.process_signals.signals_deferred`): raised inside Qt's frames — its import, a virtual such as
    paintEvent — a signal crashed the process or was swallowed."""
    with signals_deferred():
        import shiboken6

        from acq.ui.qt_app import ensure_app, grab_png

        ensure_app(offscreen=True)
        widget = build_widget()
        try:
            return grab_png(widget, path, size)
        finally:
            shiboken6.delete(widget)  # now, not at interpreter exit (deleteLater there crashes Qt's teardown)
