"""How ``acq fleet`` shows the fleet: the click command, a rich table, and a PNG with ΔK over time as one
heat strip per joint.

The numbers come from :mod:`acq.monitoring.fleet`; nothing here judges a joint.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Sequence
from dataclasses import replace
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import click
from rich.console import Console

from acq.monitoring.catalogue import Entry
from acq.ui.display import Column, start_times
from acq.ui.options import CatalogueLocation, Folder, PngPath, alarm_rule_options
from acq.ui.records import RecordTable
from acq.monitoring.fleet import JointStatus, fleet_json, load_fleet, session_start
from acq.monitoring.trend import EXIT_ALARM
from acq.ui.values import alarm_rules_line, format_value

_STYLES = {"alarm": "bold red", "stale": "yellow", "no baseline": "dim", "baseline": "cyan", "ok": ""}
#: The state column's words: "no baseline" (the JSON's) as acq monitor and acq trend say it.
_STATE_WORDS = {"no baseline": "learning baseline"}
#: Time bins of the PNG's heat strips (the width of a strip is the time since the oldest session).
HEAT_BINS = 400
#: The PNG's cells with no judged ΔK (before the baseline, not judged, stale): a grey apart from the colour scale's
#: white at ΔK = 0 (both were white: a fleet at ΔK ≈ 0 looked blank, and "no ΔK" had no legend).
NO_DELTA_K_GREY = (200, 200, 200)
#: Each session's mark on its strip, by how the trend took it: (symbol, brush, pen, legend text).
_SESSION_MARKS = {"judged": ("o", "#202020", None, "session judged (its ΔK colours the strip until the next)"),
                  "alarm": ("t", "#d62728", "#202020", "session in alarm"),
                  "not judged": ("o", None, "#202020", "session not judged (not excited, failed, before the baseline)")}


def fleet_table(statuses: Sequence[JointStatus], stale_days: float) -> RecordTable:
    """One row per joint, worst first: robot/joint, latest K and its 95 % interval, ΔK, baseline, last session,
    sessions excited / analysed in the last day, state.

    At 80 columns the interval is relative (± %) and the time short (month-day hour:minute), the state wraps at
    spaces; where that is not enough (a source column) the baseline (ΔK says how far K is from it), then the 24 h
    counts are left out, and the caption names them. Narrower than that (about 60 columns) each joint is a block of
    "header: value" lines (:class:`RecordTable`).
    """
    alarms = sum(s.state == "alarm" for s in statuses)
    title = (f"fleet — {len(statuses)} joint{'s' if len(statuses) != 1 else ''}"
             + (f"  [bold red]{alarms} in ALARM[/]" if alarms else ""))
    f1 = functools.partial(format_value, spec=".1f")
    entries = [None if s.latest is None else s.latest.entry for s in statuses]
    wide_time, short_time = start_times([None if s.last_session_utc is None else s.last_session_utc.isoformat()
                                         for s in statuses])
    names = [f"{s.robot}/{s.joint}" for s in statuses]
    columns = [Column("robot/\njoint", names, "left",  # split at the "/" when too wide, never inside a name
                      narrow=Column("robot/\njoint", [n.replace("/", "/\n", 1) for n in names], "left"), narrow_rank=1),
               Column("K\nN·m/rad", [f1(None if e is None else e.K_Nm_per_rad) for e in entries]),
               Column("95 % interval\nN·m/rad",
                      ["—" if e is None else f"{f1(e.K_ci95[0])}–{f1(e.K_ci95[1])}" for e in entries],
                      narrow=Column("95 %\n± %", [_relative_half_width(e) for e in entries])),
               Column("ΔK\n%", [format_value(s.change_pct, "+.1f") for s in statuses]),
               Column("baseline\nN·m/rad", [f1(s.trend.baseline_K_Nm_per_rad) for s in statuses], drop=1),
               replace(wide_time, header="last session\n(UTC)",
                       narrow=replace(short_time, header=short_time.header.replace("started", "last"))),
               Column("24 h\nok/all", [f"{s.excited_last_day}/{s.analysed_last_day}" for s in statuses], drop=2),
               Column("state", [(f"ALARM {s.latest.reason.replace('+', ' + ')}" if s.state == "alarm" and
                                 s.latest is not None else _STATE_WORDS.get(s.state, s.state))
                                + (" · baseline unstable" if s.trend.baseline_warning else "") for s in statuses],
                      "left", wrap=True)]
    if any(s.source for s in statuses):  # several catalogues, or several monitors of one robot and joint name
        columns.insert(1, Column("source", [s.source or "—" for s in statuses], "left", wrap=True))
    caption = [f"stale: no session for {stale_days:g} days; 24 h ok/all: sessions of the last day with a K of "
               "verdict ok / all analysed; alarm rules as acq trend (per joint: acq trend --joint J --tag robot=R)"]
    if statuses:
        caption.append(alarm_rules_line([(s.trend.joint, s.trend.rules_source) for s in statuses]))
    caption += [f"{s.trend.joint}: {s.trend.baseline_warning}" for s in statuses if s.trend.baseline_warning]
    return RecordTable(title, columns, caption, row_styles=[_STYLES[s.state] for s in statuses])


def _relative_half_width(entry: Entry | None) -> str:
    """Half the width of K's 95 % interval relative to K, "± x.x" (%), or "—"."""
    if entry is None or None in (*entry.K_ci95, entry.K_Nm_per_rad) or not entry.K_Nm_per_rad:
        return "—"
    return f"± {50.0 * (entry.K_ci95[1] - entry.K_ci95[0]) / entry.K_Nm_per_rad:.1f}"


