"""The Qt application acq draws in, and its pictures: the process's QApplication (on screen or Qt's offscreen
platform; pyqtgraph's white style is set when this module is imported) and a widget drawn into a PNG of an exact
pixel size, the one writer of the pictures acq draws on request.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pyqtgraph as pg
from pyqtgraph.Qt import QtCore, QtGui, QtWidgets

from acq.recording.storage import atomic_path, make_folders, storage_error

pg.setConfigOptions(background="w", foreground="k", antialias=True)

#: Size of the report window and of a picture drawn without a size given, px (width, height).
DEFAULT_SIZE_PX = (1600, 1000)


def ensure_app(offscreen: bool = False) -> QtWidgets.QApplication:
    """The process's QApplication, created on first use (``offscreen``: Qt's offscreen platform).

    The platform is chosen when the application is created; a later call cannot change it.
    """
    app = QtWidgets.QApplication.instance()
    if app is None:
        if offscreen:
            os.environ["QT_QPA_PLATFORM"] = "offscreen"
        QtCore.qInstallMessageHandler(_qt_message)
        app = QtWidgets.QApplication(["acq"])
    return app  # type: ignore[return-value]


def _qt_message(mode: QtCore.QtMsgType, context: QtCore.QMessageLogContext, message: str) -> None:
    """Qt's log, less the offscreen platform's notice that it cannot propagate size hints."""
    if "propagateSizeHints" not in message:
        sys.stderr.write(f"{message}\n")


def grab_png(widget: QtWidgets.QWidget, path: Path | str, size: tuple[int, int] = DEFAULT_SIZE_PX) -> Path:
    """Draw ``widget`` at exactly ``size`` (width, height) pixels into the PNG ``path``, written atomically
    (:func:`acq.recording.storage.atomic_path`): the one writer of the pictures acq draws on request (``acq trend
    --png``, ``acq fleet --png``, ``acq view --screenshot``). A failed write raises :class:`StorageError` naming
    ``path`` and the cause ("read-only file system: out.png"), exit 1; no partial file is left.
    """
    path = Path(path)
    image = widget_image(widget, size)
    try:
        make_folders(path.parent)
    except OSError as e:
        raise storage_error(e, path) from None
    with atomic_path(path) as tmp:
        save_png(image, tmp)
    return path


def widget_image(widget: QtWidgets.QWidget, size: tuple[int, int]) -> QtGui.QImage:
    """``widget`` rendered into an image of exactly ``size`` (width, height) pixels, whatever the device-pixel ratio.

    The widget is shown (on the offscreen platform this puts nothing on a screen) so that its layout is activated.
    (``WA_DontShowOnScreen`` would avoid a flash on a real screen but makes PySide 6.12 abort at exit.)
    """
    widget.resize(*size)
    widget.show()
    for _ in range(3):  # a layout change made while laying out (the f_a/f_r label rows) needs another pass
        QtWidgets.QApplication.processEvents()
    image = QtGui.QImage(size[0], size[1], QtGui.QImage.Format.Format_RGB32)
    image.fill(QtGui.QColor("white"))
    widget.render(image)
    widget.hide()
    return image


def save_png(image: QtGui.QImage, path: Path) -> None:
    """Write ``image`` as a PNG to ``path`` as it stands (the caller makes it atomic). Qt encodes it in memory and
    Python writes the file: a path is bytes on POSIX, and a folder name that is not UTF-8 (a Latin-1 one from a
    Windows USB stick) does not survive Qt's QString file names; Python's write also gives the cause of a failure
    (its errno: disk full, read-only) for :func:`acq.recording.storage.atomic_path` to name."""
    buffer = QtCore.QBuffer()
    buffer.open(QtCore.QIODevice.OpenModeFlag.WriteOnly)
    if not image.save(buffer, "PNG"):
        raise OSError(f"{path}: could not encode the PNG")
    with open(path, "wb") as f:
        f.write(buffer.data().data())
