"""The report figure in pyqtgraph, one implementation for the ``acq view`` window and the PNG.

:class:`ReportView` lays out, for one or several sessions (each its own colour):

* ``torque`` and ``speed``: the time traces on the aligned (drive) time base, x axes linked;
* ``frf``: measured |H| = |ω_m/T_e| on log–log axes with the fitted two-mass model, its 95 % band
  and f_a/f_r marked (vertical lines), a legend naming the sessions;
* ``coherence``: γ² under it, x axis linked to the FRF's;
* a side panel with the identified values, their 95 % intervals, the clock relation and the verdict.

:func:`render_report_png` draws the same widget offscreen into an image of an exact pixel size;
``acq view --screenshot`` uses it too. Log axes: pyqtgraph transforms data items, not other items,
so the f_a/f_r lines sit at log10(f) in view coordinates.
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

from acq.display import PARAMS, format_value
from analysis.report import FigureData

pg.setConfigOptions(background="w", foreground="k", antialias=True)

#: Colours of the sessions, in order (repeats after the last).
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
PANEL_WIDTH_PX = 360
_LOG_TICK_DECADES = range(-6, 7)
DEFAULT_SIZE_PX = (1600, 1000)


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


def _plot(layout: pg.GraphicsLayout, row: int, col: int, title: str,
          x: tuple[str, str], y: tuple[str, str]) -> pg.PlotItem:
    plot = layout.addPlot(row=row, col=col, title=title)  # unnamed: pyqtgraph's view registry fails at teardown
    for side, (text, units) in (("bottom", x), ("left", y)):
        axis = plot.getAxis(side)
        axis.enableAutoSIPrefix(False)
        plot.setLabel(side, text, units=units or None)
    plot.showGrid(x=True, y=True, alpha=0.25)
    return plot


class ReportView(QtWidgets.QWidget):
    """Traces, FRF with the fitted model, coherence and identified values of one or several sessions.

    Parameters
    ----------
    sessions : sequence of SessionFigure
        What to draw; several sessions overlay their curves in distinct colours.
    title : str
        Heading above the plots.

    Attributes
    ----------
    plots : dict of str → pyqtgraph.PlotItem
        ``torque``, ``speed``, ``frf``, ``coherence``.
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
        self.plots = {
            "torque": _plot(layout, 1, 0, "Electromagnetic torque", ("t (drive clock)", "s"), ("T_e", "N·m")),
            "speed": _plot(layout, 2, 0, "Motor speed", ("t (drive clock)", "s"), ("ω_m", "rad/s")),
            "frf": _plot(layout, 1, 1, "FRF amplitude |ω_m / T_e|", ("f", "Hz"), ("|H|", "rad/(s·N·m)")),
            "coherence": _plot(layout, 2, 1, "Coherence", ("f", "Hz"), ("γ²", "")),
        }
        self.plots["speed"].setXLink(self.plots["torque"])
        self.plots["coherence"].setXLink(self.plots["frf"])
        self.plots["frf"].setLogMode(x=True, y=True)
        self.plots["coherence"].setLogMode(x=True, y=False)
        self.plots["coherence"].setYRange(0.0, 1.0)
        for name, side in (("frf", "bottom"), ("frf", "left"), ("coherence", "bottom")):
            self.plots[name].getAxis(side).setTicks(log_ticks())
        self.plots["frf"].addLegend(offset=(-10, 10))
        several = len(sessions) > 1
        for i, s in enumerate(sessions):
            self._draw_session(s, i, s.name if several else "")
        self.panel = QtWidgets.QLabel(values_html(sessions))
        self.panel.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.panel.setAlignment(QtCore.Qt.AlignmentFlag.AlignTop | QtCore.Qt.AlignmentFlag.AlignLeft)
        self.panel.setWordWrap(True)
        self.panel.setFixedWidth(PANEL_WIDTH_PX * (1 if len(sessions) < 3 else 2))
        self.panel.setStyleSheet("QLabel { background: white; color: black; padding: 8px; }")
        box = QtWidgets.QHBoxLayout(self)
        box.setContentsMargins(0, 0, 0, 0)
        box.setSpacing(0)
        box.addWidget(self.graphics, stretch=1)
        box.addWidget(self.panel)
        self.resize(*DEFAULT_SIZE_PX)

    def _draw_session(self, s: SessionFigure, index: int, name: str) -> None:
        fd = s.figures
        color = COLORS[index % len(COLORS)]
        prefix = f"{name}: " if name else ""
        pen = pg.mkPen(color, width=1.5)
        self.plots["torque"].plot(fd.t_s, fd.torque_Nm, pen=pen, name=f"{prefix}T_e")
        self.plots["speed"].plot(fd.t_s, fd.speed_rad_s, pen=pen, name=f"{prefix}ω_m")
        f, h, coh = _positive(fd.f_hz, fd.H_abs, fd.coherence)
        frf, coherence = self.plots["frf"], self.plots["coherence"]
        faint = QtGui.QColor(color)
        faint.setAlpha(110)
        frf.plot(f, h, pen=pg.mkPen(faint, width=1), symbol="o", symbolSize=3, symbolPen=None,
                 symbolBrush=faint, name=f"{prefix}measured")
        coherence.plot(f, coh, pen=pen, name=f"{prefix}γ²")
        mf, model, low, high = _positive(fd.model_f_hz, fd.model_abs, fd.model_low, fd.model_high)
        if mf.size == 0:  # the fit failed: no model, no band, no f_a/f_r
            return
        edge = QtGui.QColor(color)
        edge.setAlpha(80)
        fill = QtGui.QColor(color)
        fill.setAlpha(45)
        low_curve = frf.plot(mf, low, pen=pg.mkPen(edge, width=1))
        high_curve = frf.plot(mf, high, pen=pg.mkPen(edge, width=1))
        frf.addItem(pg.FillBetweenItem(low_curve, high_curve, brush=fill))
        frf.plot(mf, model, pen=pg.mkPen(color, width=2.5), name=f"{prefix}two-mass fit, 95 % band")
        for label, f_hz in (("f_a", fd.f_a_hz), ("f_r", fd.f_r_hz)):
            if math.isfinite(f_hz) and f_hz > 0:
                line = pg.InfiniteLine(pos=math.log10(f_hz), angle=90, movable=False,
                                       pen=pg.mkPen(color, width=1, style=QtCore.Qt.PenStyle.DashLine),
                                       label=f"{label} {f_hz:.1f} Hz",
                                       labelOpts={"position": min(0.9, 0.06 + 0.08 * (2 * index + (label == "f_r"))), "color": color,
                                                  "fill": (255, 255, 255, 200)})
                line.setObjectName(f"{prefix}{label}")
                frf.addItem(line)


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


