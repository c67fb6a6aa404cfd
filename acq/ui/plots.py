"""The report figure in pyqtgraph, one implementation for the ``acq view`` window and the PNG.

:class:`ReportView` lays out, for one or several sessions (each its own colour):

* ``torque`` and ``speed``: the time traces on the aligned (drive) time base, x axes linked;
* ``frf``: measured |H| = |ω_m/T_e| on log–log axes (one session: dark grey dots) with the fitted two-mass model
  and its 95 % band (the session's colour, shaded; the legend says its width, as it is often a line's width),
  f_a/f_r marked by vertical lines, and
  what a ``poor`` verdict names there in :data:`VERDICT_MARK_COLOR` (also on the phase): the band where the
  model misses |H| shaded, labelled "misfit LO–HI Hz", a third mode a dash-dot line, "third mode ≈ F Hz";
  the legend and the f_a/f_r labels sit in strips of their own above the plot, so they never cover a
  curve, and the labels are packed into rows so that none overlaps another;
* ``misfit``: how far the model misses the measured |H|, model / measured − 1 in % over the fit band (the sign of
  the verdict's "misses by +5.9 %"), with the model's 95 % band about 0 and the verdict's marks: a misfit the
  verdict names, which a log axis hides (6 % is 0.025 decades);
* ``phase``: measured and model phase, when the clocks were aligned well enough for a phase to be the
  plant's (the residual a complex fit accepts, :func:`analysis.verdict_limits.phase_is_meaningful`);
* ``coherence``: γ²; FRF, phase and coherence share their x axis and show the fit band shaded;
* a side panel with the identified values, their 95 % intervals, the clock relation, the verdict and
  the options the result came from.

:func:`render_report_png` draws the same widget offscreen into an image of an exact pixel size;
``acq view --screenshot`` uses it too. Log axes: pyqtgraph transforms data items, not other items,
so the f_a/f_r lines, labels and the fit band sit at log10(f) in view coordinates.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from html import escape
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
import shiboken6
from pyqtgraph.Qt import QtCore, QtGui, QtWidgets

from acq.recording.storage import atomic_path, make_folders, storage_error
from acq.ui.values import PARAMS, format_value, interval_text, not_determined, options_text, readable_number
from analysis import FigureData, Thresholds

pg.setConfigOptions(background="w", foreground="k", antialias=True)

#: Colours of the sessions, in order (repeats after the last).
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
PANEL_WIDTH_PX = 360
_LOG_TICK_DECADES = range(-6, 7)
DEFAULT_SIZE_PX = (1600, 1000)
LEGEND_ROW_PX = 20  # height of a legend row (9 pt text, pyqtgraph's 20 px samples)
MARK_GAP_PX = 8  # least space between two labels in one row
VERDICT_MARK_COLOR = "#e6550d"  # what a verdict names on the FRF (misfit, third mode): no session's colour
#: The measured |H| of a single session: dark grey, apart from the model in the session's colour (both were blue). With
#: several sessions the colour tells the sessions apart, and the measured dots are a faint shade of it.
MEASURED_COLOR = "#404040"
#: The allowance of the verdict's misfit test, shaded on the misfit panel.
ALLOWANCE_COLOR = "#2ca02c"
#: The misfit panel's y range: at least ± this, % (a model that fits to ±1 % is drawn flat, not as noise magnified).
MISFIT_MIN_RANGE_PCT = 5.0


@dataclass(frozen=True)
class SessionFigure:
    """One session to draw.

    Attributes
    ----------
    name : str
        Label in the legend and the side panel.
    figures : FigureData
        The analysis's figure data (SI units).
    values : dict
        The identification as in ``<session>.result.json`` (empty: no values shown).
    """

    name: str
    figures: FigureData
    values: dict[str, Any] = field(default_factory=dict)


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


def _plot(layout: pg.GraphicsLayout, row: int, col: int, title: str | None,
          x: tuple[str, str], y: tuple[str, str], rowspan: int = 1) -> pg.PlotItem:
    # unnamed: pyqtgraph's view registry fails at teardown
    plot = layout.addPlot(row=row, col=col, rowspan=rowspan, title=title)
    for side, (text, units) in (("bottom", x), ("left", y)):
        axis = plot.getAxis(side)
        axis.enableAutoSIPrefix(False)
        plot.setLabel(side, text, units=units or None)
    plot.showGrid(x=True, y=True, alpha=0.25)
    return plot


def _with_alpha(color: str, alpha: int) -> QtGui.QColor:
    c = QtGui.QColor(color)
    c.setAlpha(alpha)
    return c


def _allowance_style() -> tuple[QtGui.QBrush, QtGui.QPen]:
    """Brush and edge of the misfit test's allowance (on the misfit panel and in the legend)."""
    return pg.mkBrush(_with_alpha(ALLOWANCE_COLOR, 70)), pg.mkPen(_with_alpha(ALLOWANCE_COLOR, 160), width=1)


