"""What a technician reads in a terminal: the rich tables of every command (values formatted by :mod:`acq.ui.values`).

Each table is a :class:`FittedTable`: it knows its columns with a wide and, where useful, a narrow form
and which columns may be left out, and chooses them when it is drawn, by the width the console
offers — an 80-column terminal or a pipe gets short dates and relative intervals instead of cells cut
to ``893…``. Text columns (states, reasons, paths) wrap at spaces; numbers never wrap. Columns left
out are named in the caption (``--json`` always has everything).

The computation behind the tables (results, summaries, trends, batches) lives in the modules that
make them; this module only turns their values into text.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from rich.console import Console, ConsoleOptions, RenderableType, RenderResult
from rich.cells import cell_len
from rich.markup import escape
from rich.measure import Measurement
from rich.table import Table
from rich.text import Text

from acq.recording.root_attrs import escaped
from acq.ui.values import (FIT_KEYS, NOT_A_RESULT, PARAMS, fit_failed, format_value, interval_text, not_a_result_note,
                           options_text)

if TYPE_CHECKING:
    from acq.monitoring.batch import BatchReport
    from acq.commissioning.devices import Section
    from acq.recording.summary import SessionSummary
    from acq.monitoring.trend import Trend

#: The result table's rows below the parameters: label, unit, path in the result document, scale from SI to the
#: unit, format, and the key of the simulated truth to compare with (or None). A row whose path the document
#: does not hold is left out, so a field the analysis adds later needs one line here.
RESULT_ROWS: tuple[tuple[str, str, tuple[str, ...], float, str, str | None], ...] = (
    ("f_a", "Hz", ("antiresonance_hz",), 1.0, ".4g", None),
    ("f_r", "Hz", ("resonance_hz",), 1.0, ".4g", None),
    ("clock offset", "ms", ("clock", "offset_s"), 1e3, ".3f", "offset_s"),
    ("clock drift", "ppm", ("clock", "drift_ppm"), 1.0, ".2f", "drift_ppm"),
    ("clock residual", "µs", ("clock", "residual_s"), 1e6, ".1f", None),
    ("coherence in band", "", ("quality", "mean_coherence"), 1.0, ".3f", None),
    ("encoder jitter", "µs", ("quality", "encoder_jitter_us"), 1.0, ".1f", None),  # left after any drive stamps
)

#: Spelled-out trend states (the alarm's rules are appended).
TREND_STATES = {"baseline": "baseline", "ok": "ok", "alarm": "ALARM", "skipped": "skipped",
                "before baseline": "before baseline"}
_TREND_STYLES = {"alarm": "bold red", "skipped": "dim", "before baseline": "dim", "baseline": "cyan", "ok": ""}


def _signed_seconds(x_s: float) -> str:
    """A signed time difference in µs below 1 ms, else in ms."""
    return f"{x_s * 1e6:+.1f} µs" if abs(x_s) < 1e-3 else f"{x_s * 1e3:+.3f} ms"


@dataclass(frozen=True)
class Column:
    """One column of a :class:`FittedTable`.

    Attributes
    ----------
    header : str
        Heading; a unit goes on its second line.
    cells : sequence of str
        One plain-text cell per row.
    justify : {"left", "right"}
        Alignment (numbers right).
    wrap : bool
        Text that may wrap at spaces (states, reasons, paths); numbers never wrap.
    drop : int
        0: always shown; 1, 2, …: left out in this order while the table is too wide.
    narrow : Column or None
        A narrower form of the column, used before any column is left out.
    narrow_rank : int
        Narrow forms are taken in this order (then left to right): a column whose narrow form reads worse (a
        name split over two lines) comes after the others.
    """

    header: str
    cells: Sequence[str]
    justify: Literal["left", "right"] = "right"
    wrap: bool = False
    drop: int = 0
    narrow: Column | None = None
    narrow_rank: int = 0


class FittedTable:
    """A rich table whose columns are chosen when it is drawn, by the width the console offers.

    Parameters
    ----------
    title : str
        Title (rich markup).
    columns : sequence of Column
        The columns, widest forms.
    caption : sequence of str
        Caption lines (plain text), left-justified.
    row_styles : sequence of str, optional
        A rich style per row.
    section_ends : set of int, optional
        Rows after which a rule is drawn.
    """

    def __init__(self, title: str, columns: Sequence[Column], caption: Sequence[str] = (),
                 row_styles: Sequence[str] | None = None, section_ends: set[int] | None = None) -> None:
        self.title, self.columns, self.caption = title, list(columns), list(caption)
        self.row_styles, self.section_ends = row_styles, section_ends or set()

    def layouts(self) -> Iterator[list[Column]]:
        """The column sets to try, widest first: every narrow form in turn, then the optional columns left out."""
        columns = list(self.columns)
        yield columns
        for i in sorted((i for i, c in enumerate(columns) if c.narrow is not None), key=lambda i: columns[i].narrow_rank):
            columns = [*columns[:i], columns[i].narrow, *columns[i + 1:]]  # type: ignore[list-item]
            yield columns
        for rank in sorted({c.drop for c in columns if c.drop}):
            columns = [c for c in columns if c.drop != rank]
            yield columns

    def build(self, columns: Sequence[Column]) -> Table:
        """The rich table of ``columns``; the caption names the columns left out."""
        shown = {id(c) for c in columns}
        left_out = [c.header.replace("\n", " ") for c in self.columns
                    if id(c) not in shown and (c.narrow is None or id(c.narrow) not in shown)]
        caption = [*self.caption, *([f"not shown at this width: {', '.join(left_out)} (widen the terminal, or "
                                     "--json)"] if left_out else [])]
        # cells and caption hold values read from catalogues (tags an older acq stored with ESC in them): escaped
        table = Table(title=self.title, caption=escape(escaped("\n".join(caption), keep="\n")) if caption else None,
                      caption_justify="left", show_edge=False)
        for c in columns:
            table.add_column(c.header, justify=c.justify, no_wrap=not c.wrap, overflow="fold")
        n_rows = len(columns[0].cells) if columns else 0
        for i in range(n_rows):
            table.add_row(*(Text(escaped(c.cells[i], keep="\n")) for c in columns),
                          style=self.row_styles[i] if self.row_styles else None, end_section=i in self.section_ends)
        return table

    def fitting_layout(self, width: int) -> list[Column] | None:
        """The widest layout whose table fits ``width`` columns, None if none does."""
        return next((columns for columns in self.layouts() if needed_width(columns) <= width), None)

    def fitted(self, width: int) -> RenderableType:
        """The table of the widest layout that fits ``width`` columns (the narrowest if none does)."""
        return self.build(self.fitting_layout(width) or list(self.layouts())[-1])

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        yield self.fitted(options.max_width)

    def __rich_measure__(self, console: Console, options: ConsoleOptions) -> Measurement:
        return Measurement.get(console, options, self.fitted(options.max_width))


def needed_width(columns: Sequence[Column]) -> int:
    """Terminal columns a table of ``columns`` needs (no outer edge, one space of padding each side of a cell):
    a number column its widest line, a text column its longest word."""
    def need(c: Column) -> int:
        texts = [c.header, *c.cells]
        pieces = [w for t in texts for w in t.split()] if c.wrap else [line for t in texts for line in t.split("\n")]
        return max((cell_len(p) for p in pieces), default=0)

    return sum(need(c) + 2 for c in columns) + max(len(columns) - 1, 0)


def result_table(doc: dict[str, Any]) -> FittedTable:
    """The identified values with 95 % intervals, frequencies, clock relation and verdict of a result document;
    on the simulated bench also the truth and the error."""
    truth = doc.get("simulated_truth") or {}
    failed = fit_failed(doc)  # the fit's numbers are not a result: "—", "not a result" (--json keeps them)
    names, values, intervals, relative, true_values, errors = [], [], [], [], [], []
    for key, name, unit in PARAMS:
        value = None if failed else doc.get(key)
        names.append(f"{name} [{unit}]")
        values.append(format_value(value))
        intervals.append(NOT_A_RESULT if failed else interval_text(doc, key))
        relative.append(NOT_A_RESULT if failed else interval_text(doc, key, relative=True))
        true_values.append(format_value(truth.get(key)))
        errors.append("—" if value is None or not truth.get(key) else f"{100.0 * (value / truth[key] - 1.0):+.2f} %")
    for name, unit, path, scale, spec, truth_key in RESULT_ROWS:
        found, value = _lookup(doc, path)
        if not found:
            continue
        true = truth.get(truth_key) if truth_key else None
        names.append(f"{name} [{unit}]" if unit else name)
        gone = failed and path[-1] in FIT_KEYS  # f_a, f_r of a failed fit
        values.append(format_value(None if gone else value, spec, scale))
        intervals.append(NOT_A_RESULT if gone else "")
        relative.append(NOT_A_RESULT if gone else "")
        true_values.append(format_value(true, ".4g", scale) if truth_key else "")
        errors.append("" if value is None or true is None else
                      _signed_seconds(value - true) if truth_key == "offset_s" else f"{value - true:+.2f} {unit}")
    columns = [Column("quantity", names, "left"), Column("value", values),
               Column("95 % interval", intervals, narrow=Column("95 % CI", relative))]
    if truth:
        columns += [Column("sim truth", true_values, drop=2), Column("error", errors, drop=1)]
    quality = doc["quality"]
    caption = [f"options: {options_text(doc)}", *([not_a_result_note("--json")] if failed else []),
               *quality["reasons"]]
    title = f"identification — verdict [bold]{escape(quality['verdict'])}[/bold]"
    if doc.get("partial"):  # why (the spans left out) is the first note of the caption
        title += (" — [bold]partial[/bold]: readable part of a damaged session" if doc["session"].get("damage")
                  else " — [bold]partial[/bold]: what was stored of a session still recording")
    return FittedTable(title, columns, caption)


def _lookup(doc: dict[str, Any], path: tuple[str, ...]) -> tuple[bool, Any]:
    """(found, value) of a nested key of a document."""
    node: Any = doc
    for key in path:
        if not isinstance(node, dict) or key not in node:
            return False, None
        node = node[key]
    return True, node


#: the optional encoder columns in words, for the summary's title
_EXTRA_TEXT = {"drive_time_s": "drive time stamps", "velocity_counts_per_s": "velocity actual",
               "velocity_demand_counts_per_s": "velocity demand"}


def summary_table(summary: SessionSummary) -> FittedTable:
    """A session at a glance, one row per stream: samples, duration, nominal rate and the rates measured on the host
    clock (line fit; first to last stamp), gaps."""
    title = (f"{escape(summary.path)}\njoint {escape(summary.joint)} · {escape(_utc_text(summary.created_utc))} · "
             f"status [bold]{escape(summary.status)}[/bold]")
    if summary.stop_reason:
        title += f" ({escape(summary.stop_reason)})"
    if summary.encoder_extras:
        title += "\nencoder also: " + ", ".join(_EXTRA_TEXT.get(n, n) for n in summary.encoder_extras)
    if summary.commanded and summary.speed_dither:
        title += f"\nmotion: speed dither ±{100 * summary.speed_dither:g} % per cycle, dither_seed {summary.dither_seed}"
    elif summary.commanded:
        title += "\nmotion: no speed dither (repeats exactly)"
    s = summary.streams
    columns = [Column("stream", [x.name for x in s], "left"), Column("samples", [f"{x.samples}" for x in s]),
               Column("duration\ns", [f"{x.duration_s:.3f}" for x in s]),
               Column("nominal rate\nHz", [f"{x.nominal_rate_hz:.1f}" for x in s],
                      narrow=Column("nominal\nHz", [f"{x.nominal_rate_hz:.1f}" for x in s])),
               Column("rate, line fit\nHz", [format_value(x.fitted_rate_hz, ".2f") for x in s],
                      narrow=Column("rate fit\nHz", [format_value(x.fitted_rate_hz, ".2f") for x in s])),
               Column("gaps", [f"{x.gaps}" for x in s]), Column("missing", [f"{x.missing}" for x in s]),
               Column("first–last\nHz", [format_value(x.effective_rate_hz, ".2f") for x in s], drop=1)]
    caption = ["rate fit: samples per host-clock second, a robust (Theil–Sen) line through the host stamps; a late "
               "first sample or a burst moves first–last, not it"]
    return FittedTable(title, columns, caption)


def _utc_text(iso: str | None) -> str:
    """An ISO time as "YYYY-MM-DD HH:MM:SS UTC" (the text as given if it is not one)."""
    try:
        return datetime.fromisoformat(iso or "").strftime("%Y-%m-%d %H:%M:%S UTC")
    except ValueError:
        return iso or "?"


def start_times(isos: Sequence[str | None]) -> tuple[Column, Column]:
    """The start-time column in a wide form (date and time to the second) and the shortest form that still tells
    the sessions apart (month-day hour:minute, the year in the header when all share it)."""
    times = []
    for iso in isos:
        try:
            times.append(datetime.fromisoformat(iso or ""))
        except ValueError:
            times.append(None)
    wide = Column("started (UTC)", [t.strftime("%Y-%m-%d %H:%M:%S") if t else "?" for t in times], "left")
    years = {t.year for t in times if t}
    header = f"started\n(UTC {years.pop()})" if len(years) == 1 else "started (UTC)"
    for spec in (("%m-%d %H:%M", "%m-%d %H:%M:%S") if header != "started (UTC)" else ("%y-%m-%d %H:%M",)):
        cells = [t.strftime(spec) if t else "?" for t in times]
        if len(set(cells)) == len(cells):
            break
    return wide, Column(header, cells, "left")


def monitor_bookkeeping_tags() -> frozenset[str]:
    """The tags acq monitor files with every window for its own use (number, identity, machine time, the alarm rules,
    the bench facts a restart compares): the same in every window or a count, they say nothing a table row needs."""
    from acq.monitoring.alarm_rules import RULE_TAGS
    from acq.monitoring.catalogue import MONITOR_TAG
    from acq.monitoring.monitor_restart import EVERY_TAG
    from acq.monitoring.monitor_scope import WINDOW_TAG
    from acq.monitoring.trend import ELAPSED_TAG
    from acq.monitoring.window_bench import FACT_TAGS

    return frozenset((MONITOR_TAG, WINDOW_TAG, EVERY_TAG, ELAPSED_TAG, *RULE_TAGS.values(), *FACT_TAGS))


def trend_table(trend: Trend) -> FittedTable:
    """The trend: per session its number (a monitor's window: the window's), start, K with its interval, change, EWMA,
    f_a, f_r, simulated K, tags and state.

    Skipped sessions' reasons are in the caption, with the baseline and the rules. acq monitor's bookkeeping tags
    (:func:`monitor_bookkeeping_tags`) are left out, and the caption says so (``--json`` has them).
    """
    from acq.monitoring.monitor_scope import window_number

    pts = trend.points
    f1 = functools.partial(format_value, spec=".1f")
    wide_time, short_time = start_times([p.entry.created_utc for p in pts])
    bookkeeping = monitor_bookkeeping_tags()
    tags = [" ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in p.entry.tags.items()
                     if k not in bookkeeping) for p in pts]
    # a monitor's windows by the number the monitor's status and alarm lines give them; other sessions by their row
    windows = [window_number(p.entry.tags) for p in pts]
    by_window = bool(pts) and None not in windows
    numbers = [str(n) for n in windows] if by_window else [str(i) for i in range(1, len(pts) + 1)]
    refs = [f"window {n}" if by_window else f"#{n}" for n in numbers]
    # "learning baseline" as acq monitor and acq fleet say it; "before baseline" only before a pinned one (--baseline)
    words = {**TREND_STATES,
             "before baseline": "before baseline" if trend.baseline_K_Nm_per_rad else "learning baseline"}
    states = [words[p.state] + (f": {p.reason.replace('+', ' + ')}" if p.state == "alarm" else "")
              + (f" ({ref} below)" if p.state == "skipped" else "") for ref, p in zip(refs, pts)]
    rel = [f"± {50.0 * (p.entry.K_ci95[1] - p.entry.K_ci95[0]) / p.entry.K_Nm_per_rad:.1f}"
           if None not in (*p.entry.K_ci95, p.entry.K_Nm_per_rad) else "—" for p in pts]
    columns = [Column("window" if by_window else "#", numbers),
               replace(wide_time, narrow=short_time),
               Column("K\nN·m/rad", [f1(p.entry.K_Nm_per_rad) for p in pts]),
               Column("K 95 % interval\nN·m/rad", ["—" if None in p.entry.K_ci95 else
                                                   f"{f1(p.entry.K_ci95[0])}–{f1(p.entry.K_ci95[1])}" for p in pts],
                      narrow=Column("95 %\n± %", rel), drop=5),
               Column("ΔK\n%", [format_value(p.change_pct, "+.1f") for p in pts]),
               Column("EWMA\n%", [format_value(p.ewma_change_pct, "+.1f") for p in pts], drop=4),
               Column("f_a\nHz", [f1(p.entry.f_a_hz) for p in pts], drop=3),
               Column("f_r\nHz", [f1(p.entry.f_r_hz) for p in pts], drop=3)]
    if any(p.entry.truth_K_Nm_per_rad is not None for p in pts):
        columns.append(Column("sim K\nN·m/rad", [f1(p.entry.truth_K_Nm_per_rad) for p in pts], drop=2))
    caption = []
    if len(set(tags)) == 1 and tags[0]:
        caption.append(f"every session tagged {tags[0]}")
    elif any(tags):
        columns.append(Column("tags", tags, "left", wrap=True, drop=1))
    if any(k in bookkeeping for p in pts for k in p.entry.tags):
        caption.append("acq monitor's own tags (window number, identity, alarm rules, bench facts) not shown: "
                       "--json has every tag")
    columns.append(Column("state", states, "left", wrap=True))
    base = (f"no baseline yet ({trend.baseline_note})" if trend.baseline_K_Nm_per_rad is None else
            f"baseline {trend.baseline_K_Nm_per_rad:.1f} N·m/rad ({trend.baseline_note})")
    sigma = "" if trend.sigma_K_Nm_per_rad is None else f", σ = {f1(trend.sigma_K_Nm_per_rad)} N·m/rad"
    caption += [f"{base}; ALARM below −{trend.threshold_pct:g} % (threshold) or "
                f"EWMA (λ = {trend.ewma_lambda:g}) below its −{trend.ewma_L:g}σ limit (EWMA){sigma}; rules: "
                f"{trend.rules_source}", *([trend.baseline_warning] if trend.baseline_warning else []),
                *(f"{ref} skipped: {p.reason}" for ref, p in zip(refs, pts) if p.state == "skipped")]
    title = f"stiffness trend — {escape(trend.joint)}" + ("  [bold red]ALARM[/]" if trend.alarm else "")
    return FittedTable(title, columns, caption, row_styles=[_TREND_STYLES[p.state] for p in pts])


#: Sessions a batch did not analyse as they are still being recorded (after their count).
STILL_RECORDING = ("skipped as still recording (acq check repairs a killed recorder's session; --partial analyses it "
                   "as it is)")


def batch_table(report: BatchReport) -> FittedTable:
    """One row per session analysed (K, verdict or the error), a caption counting the skipped ones.

    The joint is in the title when all sessions share it; the error column is there when a session failed.
    """
    outcomes = sorted(report.outcomes, key=lambda o: o.path)
    joints = [str(o.session.get("joint") or "?") for o in outcomes]
    # none when not excited; a failed verdict's K is not a result ("—" beside "failed", as in the result table)
    ks = [None if o.doc is None or fit_failed(o.doc) else o.doc.get("K_Nm_per_rad") for o in outcomes]
    columns = [Column("session", [Path(o.path).name for o in outcomes], "left")]
    one_joint = len(set(joints)) == 1
    if not one_joint:
        columns.append(Column("joint", joints, "left"))
    columns += [Column("K\nN·m/rad", [format_value(k, ".1f") for k in ks]),
                Column("verdict", ["failed" if o.doc is None else o.doc["quality"]["verdict"] for o in outcomes],
                       "left")]
    if report.failed:
        columns.append(Column("error", [o.error or "" for o in outcomes], "left", wrap=True))
    caption = [f"{len(report.outcomes)} analysed ({len(report.failed)} failed), {len(report.skipped)} skipped as "
               f"current, {report.seconds:.1f} s"]
    if report.not_ready:
        caption.append(f"{len(report.not_ready)} {STILL_RECORDING}")
    return FittedTable("batch analysis" + (f" — joint {escape(joints[0])}" if one_joint and joints else ""),
                       columns, caption)


def sections_table(sections: Sequence[Section]) -> FittedTable:
    """``acq devices``: a heading row per section, then its devices or the reason it is empty."""
    rows: list[tuple[str, str, str]] = []
    ends = set()
    for s in sections:
        rows.append((s.title, "", ""))
        rows += s.rows
        if s.empty_because:
            rows.append(("none", "", s.empty_because))
        if s.note:
            rows.append(("note", "", s.note))
        ends.add(len(rows) - 1)
    columns = [Column(name, [r[i] for r in rows], "left", wrap=True) for i, name in enumerate(("device", "kind",
                                                                                               "detail"))]
    heads = {i for i, r in enumerate(rows) if r[1:] == ("", "") and any(r[0] == s.title for s in sections)}
    return FittedTable("What this machine can record from", columns,
                       row_styles=["bold" if i in heads else "" for i in range(len(rows))], section_ends=ends)
