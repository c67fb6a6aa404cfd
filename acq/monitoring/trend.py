"""``acq trend``: a joint's stiffness K over time from the catalogue, with a baseline and alarms.

Only sessions whose analysis has verdict ``ok`` are judged; the others are listed as skipped with
their reason. The baseline is the first good session, the mean of the first N good ones, or a pinned
session (sessions before a pinned baseline are shown, not judged). Two alarm rules:

* **threshold** — K below (1 − threshold) × baseline (default −10 %): the action limit;
* **EWMA** — the exponentially weighted moving average z_t = λ K_t + (1 − λ) z_{t−1}, z_0 = baseline,
  below the lower control limit baseline − L σ √(λ/(2−λ) · (1 − (1−λ)^{2t})) (Roberts' chart, L = 3):
  a small but persistent drop, relative to the session-to-session scatter σ of K. σ is the larger of
  the baseline's own 95 % interval (as 1.96 σ) and the standard deviation of the baseline sessions.

The alarm state is the latest judged session's: exit code 3 while it is in alarm, so a cron job or a
PLC script can act; re-pin the baseline (``--baseline``) after a repair.
"""

from __future__ import annotations

import math
import statistics
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal

from acq.monitoring.batch import CATALOGUE_NAME
from acq.monitoring.catalogue import Catalogue, Entry
from acq.monitoring.catalogue_backends import is_url
from acq.recording.tags import parse_tags, tags_match
from acqcore.errors import ConfigError
from analysis import Z95

EXIT_ALARM = 3
EWMA_L = 3.0

State = Literal["baseline", "ok", "alarm", "skipped", "before baseline"]


#: Tag of a monitor window (set by :mod:`acq.monitoring.monitor`): machine time at its start, s; the x axis of a monitor's trend.
ELAPSED_TAG = "monitor_elapsed_s"

@dataclass(frozen=True)
class TrendPoint:
    """One session in the trend.

    Attributes
    ----------
    entry : Entry
        The session's analysis from the catalogue.
    state : {"baseline", "ok", "alarm", "skipped", "before baseline"}
        How the session counts.
    reason : str
        Why it was skipped, or which rules raised the alarm ("threshold", "EWMA", "threshold+EWMA").
    change_pct : float or None
        K relative to the baseline, %.
    ewma_change_pct : float or None
        The EWMA of K relative to the baseline, %.
    ewma_limit_pct : float or None
        The EWMA's lower control limit relative to the baseline, %.
    """

    entry: Entry
    state: State
    reason: str = ""
    change_pct: float | None = None
    ewma_change_pct: float | None = None
    ewma_limit_pct: float | None = None

    @property
    def threshold_alarm(self) -> bool:
        """The threshold rule fired here."""
        return self.state == "alarm" and "threshold" in self.reason


@dataclass(frozen=True)
class Trend:
    """A joint's trend: the points in time order, the baseline and the rules' settings (K in N·m/rad)."""

    joint: str
    points: list[TrendPoint]
    baseline_K_Nm_per_rad: float | None
    baseline_note: str
    sigma_K_Nm_per_rad: float | None
    threshold_pct: float
    ewma_lambda: float
    ewma_L: float = EWMA_L

    @property
    def judged(self) -> list[TrendPoint]:
        """Points compared with the baseline (ok or alarm)."""
        return [p for p in self.points if p.state in ("ok", "alarm")]

    @property
    def alarm(self) -> bool:
        """True when the latest judged session is in alarm."""
        return bool(self.judged) and self.judged[-1].state == "alarm"


def like_for_like(entries: Sequence[Entry]) -> tuple[list[Entry], dict[str, str]]:
    """One analysis per session, all with the same request: the one most sessions have (the latest on a tie).

    Returns the entries (oldest session first) and, by session key, why a session has none with that
    request (its latest analysis stands in, to be listed as skipped).
    """
    sessions: dict[str, list[Entry]] = {}
    for e in entries:
        sessions.setdefault(e.session_key, []).append(e)
    counts = Counter(e.request_key for e in entries)
    request = max(counts, key=lambda r: (counts[r], max(e.analyzed_utc for e in entries if e.request_key == r)))
    chosen, missing = [], {}
    for key, analyses in sessions.items():
        same = [e for e in analyses if e.request_key == request]
        chosen.append(same[-1] if same else analyses[-1])
        if not same:
            missing[key] = "analysed only with other options than the trend's — run acq analyze on it again"
    return chosen, missing