def legend_box(brush: QtGui.QBrush, pen: QtGui.QPen | None = None) -> pg.BarGraphItem:
    """A legend sample for a shaded region: a filled square (with a line across it when ``pen`` is given)."""
    return pg.BarGraphItem(x=[0.0], height=[1.0], width=1.0, brush=brush, pen=pen)


def band_width_text(fd: FigureData) -> str:
    """The model's 95 % band as ± its relative half-width over the fit band, % (min–max): the band is often a
    line's width on a log axis, so the legend says how wide it is."""
    half = 50.0 * (fd.model_high - fd.model_low) / fd.model_abs
    half = half[np.isfinite(half)]
    if half.size == 0:
        return "—"
    lo, hi = readable_number(float(np.min(half))), readable_number(float(np.max(half)))
    return f"± {lo} %" if lo == hi else f"± {lo}–{hi} %"


class ReportView(QtWidgets.QWidget):
    """Traces, FRF with the fitted model, phase, coherence and identified values of one or several sessions.

    The right column, top to bottom: a heading, the legend and the f_a/f_r labels (each in its own strip,
    so neither covers a curve), the FRF amplitude, the phase (only when some session's clocks are aligned
    well enough, :attr:`analysis.report.FigureData.phase_valid`) and the coherence, x axes linked; the
    fit band is shaded on all three.

    Parameters
    ----------
    sessions : sequence of SessionFigure
        What to draw; several sessions overlay their curves in distinct colours.
    title : str
        Heading above the plots.

    Attributes
    ----------
    plots : dict of str → pyqtgraph.PlotItem
        ``torque``, ``speed``, ``frf``, (``phase``), ``coherence``; ``marks`` is the f_a/f_r label strip.
    legend : pyqtgraph.LegendItem
        The FRF's legend, above the plot.
    mark_labels : list of pyqtgraph.TextItem
        The f_a/f_r labels, placed in rows of the strip so that none overlaps another.
    panel : QLabel
        The side panel with the identified values.
    """

    def __init__(self, sessions: Sequence[SessionFigure], title: str = "", parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        if not sessions:
            raise ValueError("ReportView needs at least one session")
        self.setWindowTitle(f"acq view — {title}" if title else "acq view")
        self.graphics = pg.GraphicsLayoutWidget()
        layout = self.graphics.ci
        if title:
            layout.addLabel(escape(title), row=0, col=0, colspan=2, size="12pt")
        phase = any(s.figures.phase_valid for s in sessions)
        misfit = any(s.figures.misfit_pct.size == s.figures.f_hz.size for s in sessions)
        layout.addLabel("FRF |ω_m / T_e| with the fitted two-mass model", row=1, col=1, size="11pt")
        self.legend = pg.LegendItem(colCount=1 if len(sessions) > 1 else 3, labelTextSize="9pt")
        layout.addItem(self.legend, row=2, col=1)
        marks = layout.addPlot(row=3, col=1)
        frf_row = 4
        lower = [name for name, shown in (("misfit", misfit), ("phase", phase), ("coherence", True)) if shown]
        bottom_rows = tuple(range(frf_row + 1, frf_row + 1 + len(lower)))
        self.plots = {
            "torque": _plot(layout, 1, 0, "Electromagnetic torque", ("t (drive clock)", "s"), ("T_e", "N·m"),
                            rowspan=frf_row),
            "speed": _plot(layout, bottom_rows[0], 0, "Motor speed", ("t (drive clock)", "s"), ("ω_m", "rad/s"),
                           rowspan=len(bottom_rows)),
            "frf": _plot(layout, frf_row, 1, None, ("f", "Hz"), ("|H|", "rad/(s·N·m)")),
        }
        lower_axes = {"misfit": ("model / measured − 1", "%"), "phase": ("phase of H", "°"),
                      "coherence": ("γ²", "")}
        for name, row in zip(lower, bottom_rows):
            self.plots[name] = _plot(layout, row, 1, None, ("f", "Hz"), lower_axes[name])
        for row, stretch in ((frf_row, 3), *((r, 2) for r in bottom_rows)):
            layout.layout.setRowStretchFactor(row, stretch)
        self.plots["speed"].setXLink(self.plots["torque"])
        frf = self.plots["frf"]
        frf.setLogMode(x=True, y=True)
        for name in lower:
            self.plots[name].setLogMode(x=True, y=False)
            self.plots[name].setXLink(frf)
        self.plots["coherence"].setYRange(0.0, 1.0)
        if phase:
            self.plots["phase"].setYRange(-180.0, 180.0)
            self.plots["phase"].getAxis("left").setTicks([[(float(d), f"{d}") for d in range(-180, 181, 90)], []])
        for name in ("frf", *lower):
            if name in self.plots:
                self.plots[name].getAxis("bottom").setTicks(log_ticks())
                self.plots[name].getAxis("left").setWidth(70)  # one width: the linked x axes line up
        frf.getAxis("left").setTicks(log_ticks())
        self.marks = marks
        self._setup_marks(marks, frf)
        self.mark_labels: list[pg.TextItem] = []
        self.misfit_tested = False  # a session's misfit test drawn (its legend entries then)
        several = len(sessions) > 1
        for i, s in enumerate(sessions):
            self._draw_session(s, i, s.name if several else "")
        if misfit:
            self._misfit_range(sessions)
        if self.misfit_tested:  # the misfit test's line (grey in the legend: the sessions' colours) and allowance
            line = pg.PlotDataItem(pen=pg.mkPen(MEASURED_COLOR if not several else "#888", width=2.5))
            self.legend.addItem(line, "misfit (model / measured − 1), test windows" +
                                (" (in the session's colour)" if several else ""))
            self.legend.addItem(legend_box(*_allowance_style()), "allowed misfit (noise, quantisation)")
        for band in dict.fromkeys(s.figures.band_hz for s in sessions):
            self.legend.addItem(legend_box(self._shade_band(band)), f"fit band {band[0]:g}–{band[1]:g} Hz")
        rows = -(-len(self.legend.items) // self.legend.columnCount)
        layout.layout.setRowFixedHeight(1, 24)
        layout.layout.setRowFixedHeight(2, rows * LEGEND_ROW_PX + 6)
        self.panel = QtWidgets.QLabel(values_html(sessions))
        self.panel.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.panel.setAlignment(QtCore.Qt.AlignmentFlag.AlignTop | QtCore.Qt.AlignmentFlag.AlignLeft)
        self.panel.setWordWrap(True)
        self.panel.setFixedWidth(PANEL_WIDTH_PX * (1 if len(sessions) <= 3 else 2))
        self.panel.setStyleSheet("QLabel { background: white; color: black; padding: 8px; }")
        box = QtWidgets.QHBoxLayout(self)
        box.setContentsMargins(0, 0, 0, 0)
        box.setSpacing(0)
        box.addWidget(self.graphics, stretch=1)
        box.addWidget(self.panel)
        self.resize(*DEFAULT_SIZE_PX)

    @staticmethod
    def _setup_marks(marks: pg.PlotItem, frf: pg.PlotItem) -> None:
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

    def _shade_band(self, band_hz: tuple[float, float]) -> QtGui.QBrush:
        """The fit band, shaded on the FRF, the misfit, the phase and the coherence; returns its brush."""
        brush = pg.mkBrush(0, 0, 0, 14)
        for name in ("frf", "misfit", "phase", "coherence"):
            if name in self.plots:
                region = pg.LinearRegionItem(values=[math.log10(f) for f in band_hz], movable=False, brush=brush,
                                             pen=pg.mkPen(None))
                region.setZValue(-20)
                self.plots[name].addItem(region, ignoreBounds=True)
        return brush

    def _draw_session(self, s: SessionFigure, index: int, name: str) -> None:
        fd = s.figures
        color = COLORS[index % len(COLORS)]
        prefix = f"{name}: " if name else ""
        pen = pg.mkPen(color, width=1.5)
        # the time traces (~5000 points, dense zig-zags) in a 1 px pen: Qt strokes a wider antialiased pen through its
        # general path stroker, which took 1.1 s of the report's 1.4 s CPU for a 60 s session; 1 px takes 0.02 s
        trace_pen = pg.mkPen(color, width=1)
        self.plots["torque"].plot(fd.t_s, fd.torque_Nm, pen=trace_pen, name=f"{prefix}T_e")
        self.plots["speed"].plot(fd.t_s, fd.speed_rad_s, pen=trace_pen, name=f"{prefix}ω_m")
        f, h, coh = _positive(fd.f_hz, fd.H_abs, fd.coherence)
        frf, coherence = self.plots["frf"], self.plots["coherence"]
        faint = _with_alpha(color if name else MEASURED_COLOR, 110)
        measured = frf.plot(f, h, pen=pg.mkPen(faint, width=1), symbol="o", symbolSize=3, symbolPen=None,
                            symbolBrush=faint)
        if not name:
            self.legend.addItem(measured, "measured |H|")
        elif index == 0:  # several sessions: one entry for the dots of all, one per session for its model
            self.legend.addItem(pg.PlotDataItem(pen=None, symbol="o", symbolSize=5, symbolPen=None, symbolBrush="#888"),
                                "measured (dots in the session's colour)")
        coherence.plot(f, coh, pen=pen, name=f"{prefix}γ²")
        phase = self.plots.get("phase") if fd.phase_valid else None
        if phase is not None:
            fp, ph = _positive(fd.f_hz, fd.H_phase_deg)
            phase.plot(fp, ph, pen=None, symbol="o", symbolSize=3, symbolPen=None, symbolBrush=faint)
        mf, model, low, high = _positive(fd.model_f_hz, fd.model_abs, fd.model_low, fd.model_high)
        if mf.size == 0:  # the fit failed: no model, no band, no f_a/f_r
            return
        fill = _with_alpha(color, 70)
        low_curve = frf.plot(mf, low, pen=pg.mkPen(_with_alpha(color, 110), width=1))
        high_curve = frf.plot(mf, high, pen=pg.mkPen(_with_alpha(color, 110), width=1))
        frf.addItem(pg.FillBetweenItem(low_curve, high_curve, brush=fill))
        model_pen = pg.mkPen(color, width=2)
        frf.plot(mf, model, pen=model_pen)
        self.legend.addItem(legend_box(pg.mkBrush(fill), model_pen), f"{prefix}two-mass fit, 95 % band "
                                                                      f"{band_width_text(fd)}")
        if phase is not None:
            mp, model_phase = _positive(fd.model_f_hz, fd.model_phase_deg)
            phase.plot(mp, model_phase, pen=model_pen)
        misfit = self.plots.get("misfit")
        if misfit is not None and fd.misfit_pct.size == fd.f_hz.size:  # the model's own 95 % band about 0
            with np.errstate(divide="ignore", invalid="ignore"):
                rel_low, rel_high = 100.0 * (low / model - 1.0), 100.0 * (high / model - 1.0)
            misfit.addItem(pg.FillBetweenItem(misfit.plot(mf, rel_low, pen=pg.mkPen(_with_alpha(color, 110))),
                                              misfit.plot(mf, rel_high, pen=pg.mkPen(_with_alpha(color, 110))),
                                              brush=fill))
            misfit.addItem(pg.InfiniteLine(pos=0.0, angle=0, movable=False, pen=model_pen), ignoreBounds=True)
            fm, pct = _positive(fd.f_hz, fd.misfit_pct)
            misfit.plot(fm, pct, pen=None, symbol="o", symbolSize=4, symbolPen=None, symbolBrush=faint)
            self._draw_misfit_test(fd, misfit, color if name else MEASURED_COLOR)
        for label, f_hz in (("f_a", fd.f_a_hz), ("f_r", fd.f_r_hz)):
            if math.isfinite(f_hz) and f_hz > 0:
                for plot in (frf, phase):
                    if plot is not None:
                        line = pg.InfiniteLine(pos=math.log10(f_hz), angle=90, movable=False,
                                               pen=pg.mkPen(color, width=1, style=QtCore.Qt.PenStyle.DashLine))
                        line.setObjectName(f"{prefix}{label}")
                        plot.addItem(line)
                text = pg.TextItem(f"{label} {f_hz:.1f} Hz", color=color, anchor=(0.5, 0.5))
                text.setPos(math.log10(f_hz), 0.5)
                self.marks.addItem(text, ignoreBounds=True)
                self.mark_labels.append(text)
        for label, low_hz, high_hz in verdict_marks(fd):
            for plot in (frf, misfit, phase):
                if plot is not None:
                    plot.addItem(_verdict_mark(low_hz, high_hz, f"{prefix}{label}"), ignoreBounds=True)
            where = f"≈ {low_hz:.0f} Hz" if low_hz == high_hz else f"{low_hz:.0f}–{high_hz:.0f} Hz"
            text = pg.TextItem(f"{prefix}{label} {where}", color=VERDICT_MARK_COLOR, anchor=(0.5, 0.5))
            text.setPos(0.5 * (math.log10(low_hz) + math.log10(high_hz)), 0.5)
            self.marks.addItem(text, ignoreBounds=True)
            self.mark_labels.append(text)
        place_marks(self.marks)

    def _draw_misfit_test(self, fd: FigureData, plot: pg.PlotItem, color: str) -> None:
        """What the verdict's misfit test weighed (:attr:`analysis.report.FigureData.misfit_windows`): each window's
        mean misfit (a line through the windows' centres, %, in ``color``) and the allowance it was held to (shaded
        about 0); a window beyond it is what the verdict names. The legend's entries come once, after the sessions."""
        windows = fd.misfit_windows.reshape(-1, 4)
        windows = windows[np.all(np.isfinite(windows), axis=1)]
        if windows.shape[0] < 2:
            return
        centre = np.sqrt(windows[:, 0] * windows[:, 1])
        mean_pct, upper, lower = (100.0 * np.expm1(windows[:, 2]), 100.0 * np.expm1(windows[:, 3]),
                                  100.0 * np.expm1(-windows[:, 3]))
        brush, edge = _allowance_style()
        plot.addItem(pg.FillBetweenItem(plot.plot(centre, lower, pen=edge), plot.plot(centre, upper, pen=edge),
                                        brush=brush))
        plot.plot(centre, mean_pct, pen=pg.mkPen(color, width=2.5))
        self.misfit_tested = True

    def _misfit_range(self, sessions: Sequence[SessionFigure]) -> None:
        """The misfit panel's y range: 1.5 × the largest window mean of the misfit test (what the verdict weighs),
        else (no test made) the 2nd…98th percentiles of the bins' misfits; at least ± :data:`MISFIT_MIN_RANGE_PCT`.
        Single bins scatter far wider where the coherence falls (and at f_a, where |H| dips to the noise floor):
        they would flatten the window means the verdict is about; they are drawn, partly off the range."""
        means = [100.0 * np.expm1(s.figures.misfit_windows[:, 2]) for s in sessions if s.figures.misfit_windows.size]
        joined = np.concatenate(means) if means else np.empty(0)
        joined = joined[np.isfinite(joined)]
        if joined.size:
            span = 1.5 * float(np.max(np.abs(joined)))
        else:
            bins = np.concatenate([s.figures.misfit_pct for s in sessions])
            bins = bins[np.isfinite(bins)]
            span = float(np.max(np.abs(np.percentile(bins, [2.0, 98.0])))) if bins.size else 0.0
        span = max(span, MISFIT_MIN_RANGE_PCT)
        self.plots["misfit"].setYRange(-1.1 * span, 1.1 * span, padding=0.0)


def verdict_marks(fd: FigureData) -> list[tuple[str, float, float]]:
    """What the verdict names on the FRF: (label, low Hz, high Hz) of the misfit band and of a third mode (a
    single frequency: low = high)."""
    marks = [("misfit", *fd.misfit_band_hz), ("third mode", fd.third_mode_hz, fd.third_mode_hz)]
    return [(label, lo, hi) for label, lo, hi in marks if math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi]


def _verdict_mark(low_hz: float, high_hz: float, name: str) -> pg.GraphicsObject:
    """A verdict's mark at log10(f): a dash-dot line at one frequency, a shaded span over a band."""
    if low_hz == high_hz:
        mark = pg.InfiniteLine(pos=math.log10(low_hz), angle=90, movable=False,
                               pen=pg.mkPen(VERDICT_MARK_COLOR, width=2, style=QtCore.Qt.PenStyle.DashDotLine))
    else:
        mark = pg.LinearRegionItem(values=[math.log10(low_hz), math.log10(high_hz)], movable=False,
                                   brush=pg.mkBrush(_with_alpha(VERDICT_MARK_COLOR, 60)),
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


def log_ticks() -> list[list[tuple[float, str]]]:
    """Ticks of a log axis in view coordinates (log10): 1·10ⁿ labelled, 2 and 5 ·10ⁿ labelled minor."""
    major = [(float(n), f"{10.0**n:g}") for n in _LOG_TICK_DECADES]
    minor = [(math.log10(m * 10.0**n), f"{m * 10.0**n:g}") for n in _LOG_TICK_DECADES for m in (2, 5)]
    return [major, minor]


def _positive(f_hz: np.ndarray, *ys: np.ndarray) -> tuple[np.ndarray, ...]:
    """Keep the points with f > 0 and every value finite (log axes)."""
    keep = (np.asarray(f_hz) > 0) & np.isfinite(f_hz)
    for y in ys:
        keep &= np.isfinite(y)
    return (np.asarray(f_hz)[keep], *(np.asarray(y)[keep] for y in ys))


def values_html(sessions: Sequence[SessionFigure]) -> str:
    """The side panel: identified values with 95 % intervals, f_a, f_r, clock and verdict, one block per session."""
    parts = ["<h3>Identified two-mass model (motor side)</h3>"]  # K, J through the gear as the motor sees them
    for i, s in enumerate(sessions):
        color = COLORS[i % len(COLORS)]
        parts.append(f"<p><b style='color:{color}'>{escape(s.name)}</b></p>")
        v = s.values
        if not v:
            parts.append("<p>no identified values</p>")
            continue
        rows = []
        for key, name, unit in PARAMS:
            rows.append((name, format_value(v.get(key)), interval_text(v, key, relative=True), unit))
        clock = v.get("clock", {})
        rows += [("f_a", format_value(v.get("antiresonance_hz")), "", "Hz"),
                 ("f_r", format_value(v.get("resonance_hz")), "", "Hz"),
                 ("clock offset", format_value(clock.get("offset_s"), scale=1e3), "", "ms"),
                 ("clock drift", format_value(clock.get("drift_ppm")), "", "ppm"),
                 ("clock residual", format_value(clock.get("residual_s"), scale=1e6), "", "µs")]
        quality = v.get("quality", {})
        table = "".join(f"<tr><td nowrap>{escape(n)}</td><td align='right'><b>{val}</b></td>"
                        f"<td align='right' nowrap>{ci}</td><td nowrap>{escape(u)}</td></tr>" for n, val, ci, u in rows)
        parts.append("<table cellspacing='0' cellpadding='2'><tr><th></th><th>value</th><th>95 % CI</th><th></th></tr>"
                     f"{table}</table>")
        # a value the data do not determine: its interval, whose ends the relative "± 360 %" hid
        wide = [f"{name} {format_value(v.get(key))} {escape(unit)}: its 95 % interval "
                f"{' – '.join(readable_number(b) for b in v['ci95'][key])} does not determine it"
                for key, name, unit in PARAMS if not_determined(v, key)]
        if wide:
            parts.append(f"<p>{'<br>'.join(wide)}</p>")
        parts.append(f"<p>verdict <b>{escape(str(quality.get('verdict', '—')))}</b>, mean γ² in band "
                     f"{format_value(quality.get('mean_coherence'), '.3g')}</p>")
        parts.append(f"<p>{escape(phase_text(s))}</p><p><i>{escape(options_text(v))}</i></p>")
        reasons = [r for r in quality.get("reasons", []) if not r.startswith("note: ")]
        if reasons:
            parts.append("<ul>" + "".join(f"<li>{escape(r)}</li>" for r in reasons) + "</ul>")
    return "".join(parts)


def phase_text(s: SessionFigure) -> str:
    """Why the phase is shown or not: the clock residual against the limit a complex fit accepts."""
    limit_us = 1e6 * Thresholds().clock_residual_complex_s
    residual = s.values.get("clock", {}).get("residual_s")
    if s.figures.phase_valid:
        return f"phase shown: clocks aligned to {1e6 * residual:.0f} µs (limit {limit_us:.0f} µs)"
    if residual is None:
        return "phase not shown: the clocks were not aligned"
    return f"phase not shown: clock residual {1e6 * residual:.0f} µs exceeds {limit_us:.0f} µs"


def grab_png(widget: QtWidgets.QWidget, path: Path | str, size: tuple[int, int] = DEFAULT_SIZE_PX) -> Path:
    """Draw ``widget`` at exactly ``size`` (width, height) pixels into the PNG ``path``, written atomically
    (:func:`acq.recording.storage.atomic_path`): the one writer of the pictures acq draws on request (``acq trend
    --png``, ``acq fleet --png``, ``acq view --screenshot``). A failed write raises :class:`StorageError` naming
    ``path`` and the cause ("read-only file system: out.png"), exit 1; no partial file is left.
    """
    path = Path(path)
    image = _widget_image(widget, size)
    try:
        make_folders(path.parent)
    except OSError as e:
        raise storage_error(e, path) from None
    with atomic_path(path) as tmp:
        _save_png(image, tmp)
    return path


def _widget_image(widget: QtWidgets.QWidget, size: tuple[int, int]) -> QtGui.QImage:
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


def _save_png(image: QtGui.QImage, path: Path) -> None:
    """Write ``image`` as a PNG to ``path`` as it stands (the caller makes it atomic); Qt says only whether it could,
    so a failure is an :class:`OSError` without errno (:func:`acq.recording.storage.atomic_path` then names the
    cause: disk full, else I/O error)."""
    if not image.save(str(path), "PNG"):
        raise OSError(f"{path}: could not write the PNG")


def render_report_png(figure_data: FigureData, path: Path | str, size: tuple[int, int] = DEFAULT_SIZE_PX, *,
                      title: str = "", values: dict[str, Any] | None = None) -> Path:
    """Write ``<session>.report.png``: the :class:`ReportView` of one session, drawn offscreen.

    Parameters
    ----------
    figure_data : FigureData
        The analysis's figure data.
    path : Path or str
        PNG to write.
    size : (int, int)
        Image width and height, px.
    title : str
        Heading (e.g. joint and session file name).
    values : dict, optional
        The ``.result.json`` document for the side panel.

    Returns
    -------
    Path
        ``path``.
    """
    ensure_app(offscreen=True)
    view = ReportView([SessionFigure(title or "session", figure_data, values or {})], title=title)
    try:  # written as it stands: its caller writes it atomically, putting it in place only if still current
        _save_png(_widget_image(view, size), Path(path))
        return Path(path)
    finally:
        shiboken6.delete(view)  # now, not at interpreter exit after the QApplication (that segfaults)
