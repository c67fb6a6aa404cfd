"""What the report marks on its FRF beside the curves: the strip above the plot that holds the f_a/f_r labels
(packed into rows so that none overlaps another) and what a ``poor`` verdict names there, in
:data:`VERDICT_MARK_COLOR` (the band where the model misses |H| shaded, "misfit LO–HI Hz"; a third mode a
dash-dot line, "third mode ≈ F Hz"). Marks sit at log10(f) in view coordinates: pyqtgraph's log mode transforms
data items only.
"""

from __future__ import annotations

import math

import pyqtgraph as pg
from pyqtgraph.Qt import QtCore, QtWidgets

from acq.ui.plot_style import with_alpha
from analysis import FigureData

MARK_GAP_PX = 8  # least space between two labels in one row
VERDICT_MARK_COLOR = "#e6550d"  # what a verdict names on the FRF (misfit, third mode): no session's colour


def setup_mark_strip(marks: pg.PlotItem, frf: pg.PlotItem) -> None:
    """The f_a/f_r label strip: no axes, no mouse, x linked to the FRF (pyqtgraph lines linked views up by
    their position on the screen, so a label sits over its line)."""
    marks.hideButtons()
    marks.setMouseEnabled(x=False, y=False)
    marks.hideAxis("bottom")
    marks.hideAxis("left")
    marks.setLogMode(x=True, y=False)
    marks.setXLink(frf)
    marks.vb.disableAutoRange()
    marks.setContentsMargins(0, 0, 0, 0)
    marks.vb.setFlag(QtWidgets.QGraphicsItem.GraphicsItemFlag.ItemClipsChildrenToShape, False)
    marks.setYRange(0.0, 1.0, padding=0.0)
    marks.vb.sigResized.connect(lambda *_: place_marks(marks))
    marks.vb.sigXRangeChanged.connect(lambda *_: place_marks(marks))


def verdict_marks(fd: FigureData) -> list[tuple[str, float, float]]:
    """What the verdict names on the FRF: (label, low Hz, high Hz) of the misfit band and of a third mode (a
    single frequency: low = high)."""
    marks = [("misfit", *fd.misfit_band_hz), ("third mode", fd.third_mode_hz, fd.third_mode_hz)]
    return [(label, lo, hi) for label, lo, hi in marks if math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi]


def verdict_mark(low_hz: float, high_hz: float, name: str) -> pg.GraphicsObject:
    """A verdict's mark at log10(f): a dash-dot line at one frequency, a shaded span over a band."""
    if low_hz == high_hz:
        mark = pg.InfiniteLine(pos=math.log10(low_hz), angle=90, movable=False,
                               pen=pg.mkPen(VERDICT_MARK_COLOR, width=2, style=QtCore.Qt.PenStyle.DashDotLine))
    else:
        mark = pg.LinearRegionItem(values=[math.log10(low_hz), math.log10(high_hz)], movable=False,
                                   brush=pg.mkBrush(with_alpha(VERDICT_MARK_COLOR, 60)),
                                   pen=pg.mkPen(VERDICT_MARK_COLOR, width=1))
        mark.setZValue(-10)  # over the fit band's shade, under the curves
    mark.setObjectName(name)
    return mark


def place_marks(marks: pg.PlotItem) -> int:
    """Put the f_a/f_r labels of the strip into rows so that no two overlap (left to right, each into the lowest
    row where it clears the labels already there), and size the strip to hold the rows; returns the rows used.

    Labels are measured in pixels, so the rows follow the window's width and the x range (zoom).
    """
    labels = sorted((i for i in marks.items if isinstance(i, pg.TextItem)), key=lambda t: t.pos().x())
    x0, x1 = marks.vb.viewRange()[0]
    width_px = marks.vb.width()
    if not labels or width_px <= 0 or x1 <= x0:
        return 0
    px_per_decade = width_px / (x1 - x0)
    ends: list[float] = []
    rows = []
    for t in labels:
        w = t.textItem.boundingRect().width()
        left = (t.pos().x() - x0) * px_per_decade - 0.5 * w
        row = next((r for r, end in enumerate(ends) if end + MARK_GAP_PX <= left), len(ends))
        ends[row:row + 1] = [left + w]
        rows.append(row)
    for t, row in zip(labels, rows):
        t.setPos(t.pos().x(), (row + 0.5) / len(ends))
    row_px = max(t.textItem.boundingRect().height() for t in labels)
    height = int(len(ends) * row_px) + 4
    if marks.minimumHeight() != height:
        marks.setMinimumHeight(height)
        marks.setMaximumHeight(height)
    return len(ends)
