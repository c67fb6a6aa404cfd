"""The report figure in pyqtgraph, one implementation for the ``acq view`` window and the PNG.

:class:`ReportView` lays out, for one or several sessions (each its own colour):

* ``torque`` and ``speed``: the time traces on the aligned (drive) time base, x axes linked;
* ``frf``: measured |H| = |ω_m/T_e| on log–log axes (one session: dark grey dots) with the fitted two-mass model
  and its 95 % band (the session's colour, shaded; the legend says its width, as it is often a line's width),
  f_a/f_r marked by vertical lines, and what a ``poor`` verdict names there (also on the phase,
  :mod:`acq.ui.report_marks`); the legend and the f_a/f_r labels sit in strips of their own above the plot, so
  they never cover a curve;
* ``misfit``: how far the model misses the measured |H|, model / measured − 1 in % over the fit band (the sign of
  the verdict's "misses by +5.9 %"), with the model's 95 % band about 0 and the verdict's marks: a misfit the
  verdict names, which a log axis hides (6 % is 0.025 decades);
* ``phase``: measured and model phase, when the clocks were aligned well enough for a phase to be the
  plant's (the residual a complex fit accepts, :func:`analysis.verdict_limits.phase_is_meaningful`);
* ``coherence``: γ²; FRF, phase and coherence share their x axis and show the fit band shaded;
* a side panel with the identified values, their 95 % intervals, the clock relation, the verdict and
  the options the result came from (:mod:`acq.ui.report_panel`).

:func:`render_report_png` draws the same widget offscreen into an image of an exact pixel size;
``acq view --screenshot`` draws it through :func:`acq.ui.qt_app.grab_png`. Log axes: pyqtgraph transforms data
items, not other items, so the f_a/f_r lines, labels and the fit band sit at log10(f) in view coordinates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from html import escape
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
import shiboken6
from pyqtgraph.Qt import QtCore, QtGui, QtWidgets

from acq.ui.plot_style import COLORS, TITLE_SIZE, add_plot, legend_box, log_ticks, positive, with_alpha
from acq.ui.qt_app import DEFAULT_SIZE_PX, ensure_app, save_png, widget_image
from acq.ui.report_marks import VERDICT_MARK_COLOR, place_marks, setup_mark_strip, verdict_mark, verdict_marks
from acq.ui.report_panel import SessionFigure, values_html
from acq.ui.values import fit_failed, readable_number
from analysis import FigureData

PANEL_WIDTH_PX = 360  # the side panel's width (twice that for more than three sessions)
LEGEND_ROW_PX = 20  # height of a legend row (9 pt text, pyqtgraph's 20 px samples)
#: Width of the time traces' y axes, px: one width, so that the two linked time axes line up (each axis sized itself
#: to its tick labels: torque's 18 px narrower than speed's) and the report's minimum size is known before it is drawn
#: (:meth:`ReportView.minimum_size`); room for four characters of tick label ("-100", "0.05") beside the axis's name.
TRACE_AXIS_PX = 56
#: The measured |H| of a single session: dark grey, apart from the model in the session's colour (both were blue). With
#: several sessions the colour tells the sessions apart, and the measured dots are a faint shade of it.
MEASURED_COLOR = "#404040"
#: The allowance of the verdict's misfit test, shaded on the misfit panel.
ALLOWANCE_COLOR = "#2ca02c"
#: The misfit panel's y range: at least ± this, % (a model that fits to ±1 % is drawn flat, not as noise magnified).
MISFIT_MIN_RANGE_PCT = 5.0


def _allowance_style() -> tuple[QtGui.QBrush, QtGui.QPen]:
    """Brush and edge of the misfit test's allowance (on the misfit panel and in the legend)."""
    return pg.mkBrush(with_alpha(ALLOWANCE_COLOR, 70)), pg.mkPen(with_alpha(ALLOWANCE_COLOR, 160), width=1)


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
        layout.addLabel("FRF |ω_m / T_e| with the fitted two-mass model", row=1, col=1, size=TITLE_SIZE)
        # two columns, not three: three made the scene at least 1076 px wide, wider than the plots get in a 1200 px
        # window (its right part cut off: the FRF above 80 Hz, f_r's label, the title); one where two do not fit
        # (resizeEvent)
        self.legend = pg.LegendItem(colCount=1 if len(sessions) > 1 else 2, labelTextSize="9pt")
        layout.addItem(self.legend, row=2, col=1)
        marks = layout.addPlot(row=3, col=1)
        frf_row = 4
        lower = [name for name, shown in (("misfit", misfit), ("phase", phase), ("coherence", True)) if shown]
        bottom_rows = tuple(range(frf_row + 1, frf_row + 1 + len(lower)))
        self.plots = {
            "torque": add_plot(layout, 1, 0, "Electromagnetic torque", ("t (drive clock)", "s"), ("T_e", "N·m"),
                            rowspan=frf_row),
            "speed": add_plot(layout, bottom_rows[0], 0, "Motor speed", ("t (drive clock)", "s"), ("ω_m", "rad/s"),
                           rowspan=len(bottom_rows)),
            "frf": add_plot(layout, frf_row, 1, None, ("f", "Hz"), ("|H|", "rad/(s·N·m)")),
        }
        # "misfit", as the legend names it (with what it is): the whole formula was taller than the panel at 1200×800
        # and ran into the |H| and phase labels
        lower_axes = {"misfit": ("misfit", "%"), "phase": ("phase of H", "°"),
                      "coherence": ("γ²", "")}
        for name, row in zip(lower, bottom_rows):
            self.plots[name] = add_plot(layout, row, 1, None, ("f", "Hz"), lower_axes[name])
        for row, stretch in ((frf_row, 3), *((r, 2) for r in bottom_rows)):
            layout.layout.setRowStretchFactor(row, stretch)
        layout.layout.setColumnStretchFactor(1, 2)  # the frequency panels twice the traces' width where there is room
        self.plots["speed"].setXLink(self.plots["torque"])
        for name in ("torque", "speed"):
            self.plots[name].getAxis("left").setWidth(TRACE_AXIS_PX)
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
        setup_mark_strip(marks, frf)
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
        layout.layout.setRowFixedHeight(1, 24)
        self._legend_columns = self.legend.columnCount  # where they fit
        self._set_legend_columns(self._legend_columns)
        self._legend_columns_min_px = layout.layout.minimumSize().width()  # the plots' narrowest with them
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
        self.setMinimumSize(*self.minimum_size())  # a window made smaller would cut plots off
        self.resize(*DEFAULT_SIZE_PX)

    def minimum_size(self) -> tuple[int, int]:
        """The smallest (width, height), px, at which nothing is cut off: the plots at their narrowest (the legend in
        one column) beside the side panel, as high as the higher of the two. One session: 921×446 px."""
        columns = self.legend.columnCount
        self._set_legend_columns(1)
        plots = self.graphics.ci.layout.minimumSize()
        self._set_legend_columns(columns)
        panel_px = self.panel.minimumWidth()
        return (math.ceil(plots.width()) + panel_px,
                max(math.ceil(plots.height()), self.panel.heightForWidth(panel_px)))

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:  # noqa: N802 - Qt's name
        """The legend in its columns where they fit beside the panel, else in one (two made the plots 828 px wide at
        least, which a 1000 px window gave 640: the FRF was cut off at 60 Hz, f_r with it)."""
        room_px = event.size().width() - self.panel.minimumWidth()
        self._set_legend_columns(self._legend_columns if room_px >= self._legend_columns_min_px else 1)
        super().resizeEvent(event)

    def _set_legend_columns(self, columns: int) -> None:
        """Lay the legend out in ``columns`` columns, its row as high as its rows."""
        self.legend.setColumnCount(columns)
        self.graphics.ci.layout.setRowFixedHeight(2, self.legend.rowCount * LEGEND_ROW_PX + 6)

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
        f, h, coh = positive(fd.f_hz, fd.H_abs, fd.coherence)
        frf, coherence = self.plots["frf"], self.plots["coherence"]
        faint = with_alpha(color if name else MEASURED_COLOR, 110)
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
            fp, ph = positive(fd.f_hz, fd.H_phase_deg)
            phase.plot(fp, ph, pen=None, symbol="o", symbolSize=3, symbolPen=None, symbolBrush=faint)
        mf, model, low, high = positive(fd.model_f_hz, fd.model_abs, fd.model_low, fd.model_high)
        if mf.size == 0:  # the fit failed: no model, no band, no f_a/f_r
            return
        fill = with_alpha(color, 70)
        low_curve = frf.plot(mf, low, pen=pg.mkPen(with_alpha(color, 110), width=1))
        high_curve = frf.plot(mf, high, pen=pg.mkPen(with_alpha(color, 110), width=1))
        frf.addItem(pg.FillBetweenItem(low_curve, high_curve, brush=fill))
        model_pen = pg.mkPen(color, width=2)
        frf.plot(mf, model, pen=model_pen)
        failed = fit_failed(s.values)  # drawn to show how it misses, its f_a and f_r without numbers
        self.legend.addItem(legend_box(pg.mkBrush(fill), model_pen),
                            f"{prefix}{'failed ' if failed else ''}two-mass fit, 95 % band {band_width_text(fd)}")
        if phase is not None:
            mp, model_phase = positive(fd.model_f_hz, fd.model_phase_deg)
            phase.plot(mp, model_phase, pen=model_pen)
        misfit = self.plots.get("misfit")
        if misfit is not None and fd.misfit_pct.size == fd.f_hz.size:  # the model's own 95 % band about 0
            with np.errstate(divide="ignore", invalid="ignore"):
                rel_low, rel_high = 100.0 * (low / model - 1.0), 100.0 * (high / model - 1.0)
            misfit.addItem(pg.FillBetweenItem(misfit.plot(mf, rel_low, pen=pg.mkPen(with_alpha(color, 110))),
                                              misfit.plot(mf, rel_high, pen=pg.mkPen(with_alpha(color, 110))),
                                              brush=fill))
            misfit.addItem(pg.InfiniteLine(pos=0.0, angle=0, movable=False, pen=model_pen), ignoreBounds=True)
            fm, pct = positive(fd.f_hz, fd.misfit_pct)
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
                text = pg.TextItem(f"{label} of the failed fit" if failed else f"{label} {f_hz:.1f} Hz", color=color,
                                   anchor=(0.5, 0.5))
                text.setPos(math.log10(f_hz), 0.5)
                self.marks.addItem(text, ignoreBounds=True)
                self.mark_labels.append(text)
        for label, low_hz, high_hz in verdict_marks(fd):
            for plot in (frf, misfit, phase):
                if plot is not None:
                    plot.addItem(verdict_mark(low_hz, high_hz, f"{prefix}{label}"), ignoreBounds=True)
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
        save_png(widget_image(view, size), Path(path))
        return Path(path)
    finally:
        shiboken6.delete(view)  # now, not at interpreter exit after the QApplication (that segfaults)