def _skip_reason(e: Entry) -> str | None:
    if e.error is not None:
        return f"analysis failed: {e.error}"
    if e.verdict != "ok" or e.K_Nm_per_rad is None:
        why = [r for r in e.reasons if not r.startswith("note: ")]
        return f"verdict {e.verdict}" + (f": {why[0]}" if why else "")
    return None


def _sigma(baseline: Sequence[Entry]) -> float:
    """Session-to-session standard deviation of K: the larger of the intervals' and the baseline's scatter."""
    widths = [(hi - lo) / (2 * Z95) for lo, hi in (e.K_ci95 for e in baseline) if lo is not None and hi is not None]
    from_ci = math.sqrt(statistics.fmean(w * w for w in widths)) if widths else 0.0
    scatter = statistics.stdev(e.K_Nm_per_rad for e in baseline) if len(baseline) > 1 else 0.0  # type: ignore[misc]
    return max(from_ci, scatter)


def compute_trend(joint: str, entries: Sequence[Entry], *, baseline_sessions: int = 1, baseline_id: str | None = None,
                  threshold_pct: float = 10.0, ewma_lambda: float = 0.2) -> Trend:
    """Judge a joint's sessions (oldest first) against a baseline with the threshold and EWMA rules.

    Parameters
    ----------
    joint : str
        The joint's name (for the heading).
    entries : sequence of Entry
        The sessions' analyses, oldest session first (see :func:`like_for_like`).
    baseline_sessions : int
        Baseline = mean K of the first this many good sessions.
    baseline_id : str, optional
        Baseline = this session (its id or a unique prefix); overrides ``baseline_sessions``.
    threshold_pct : float
        Alarm when K drops more than this below the baseline, %.
    ewma_lambda : float
        Weight of the newest session in the EWMA, 0 < λ ≤ 1.
    """
    entries, missing = like_for_like(entries)
    skip = {id(e): missing.get(e.session_key) or _skip_reason(e) for e in entries}
    good = [e for e in entries if skip[id(e)] is None]
    if baseline_id is not None:
        pinned = [e for e in entries if (e.session_id or "").startswith(baseline_id)]
        if len(pinned) != 1:
            raise ConfigError(f"--baseline {baseline_id}: {'no' if not pinned else 'more than one'} session of "
                              f"joint {joint} has that id")
        if skip[id(pinned[0])] is not None:
            raise ConfigError(f"--baseline {baseline_id}: cannot be the baseline ({skip[id(pinned[0])]})")
        baseline, first = pinned, entries.index(pinned[0])
        note = f"session {pinned[0].session_id}"
    else:
        baseline = good[:baseline_sessions]
        first = entries.index(baseline[0]) if baseline else len(entries)
        note = (f"mean of the first {baseline_sessions} good sessions" if baseline_sessions > 1 else
                "first good session")
    if len(baseline) < (1 if baseline_id else baseline_sessions):
        points = [TrendPoint(e, "skipped", skip[id(e)] or "") if skip[id(e)] else TrendPoint(e, "before baseline")
                  for e in entries]
        return Trend(joint, points, None, f"not yet: {note} needs {baseline_sessions}, {len(good)} so far", None,
                     threshold_pct, ewma_lambda)
    base = statistics.fmean(e.K_Nm_per_rad for e in baseline)  # type: ignore[misc]
    sigma = _sigma(baseline)
    z, t, points = base, 0, []
    for i, e in enumerate(entries):
        if skip[id(e)] is not None:
            points.append(TrendPoint(e, "skipped", skip[id(e)] or ""))
            continue
        if i < first:
            points.append(TrendPoint(e, "before baseline"))
            continue
        k = e.K_Nm_per_rad
        assert k is not None  # good entries have K
        change = 100.0 * (k / base - 1.0)
        if any(e is b for b in baseline):
            points.append(TrendPoint(e, "baseline", change_pct=change))
            continue
        t += 1
        z = ewma_lambda * k + (1.0 - ewma_lambda) * z
        limit = EWMA_L * sigma * math.sqrt(ewma_lambda / (2.0 - ewma_lambda) * (1.0 - (1.0 - ewma_lambda) ** (2 * t)))
        rules = ["threshold"] if change < -threshold_pct else []
        rules += ["EWMA"] if z < base - limit else []
        points.append(TrendPoint(e, "alarm" if rules else "ok", "+".join(rules), change,
                                 100.0 * (z / base - 1.0), -100.0 * limit / base))
    return Trend(joint, points, base, note, sigma, threshold_pct, ewma_lambda)


