"""The pyqtgraph pieces the report's panels share: the sessions' colours, a labelled plot, a shade of a colour,
a legend sample for a shaded region, log-axis ticks and the points a log axis can show.
"""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from pyqtgraph.Qt import QtGui

#: Colours of the sessions, in order (repeats after the last).
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
_LOG_TICK_DECADES = range(-6, 7)
#: A panel's title (pyqtgraph's default is 11 pt: "Electromagnetic torque" 184 px and the FRF's heading 365 px made the
#: report's plots 640 px wide at least, all a 1000 px window leaves them beside the values).
TITLE_SIZE = "10pt"


def add_plot(layout: pg.GraphicsLayout, row: int, col: int, title: str | None,
             x: tuple[str, str], y: tuple[str, str], rowspan: int = 1) -> pg.PlotItem:
    """A plot in ``layout`` at ``row``, ``col``, titled in :data:`TITLE_SIZE`, its axes labelled ``x`` and ``y`` (text,
    units; no SI prefix), with a light grid."""
    # unnamed: pyqtgraph's view registry fails at teardown
    plot = layout.addPlot(row=row, col=col, rowspan=rowspan)
    if title is not None:
        plot.setTitle(title, size=TITLE_SIZE)
    for side, (text, units) in (("bottom", x), ("left", y)):
        axis = plot.getAxis(side)
        axis.enableAutoSIPrefix(False)
        plot.setLabel(side, text, units=units or None)
    plot.showGrid(x=True, y=True, alpha=0.25)
    return plot


def with_alpha(color: str, alpha: int) -> QtGui.QColor:
    """``color`` with opacity ``alpha`` (0 … 255)."""
    c = QtGui.QColor(color)
    c.setAlpha(alpha)
    return c


def legend_box(brush: QtGui.QBrush, pen: QtGui.QPen | None = None) -> pg.BarGraphItem:
    """A legend sample for a shaded region: a filled square (with a line across it when ``pen`` is given)."""
    return pg.BarGraphItem(x=[0.0], height=[1.0], width=1.0, brush=brush, pen=pen)


def log_ticks() -> list[list[tuple[float, str]]]:
    """Ticks of a log axis in view coordinates (log10): 1·10ⁿ labelled, 2 and 5 ·10ⁿ labelled minor."""
    major = [(float(n), f"{10.0**n:g}") for n in _LOG_TICK_DECADES]
    minor = [(math.log10(m * 10.0**n), f"{m * 10.0**n:g}") for n in _LOG_TICK_DECADES for m in (2, 5)]
    return [major, minor]


def positive(f_hz: np.ndarray, *ys: np.ndarray) -> tuple[np.ndarray, ...]:
    """Keep the points with f > 0 and every value finite (log axes)."""
    keep = (np.asarray(f_hz) > 0) & np.isfinite(f_hz)
    for y in ys:
        keep &= np.isfinite(y)
    return (np.asarray(f_hz)[keep], *(np.asarray(y)[keep] for y in ys))