def _halfwidth(value: float | None, ci: Sequence[float | None] | None) -> str:
    """The 95 % interval as ± its half-width relative to the value, %."""
    if value is None or not ci or None in ci or value == 0:
        return "—"
    return f"± {50.0 * (ci[1] - ci[0]) / abs(value):.2g} %"


def values_html(sessions: Sequence[SessionFigure]) -> str:
    """The side panel: identified values with 95 % intervals, f_a, f_r, clock and verdict, one block per session."""
    parts = ["<h3>Identified two-mass model</h3>"]
    for i, s in enumerate(sessions):
        color = COLORS[i % len(COLORS)]
        parts.append(f"<p><b style='color:{color}'>{escape(s.name)}</b></p>")
        v = s.values
        if not v:
            parts.append("<p>no identified values</p>")
            continue
        rows = []
        for key, name, unit in PARAMS:
            rows.append((name, format_value(v.get(key)), _halfwidth(v.get(key), v.get("ci95", {}).get(key)), unit))
        clock = v.get("clock", {})
        rows += [("f_a", format_value(v.get("antiresonance_hz")), "", "Hz"),
                 ("f_r", format_value(v.get("resonance_hz")), "", "Hz"),
                 ("clock offset", format_value(clock.get("offset_s"), scale=1e3), "", "ms"),
                 ("clock drift", format_value(clock.get("drift_ppm")), "", "ppm"),
                 ("clock residual", format_value(clock.get("residual_s"), scale=1e6), "", "µs")]
        quality = v.get("quality", {})
        table = "".join(f"<tr><td>{escape(n)}</td><td align='right'><b>{val}</b></td>"
                        f"<td align='right'>{ci}</td><td>{escape(u)}</td></tr>" for n, val, ci, u in rows)
        parts.append("<table cellspacing='0' cellpadding='2'><tr><th></th><th>value</th><th>95 % CI</th><th></th></tr>"
                     f"{table}</table>")
        parts.append(f"<p>verdict <b>{escape(str(quality.get('verdict', '—')))}</b>, mean γ² in band "
                     f"{format_value(quality.get('mean_coherence'), '.3g')}</p>")
        reasons = [r for r in quality.get("reasons", []) if not r.startswith("note: ")]
        if reasons:
            parts.append("<ul>" + "".join(f"<li>{escape(r)}</li>" for r in reasons) + "</ul>")
    return "".join(parts)


def grab_png(widget: QtWidgets.QWidget, path: Path | str, size: tuple[int, int] = DEFAULT_SIZE_PX) -> Path:
    """Draw ``widget`` at exactly ``size`` (width, height) pixels into a PNG.

    The widget is shown (on the offscreen platform this puts nothing on a screen) so that its
    layout is activated, then rendered into an image of that size, whatever the device-pixel ratio.
    (``WA_DontShowOnScreen`` would avoid a flash on a real screen but makes PySide 6.12 abort at exit.)
    """
    path = Path(path)
    widget.resize(*size)
    widget.show()
    QtWidgets.QApplication.processEvents()
    image = QtGui.QImage(size[0], size[1], QtGui.QImage.Format.Format_RGB32)
    image.fill(QtGui.QColor("white"))
    widget.render(image)
    widget.hide()
    path.parent.mkdir(parents=True, exist_ok=True)
    if not image.save(str(path), "PNG"):
        raise OSError(f"{path}: could not write the PNG")
    return path


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
    try:
        return grab_png(view, path, size)
    finally:
        shiboken6.delete(view)  # now, not at interpreter exit after the QApplication (that segfaults)