def trend_json(trend: Trend) -> dict[str, Any]:
    """The ``--json`` document: settings, baseline, alarm and every point."""
    return {"joint": trend.joint, "alarm": trend.alarm, "baseline_K_Nm_per_rad": trend.baseline_K_Nm_per_rad,
            "baseline": trend.baseline_note, "sigma_K_Nm_per_rad": trend.sigma_K_Nm_per_rad,
            "threshold_pct": trend.threshold_pct, "ewma_lambda": trend.ewma_lambda, "ewma_L": EWMA_L,
            "points": [{**asdict(p.entry), "state": p.state, "reason": p.reason, "change_pct": p.change_pct,
                        "ewma_change_pct": p.ewma_change_pct, "ewma_limit_pct": p.ewma_limit_pct}
                       for p in trend.points]}


def render_trend_png(trend: Trend, path: Path | str, size: tuple[int, int] = (1400, 900)) -> Path:
    """Draw :func:`trend_widget` offscreen into a PNG of ``size`` (width, height) px."""
    import shiboken6

    from acq.ui.plots import ensure_app, grab_png

    ensure_app(offscreen=True)
    frame = trend_widget(trend)
    try:
        return grab_png(frame, path, size)
    finally:
        shiboken6.delete(frame)  # now, not at interpreter exit (deleteLater there crashes Qt's teardown)


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
            k_plot.addItem(pg.FillBetweenItem(limit_curve, k_plot.plot(jx, [base] * len(jx), pen=None),
                                              brush=pg.mkBrush(255, 127, 14, 35)))
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
                           f"no K: {len(no_k)} not excited / failed")
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
        ticks = [(float(i), f"{e / 3600:.1f} h") for i, e in enumerate(elapsed)][::step]  # type: ignore[operator]
        x_label = "machine time at the window's start (h)"
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
    widget.ci.layout.setRowFixedHeight(1, 20 * -(-len(legend.items) // 3) + 5)  # every legend row, none clipped
    return frame


def _category(p: TrendPoint) -> str:
    """The point's marker class in the plot: the threshold outranks the EWMA."""
    if p.state != "alarm":
        return p.state
    return "alarm: threshold" if p.threshold_alarm else "alarm: EWMA"


def catalogue_location(folder: Path | None, catalogue: Path | str | None) -> Path | str:
    """The catalogue to read: ``catalogue`` (a file or URL) or FOLDER/catalogue.sqlite; an error when no file."""
    path = catalogue or (folder or Path("sessions")) / CATALOGUE_NAME
    if not is_url(path) and not Path(path).is_file():
        raise ConfigError(f"{path}: no catalogue — fill one with acq analyze {folder or 'sessions'}/ first")
    return path


def load_trend(folder: Path | None, catalogue_path: Path | str | None, joint: str, tags: Sequence[str] = (),
               **options: Any) -> Trend:
    """The trend of ``joint`` from a catalogue (``folder``/catalogue.sqlite or ``catalogue_path``), sessions
    filtered on ``tags`` (``KEY=VALUE``); ``options`` go to :func:`compute_trend`."""
    wanted = parse_tags(tags)
    with Catalogue(catalogue_location(folder, catalogue_path)) as catalogue:
        entries = [e for e in catalogue.entries(joint) if tags_match(e.tags, wanted)]
        if not entries:
            tagged = f" tagged {' '.join(tags)}" if tags else ""
            raise ConfigError(f"{catalogue.path}: no sessions of joint {joint}{tagged} "
                              f"(joints: {', '.join(catalogue.joints()) or 'none'})")
    return compute_trend(joint, entries, **options)
