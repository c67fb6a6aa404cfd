"""The stiffness trend of :mod:`acq.monitoring.trend` drawn: a pyqtgraph figure (``acq trend --png``, ``acq view
--trend``) and its PNG."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from acq.monitoring.trend import ELAPSED_TAG, Trend, TrendPoint
from acq.ui.values import alarm_rules_line, clock_text


def render_trend_png(trend: Trend, path: Path | str, size: tuple[int, int] = (1400, 900)) -> Path:
    """Draw :func:`trend_widget` offscreen into a PNG of ``size`` (width, height) px."""
    from acq.ui.offscreen_png import render_offscreen_png

    return render_offscreen_png(lambda: trend_widget(trend), path, size)


def trend_widget(trend: Trend) -> Any:
    """The trend figure (needs a QApplication): K with its 95 % intervals, baseline, threshold, EWMA and its
    limit, alarms in red (top); f_a and f_r (bottom). x is the session's place in time, labelled with its start."""
    import numpy as np
    import pyqtgraph as pg
    from pyqtgraph.Qt import QtCore, QtWidgets

    frame = QtWidgets.QWidget()
    widget = pg.GraphicsLayoutWidget()
    QtWidgets.QVBoxLayout(frame).addWidget(widget)
    widget.ci.addLabel(f"stiffness trend — {trend.joint}" + ("  (ALARM)" if trend.alarm else ""), row=0, col=0,
                       size="14pt")
    legend = pg.LegendItem(colCount=3, labelTextSize="10pt")  # a row of its own: it never covers a point
    widget.ci.addItem(legend, row=1, col=0)
    k_plot = widget.addPlot(row=2, col=0)
    f_plot = widget.addPlot(row=3, col=0)
    widget.ci.layout.setRowStretchFactor(2, 3)
    widget.ci.layout.setRowStretchFactor(3, 2)
    k_plot.setXLink(f_plot)
    k_plot.getAxis("bottom").setStyle(showValues=False)  # the f plot under it names the sessions
    pts = [(i, p) for i, p in enumerate(trend.points) if p.entry.K_Nm_per_rad is not None]
    x = np.array([i for i, _ in pts], dtype=float)
    k = np.array([p.entry.K_Nm_per_rad for _, p in pts], dtype=float)
    lo = np.array([p.entry.K_ci95[0] if p.entry.K_ci95[0] is not None else np.nan for _, p in pts], dtype=float)
    hi = np.array([p.entry.K_ci95[1] if p.entry.K_ci95[1] is not None else np.nan for _, p in pts], dtype=float)
    # intervals of the judged points only: a skipped point's (often wild) interval would be a bar without its dot
    barred = np.array([_category(p) != "skipped" for _, p in pts], dtype=bool)
    k_plot.addItem(pg.ErrorBarItem(x=x[barred], y=k[barred], top=np.nan_to_num(hi - k)[barred],
                                   bottom=np.nan_to_num(k - lo)[barred], beam=0.2, pen=pg.mkPen("#555", width=1.5)))
    colors = {"baseline": "#17becf", "ok": "#1f77b4", "alarm: EWMA": "#ff7f0e", "alarm: threshold": "#d62728",
              "skipped": "#bbbbbb", "before baseline": "#bbbbbb"}
    for state, color in colors.items():
        sel = [j for j, (_, p) in enumerate(pts) if _category(p) == state]
        if sel:
            legend.addItem(k_plot.plot(x[sel], k[sel], pen=None, symbol="o", symbolSize=11, symbolBrush=color), state)
    base = trend.baseline_K_Nm_per_rad
    if base is not None:
        legend.addItem(k_plot.plot(x[:1], [base], pen=pg.mkPen("#17becf", width=3)), f"baseline {base:.1f} N·m/rad")
        k_plot.addLine(y=base, pen=pg.mkPen("#17becf", width=3))
        threshold = base * (1 - trend.threshold_pct / 100)
        dashed_red = pg.mkPen("#d62728", width=2, style=QtCore.Qt.PenStyle.DashLine)
        legend.addItem(k_plot.plot(x[:1], [threshold], pen=dashed_red),
                       f"threshold −{trend.threshold_pct:g} % ({threshold:.1f})")
        k_plot.addLine(y=threshold, pen=dashed_red)
        levels = [base, threshold]
        judged = [(i, p) for i, p in enumerate(trend.points) if p.ewma_change_pct is not None]
        if judged:
            jx = np.array([i for i, _ in judged], dtype=float)
            ewma = [base * (1 + p.ewma_change_pct / 100) for _, p in judged]  # type: ignore[operator]
            limit = [base * (1 + p.ewma_limit_pct / 100) for _, p in judged]  # type: ignore[operator]
            legend.addItem(k_plot.plot(jx, ewma, pen=pg.mkPen("#ff7f0e", width=2.5), symbol="d", symbolSize=7,
                                       symbolBrush="#ff7f0e", symbolPen=None), f"EWMA (λ = {trend.ewma_lambda:g})")
            limit_curve = k_plot.plot(jx, limit, pen=pg.mkPen("#ff7f0e", width=2, style=QtCore.Qt.PenStyle.DashLine))
            # between two curve items with pens: a PlotDataItem drawn with pen=None has no path to fill, so the
            # shading the legend promised was never drawn (the third trial)
            base_curve = pg.PlotCurveItem(jx, [base] * len(jx), pen=pg.mkPen(0, 0, 0, 0))
            k_plot.addItem(base_curve)
            k_plot.addItem(pg.FillBetweenItem(limit_curve.curve, base_curve, brush=pg.mkBrush(255, 127, 14, 45)))
            legend.addItem(limit_curve, f"EWMA limit −{trend.ewma_L:g}σ (latest {limit[-1]:.1f}; shaded: no alarm)")
            levels += [*ewma, *limit]
        # the range of what is judged (and its limits): a skipped session's K — often wild, that is why it was
        # skipped — must not squash the trend into a line; it is listed in the table and the legend says so
        judged_pts = np.array([_category(p) not in ("skipped", "before baseline") for _, p in pts], dtype=bool)
        values = np.concatenate([lo[judged_pts], hi[judged_pts], k[judged_pts], levels])
        values = values[np.isfinite(values)]
        pad = 0.05 * (values.max() - values.min() or values.max())
        k_plot.setYRange(values.min() - pad, values.max() + pad, padding=0)
        no_k = [i for i, p in enumerate(trend.points) if p.entry.K_Nm_per_rad is None]
        if no_k:  # a gap in the trend says why: those windows are there, without a number
            legend.addItem(k_plot.plot(no_k, [values.min() - 0.5 * pad] * len(no_k), pen=None, symbol="x",
                                       symbolSize=9, symbolPen="#777", symbolBrush="#777"),
                           f"no K: {no_k_counts(trend.points)}")
        outside = int(np.sum(~judged_pts & ((k < values.min() - pad) | (k > values.max() + pad))))
        if outside:
            # a legend line only: an empty curve in the plot would upset its x range
            legend.addItem(pg.PlotDataItem(pen=None), f"{outside} skipped session(s) outside the range shown")
    for key, color, name in (("f_a_hz", "#2ca02c", "f_a (lower plot)"), ("f_r_hz", "#9467bd", "f_r (lower plot)")):
        # a skipped session's f_a, f_r (its fit is why it was skipped) would blow up the range like its K
        fx = [i for i, p in pts if getattr(p.entry, key) is not None and _category(p) != "skipped"]
        legend.addItem(f_plot.plot(fx, [getattr(trend.points[i].entry, key) for i in fx], pen=pg.mkPen(color, width=2),
                                   symbol="s", symbolBrush=color), name)
    k_plot.setXRange(-0.5, len(trend.points) - 0.5, padding=0.02)  # every session, whatever the curves hold
    step = max(1, len(trend.points) // 10)
    elapsed = [p.entry.tags.get(ELAPSED_TAG) for p in trend.points]
    if trend.points and all(isinstance(e, int | float) for e in elapsed):  # a monitor's windows: its machine time
        span_s = max(elapsed) - min(elapsed)  # type: ignore[type-var,operator]
        ticks = [(float(i), clock_text(e, span_s)[0]) for i, e in enumerate(elapsed)][::step]  # type: ignore[arg-type]
        x_label = f"machine time at the window's start ({clock_text(0.0, span_s)[1]})"
    else:
        ticks = [(float(i), (p.entry.created_utc or "?")[:19].replace("T", "\n"))
                 for i, p in enumerate(trend.points)][::step]
        x_label = "session start (UTC)"
    for plot, label, unit in ((k_plot, "K", "N·m/rad"), (f_plot, "frequency", "Hz")):
        plot.setLabel("left", label, units=unit)
        plot.getAxis("left").enableAutoSIPrefix(False)
        plot.getAxis("bottom").setTicks([ticks])
        plot.showGrid(x=True, y=True, alpha=0.25)
    f_plot.setLabel("bottom", x_label)
    widget.ci.addLabel(alarm_rules_line([(trend.joint, trend.rules_source)]), row=4, col=0, size="9pt")
    widget.ci.layout.setRowFixedHeight(1, 20 * -(-len(legend.items) // 3) + 5)  # every legend row, none clipped
    return frame


def no_k_counts(points: list[TrendPoint]) -> str:
    """The points without K counted by why: '7 not excited · 1 interrupted' (the catalogue's verdict; 'analysis
    failed' for one without a result), so the legend's count is the catalogue's and each is named."""
    why = Counter("analysis failed" if p.entry.error is not None or p.entry.verdict is None else p.entry.verdict
                  for p in points if p.entry.K_Nm_per_rad is None)
    return " · ".join(f"{n} {verdict}" for verdict, n in sorted(why.items(), key=lambda item: -item[1]))


def _category(p: TrendPoint) -> str:
    """The point's marker class in the plot: the threshold outranks the EWMA."""
    if p.state != "alarm":
        return p.state
    return "alarm: threshold" if p.threshold_alarm else "alarm: EWMA"