def render_fleet_png(statuses: Sequence[JointStatus], path: Path | str, *, now: datetime, threshold_pct: float,
                     stale_days: float, size: tuple[int, int] | None = None) -> Path:
    """Draw :func:`fleet_widget` offscreen into a PNG (default 1400 px wide, 40 px per joint and the legend)."""
    from acq.ui.offscreen_png import render_offscreen_png

    return render_offscreen_png(lambda: fleet_widget(statuses, now=now, threshold_pct=threshold_pct,
                                                     stale_days=stale_days),
                                path, size or (1400, 270 + 40 * len(statuses)))


def fleet_widget(statuses: Sequence[JointStatus], *, now: datetime, threshold_pct: float, stale_days: float) -> Any:
    """The fleet figure (needs a QApplication): one row per joint, worst at the top, coloured by ΔK against its
    baseline from each judged session until the next, the last for at most ``stale_days`` (red: K below; pale
    yellow: at the baseline; blue: above; grey: no ΔK — before the baseline, or stale); the colour scale spans ±2 ×
    the alarm threshold. Each session is marked on its row (judged, in alarm, not judged), and a legend says what the
    marks and the grey mean."""
    import numpy as np
    import pyqtgraph as pg
    from pyqtgraph.Qt import QtCore, QtWidgets

    from acq.ui.plot_style import legend_box

    frame = QtWidgets.QWidget()
    widget = pg.GraphicsLayoutWidget()
    QtWidgets.QVBoxLayout(frame).addWidget(widget)
    alarms = sum(s.state == "alarm" for s in statuses)
    widget.ci.addLabel("fleet — ΔK against each joint's baseline" + (f"  ({alarms} in ALARM)" if alarms else ""),
                       row=0, col=0, colspan=2, size="14pt")
    legend = pg.LegendItem(colCount=2, labelTextSize="9pt")  # a row of its own: it covers no strip
    widget.ci.addItem(legend, row=1, col=0)
    plot = widget.addPlot(row=2, col=0, axisItems={"bottom": pg.DateAxisItem()})
    histories = [s.history() for s in statuses]
    t0 = min((h[0][0] for h in histories if h), default=now - timedelta(days=1))
    span_s = max((now - t0).total_seconds(), 3600.0)
    edges = [t0 + timedelta(seconds=span_s * i / HEAT_BINS) for i in range(HEAT_BINS + 1)]
    heat = np.full((HEAT_BINS, len(statuses)), np.nan)  # ImageItem: axis 0 is x (time), axis 1 is y (joint)
    edge_s = np.array([e.timestamp() for e in edges])
    for row, history in enumerate(histories):
        for start, change in history:  # each value holds from its session until the next one (later ones overwrite)
            first, last = np.searchsorted(edge_s, [start.timestamp(), start.timestamp() + stale_days * 86400.0],
                                          side="right") - 1
            heat[max(first, 0):last + 1, len(statuses) - 1 - row] = change
            heat[last + 1:, len(statuses) - 1 - row] = np.nan
    limit = 2.0 * threshold_pct
    # ColorBrewer's RdYlBu (red: K below its baseline; blue: above): its pale yellow at ΔK = 0 is seen on the white
    # page and apart from the grey of no ΔK (a white centre made a healthy fleet a blank picture); safe for the common
    # colour blindness (no red against green)
    colormap = pg.ColorMap(pos=[0.0, 0.25, 0.5, 0.75, 1.0], color=[(215, 48, 39), (252, 141, 89), (255, 255, 191),
                                                                   (145, 191, 219), (69, 117, 180)])
    image = pg.ImageItem(heat, levels=(-limit, limit), lut=colormap.getLookupTable(nPts=256))
    rect = QtCore.QRectF(t0.timestamp(), 0.0, span_s, float(len(statuses)))
    grey = pg.mkBrush(*NO_DELTA_K_GREY)
    underlay = QtWidgets.QGraphicsRectItem(rect)  # shows through the cells without ΔK (NaN: transparent)
    underlay.setBrush(grey)
    underlay.setPen(pg.mkPen(None))
    plot.addItem(underlay)
    image.setRect(rect)
    plot.addItem(image)
    bar = pg.ColorBarItem(values=(-limit, limit), colorMap=colormap, label="ΔK %", interactive=False)
    bar.setImageItem(image)
    widget.addItem(bar, row=2, col=1)
    marks: dict[str, tuple[list[float], list[float]]] = {kind: ([], []) for kind in _SESSION_MARKS}
    for row, s in enumerate(statuses):
        for point in s.trend.points:
            start = session_start(point.entry)
            if start is None:
                continue
            kind = ("alarm" if point.state == "alarm" else "judged" if point.change_pct is not None else "not judged")
            marks[kind][0].append(start.timestamp())
            marks[kind][1].append(len(statuses) - 1 - row + 0.5)
    for kind, (symbol, brush, pen, text) in _SESSION_MARKS.items():
        xs, ys = marks[kind]
        item = pg.ScatterPlotItem(xs, ys, symbol=symbol, size=8, brush=pg.mkBrush(brush) if brush else None,
                                  pen=pg.mkPen(pen) if pen else pg.mkPen(None))
        plot.addItem(item)
        legend.addItem(item, text)
    legend.addItem(legend_box(grey), f"grey: no ΔK (before the baseline, or no session for {stale_days:g} days)")
    widget.ci.layout.setRowFixedHeight(1, 20 * -(-len(legend.items) // 2) + 6)
    labels = [(len(statuses) - 1 - i + 0.5, f"{s.robot}/{s.joint}{f' ({s.source})' if s.source else ''} · "
               f"{_STATE_WORDS.get(s.state, s.state)}" + ("" if s.change_pct is None else f" {s.change_pct:+.1f} %"))
              for i, s in enumerate(statuses)]
    plot.getAxis("left").setTicks([labels])
    plot.getAxis("left").setWidth(12 + 8 * max((len(text) for _, text in labels), default=10))
    plot.setLabel("bottom", "session start (UTC)")
    plot.setXRange(t0.timestamp(), now.timestamp(), padding=0.01)
    plot.setYRange(0.0, float(len(statuses)), padding=0.0)
    plot.showGrid(x=True, y=False, alpha=0.25)
    return frame


@click.command(name="fleet")
@click.argument("folders", nargs=-1, type=Folder(catalogue_option=True))
@click.option("--catalogue", "catalogues", type=CatalogueLocation(), multiple=True,
              help="A catalogue, a file or postgresql:// URL (repeatable; default: FOLDER/catalogue.sqlite of each "
                   "FOLDER, FOLDER defaulting to sessions/). Several are judged apart, each row saying its source.")
@click.option("--tag", "tags", multiple=True, metavar="KEY=VALUE",
              help="Only sessions with this tag (repeatable), e.g. --tag site=plant2; read as acq record --tag reads "
                   "it.")
@click.option("--stale-days", type=click.FloatRange(0, min_open=True), default=7.0, show_default=True,
              help="A joint with no session for this many days is stale.")
@alarm_rule_options("each joint's")
@click.option("--png", "png_path", type=PngPath(), default=None,
              help="Also draw the fleet (ΔK over time, one row per joint) into this PNG.")
@click.option("--json", "as_json", is_flag=True, help="Print the fleet as JSON.")
def fleet_command(folders: tuple[Path, ...], catalogues: tuple[Path | str, ...], tags: tuple[str, ...],
                  stale_days: float, baseline_sessions: int | None, threshold_pct: float | None,
                  ewma_lambda: float | None, png_path: Path | None, as_json: bool) -> int:
    """Every joint (by robot tag): latest K ± 95 %, ΔK to its baseline, sessions of the last day, state
    (alarm / stale / no baseline / ok), worst first; exit code 3 if any joint is in alarm."""
    now = datetime.now(UTC)
    statuses = load_fleet(folders, catalogues, tags, now=now, stale_days=stale_days,
                          baseline_sessions=baseline_sessions, threshold_pct=threshold_pct, ewma_lambda=ewma_lambda)
    out = Console()
    if as_json:
        click.echo(json.dumps(fleet_json(statuses), indent=2))
    else:
        out.print(fleet_table(statuses, stale_days))
    if png_path is not None:
        scale_pct = max(s.trend.threshold_pct for s in statuses)  # each joint's own rules: the widest sets the scale
        render_fleet_png(statuses, png_path, now=now, threshold_pct=scale_pct, stale_days=stale_days)
        if not as_json:
            out.print(f"plot: {png_path}")
    return EXIT_ALARM if any(s.state == "alarm" for s in statuses) else 0
