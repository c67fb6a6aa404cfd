"""``acq monitor``: the command line and the live status of :mod:`acq.monitoring.monitor`."""

from __future__ import annotations

import math
import re
from typing import Any
from pathlib import Path

import click
from rich.console import Console
from rich.live import Live
from rich.markup import escape
from rich.table import Table

from acq.config import load_bench
from acq.monitoring.session_outcome import CATALOGUE_NAME
from acq.monitoring.catalogue_backends import is_url, redacted
from acq.monitoring.monitor import Monitor, MonitorSettings, MonitorStatus
from acq.monitoring.retention import parse_size
from acq.recording.tags import parse_tags
from acq.ui.options import CatalogueLocation, FiniteFloatRange, Folder
from acq.ui.values import duration_text, format_value
from acqcore.errors import ConfigError
from drivers.motion import RPM_TO_RAD_S

#: Seconds per unit of a duration; each part of ``2h 10min`` is a number and one of these (none: seconds).
_UNITS_S = {"s": 1.0, "sec": 1.0, "m": 60.0, "min": 60.0, "h": 3600.0, "d": 86400.0}
_NUMBER = r"(?:[0-9]+\.?[0-9]*|\.[0-9]+)"
_PART = re.compile(rf"[ \t]*({_NUMBER})[ \t]*([a-z]+)")  # spaces between parts, never a line break
#: Moves listed in the status table (a window of a busy program holds a dozen or more).
_MOVES_SHOWN = 8


def parse_duration(option: str, text: str) -> float:
    """``600``, ``90s``, ``10min`` (``10m``), ``1.5h``, ``1d``, and parts summed (``2h10min``, ``2h 10min``) →
    seconds (s); ConfigError naming the option, the value and the accepted forms otherwise (zero too)."""
    lowered = text.strip().lower()
    seconds = math.nan
    if re.fullmatch(_NUMBER, lowered):
        seconds = float(lowered)
    elif re.fullmatch(rf"(?:{_PART.pattern})+", lowered):
        parts = _PART.findall(lowered)
        units = [_UNITS_S.get(unit) for _, unit in parts]
        if None not in units and len(set(units)) == len(units):  # each unit once: "2h 2h" is more likely a typo
            seconds = sum(float(number) * _UNITS_S[unit] for number, unit in parts)
    if not (math.isfinite(seconds) and seconds > 0):
        shown = text if text.isprintable() else text.encode("unicode_escape").decode("ascii")  # the error on one line
        raise ConfigError(f"{option} {shown}: not a duration — seconds, or numbers with s, min (m), h or d, summed: "
                          "600, 90s, 10min, 1.5h, 2h10min, 2h 10min")
    return seconds


def status_table(st: MonitorStatus) -> Table:
    """The monitor's live figures as one rich table."""
    table = Table(title=f"acq monitor — {st.joint}" + ("  [bold red]ALARM[/]" if st.state == "alarm" else ""),
                  show_header=False)
    table.add_column("what")
    table.add_column("value", justify="right")
    lo, hi = st.last_K_ci
    k_text = "—" if st.last_K is None else (f"{st.last_K:.1f} ({format_value(lo, '.1f')} … {format_value(hi, '.1f')})"
                                            f" · window {st.last_K_window}")
    rows = [
        ("machine time", duration_text(st.machine_time_s)),
        ("windows filed (this run)", filed_text(st)),
        *([("windows in the folder (earlier runs too)", str(st.in_folder))] if st.resumed else []),
        *([("not captured: the disk budget (--max-disk) was full", str(st.not_captured))] if st.not_captured else []),
        *([("not captured: the file system was full", str(st.no_room))] if st.no_room else []),
        *([("catalogue", catalogue_text(st))] if st.catalogue_down_since or st.waiting else []),
        *([("not filed: analysis unfinished, a restart analyses them", str(st.unfinished))] if st.unfinished else []),
        *([("copies of other monitors' windows deleted", str(st.copied_deleted))] if st.copied_deleted else []),
        *([("damaged windows kept (not for --keep; last to go for room)", str(st.damaged_kept))]
          if st.damaged_kept else []),
        ("last K N·m/rad (95 %) · its window", k_text),
        ("ΔK against the baseline", format_value(st.change_pct, "+.1f") + " %"),
        ("baseline K N·m/rad", format_value(st.baseline_K, ".1f")),
        ("excited share: last window · all windows", f"{_pct(st.last_excited_fraction)} · "
                                                     f"{_pct(st.program_excited_fraction)}"),
        *([("the last window is filed not excited", escape(st.last_not_excited_why))]
          if st.last_not_excited_why is not None else []),  # its excited share alone contradicted that
        *([("segment selection of the last window", escape(st.last_segments))] if st.last_segments else []),
        ("trend state", f"[bold red]{st.state}[/]" if st.state == "alarm" else st.state),
        ("alarms raised", str(st.alarms) + (f" · [bold red]{escape(st.alarm_command_failure)}[/]"
                                            if st.alarm_command_failure else "")),
        ("disk used", f"{st.disk_bytes / 1e6:.1f} MB"),
    ]
    for what, value in rows:
        table.add_row(what, value)
    if st.last_moves:
        excited = sum(m["excited"] for m in st.last_moves)
        table.add_row(f"moves of the last window: {excited} of {len(st.last_moves)} excite", moves_table(st.last_moves))
    table.caption = "\n".join(filter(None, (st.baseline_warning, st.message))) or None
    return table


def filed_parts(st: MonitorStatus) -> str:
    """How the windows this run filed count, adding up to them: '19 ok + 7 not excited + 1 interrupted' (the kinds of
    :data:`acq.monitoring.monitor_status.FILED_KINDS` that have any)."""
    return " + ".join(f"{n} {kind}" for kind, n in st.filed.items() if n)


def filed_text(st: MonitorStatus) -> str:
    """'27 = 19 ok + 7 not excited + 1 interrupted'; '0' before the first window is filed."""
    return f"{st.filed_total}" + (f" = {filed_parts(st)}" if st.filed_total else "")


def _filed(st: MonitorStatus) -> str:
    """'1 window filed (1 ok)', '12 windows filed in this run (…), 15 in the folder' (after a restart)."""
    text = f"{st.filed_total} window{'s' if st.filed_total != 1 else ''} filed"
    text += " in this run" if st.resumed else ""
    text += f" ({filed_parts(st)})" if st.filed_total else ""
    text += f", {st.in_folder} in the folder" if st.resumed else ""
    return text + (f", {st.unfinished} not filed (analysis unfinished: the restart analyses "
                   f"{'it' if st.unfinished == 1 else 'them'})" if st.unfinished else "")


def catalogue_text(st: MonitorStatus) -> str:
    """'catalogue unreachable since 21:30:05 UTC (2 windows waiting)', or '2 windows waiting for the catalogue'."""
    waiting = f"{st.waiting} window{'s' if st.waiting != 1 else ''} waiting"
    if st.catalogue_down_since is None:
        return f"{waiting} for the catalogue"
    return f"catalogue unreachable since {st.catalogue_down_since} UTC ({waiting})"


def _pct(fraction: float | None) -> str:
    return "—" if fraction is None else f"{100 * fraction:.0f} %"


def moves_table(moves: tuple[dict[str, Any], ...]) -> Table:
    """A window's moves: number, start (s), peak speed (rpm), whether the analysis used them (excites)."""
    table = Table(box=None, pad_edge=False, show_edge=False)
    for column in ("move", "start s", "peak rpm", "excites"):
        table.add_column(column, justify="right")
    for m in moves[:_MOVES_SHOWN]:
        table.add_row(str(m["index"]), f"{m['start_s']:.2f}", f"{m['peak_rad_s'] / RPM_TO_RAD_S:.0f}",
                      "[green]yes[/]" if m["excited"] else "no")
    if len(moves) > _MOVES_SHOWN:
        rest = moves[_MOVES_SHOWN:]
        table.add_row("…", f"+{len(rest)} more", "", f"{sum(m['excited'] for m in rest)} yes")
    return table


@click.command(name="monitor")
@click.option("--bench", "bench_path", type=click.Path(path_type=Path), required=True,
              help="Bench TOML with [drive] motion = \"external\" (e.g. configs/benches/sim_robot.toml).")
@click.option("--window", "window_s", type=FiniteFloatRange(min=1.0), default=10.0, show_default=True,
              help="Seconds per window.")
@click.option("--every", "every", default="60", show_default=True, help="One window per this (600, 90s, 10min, 1.5h, 2h10min).")
@click.option("--for", "for_text", default=None, help="Stop after this (8h, 2h10min); default: until Ctrl-C.")
@click.option("--on-alarm", default=None, metavar="CMD",
              help="Run CMD through sh -c on entering alarm (in the background; a failure is reported), with "
                   "ACQ_JOINT, ACQ_K, ACQ_BASELINE_K, ACQ_CHANGE_PCT, ACQ_SESSION, ACQ_WINDOW (from 1) in its "
                   "environment.")
@click.option("--keep", type=click.IntRange(min=0), default=10, show_default=True,
              help="Keep the raw files of the last N windows (baseline and alarming windows are always kept).")
@click.option("--max-disk", default=None, help="Disk budget of the folder (2GB, 500MB); never exceeded.")
@click.option("--out", "out_dir", type=Folder(), default=Path("monitor"), show_default=True,
              help="Folder for the windows and catalogue.sqlite (a restart there resumes).")
@click.option("--catalogue", "catalogue_path", type=CatalogueLocation(), default=None,
              help="File every window into this catalogue, a file or postgresql:// URL, which other monitors and "
                   "benches may share (default: OUT/catalogue.sqlite).")
@click.option("--tag", "tags", multiple=True, metavar="KEY=VALUE",
              help="Tag every window (repeatable), e.g. --tag robot=r1: acq fleet and acq trend --tag tell the "
                   "robots apart by it. Values as acq record --tag reads them (2.5 a number, 007 text).")
@click.option("--move-catalogue", is_flag=True,
              help="Resume with another --catalogue than the monitor filed into (e.g. SQLite to PostgreSQL): copy its "
                   "windows there first.")
@click.option("--new-identity", is_flag=True,
              help="A folder copied from another monitor: make this one a monitor of its own (only acts on a copy).")
@click.option("--moved", is_flag=True,
              help="A folder moved here from another host: it is the same monitor, the one there no longer runs "
                   "(only acts on a folder bound elsewhere).")
@click.option("--baseline-windows", type=click.IntRange(min=1), default=5, show_default=True,
              help="Baseline = mean K of the first N good windows.")
@click.option("--threshold-pct", type=FiniteFloatRange(0, 100, min_open=True), default=10.0, show_default=True,
              help="Alarm when K is this many % below the baseline (or by the EWMA rule).")
@click.option("--ewma-lambda", type=FiniteFloatRange(0, 1, min_open=True), default=0.2, show_default=True,
              help="EWMA weight of the newest window; alarm when the EWMA is below the 3σ control limit.")
@click.option("--jobs", type=click.IntRange(min=1), default=1, show_default=True, help="Analysis worker processes.")
@click.option("--fast", is_flag=True, help="Simulated bench: machine time runs as fast as the analysis allows.")
def monitor_command(bench_path: Path, window_s: float, every: str, for_text: str | None, on_alarm: str | None,
                    keep: int, max_disk: str | None, out_dir: Path, baseline_windows: int, threshold_pct: float,
                    ewma_lambda: float, jobs: int, fast: bool, catalogue_path: Path | str | None, tags: tuple[str, ...],
                    move_catalogue: bool, new_identity: bool, moved: bool) -> int:
    """Listen to a running machine window by window, trend K, raise the alarm; exit code 3 if it ends in alarm."""
    if moved and new_identity:  # the same monitor and another one: taking either would be a guess
        raise ConfigError("--moved and --new-identity: a folder is either the same monitor moved here or another "
                          "one — give one of them")
    bench = load_bench(bench_path)
    if not bench.listens():
        raise ConfigError(f"{bench_path}: acq monitor listens only — set [drive] motion = \"external\" "
                          "(the machine's controller moves the joint)")
    try:
        budget = None if max_disk is None else parse_size(max_disk)
    except ValueError as e:
        raise ConfigError(f"--max-disk {max_disk}: {e}") from None
    settings = MonitorSettings(bench=bench, out_dir=out_dir, window_s=window_s, every_s=parse_duration("--every", every),
                               for_s=None if for_text is None else parse_duration("--for", for_text), on_alarm=on_alarm,
                               keep=keep, max_disk_bytes=budget, fast=fast, jobs=jobs,
                               baseline_windows=baseline_windows, threshold_pct=threshold_pct,
                               ewma_lambda=ewma_lambda, catalogue=catalogue_path, tags=parse_tags(tags), new_identity=new_identity,
                               moved=moved, move_catalogue=move_catalogue)
    console = Console(stderr=True)
    if console.is_terminal:
        with Live(status_table(MonitorStatus(bench.joint)), console=console, refresh_per_second=2) as live:
            monitor = Monitor(settings, on_status=lambda st: live.update(status_table(st)))
            code = monitor.run()
        _say_if_stopped(monitor, catalogue_path or out_dir / CATALOGUE_NAME)
        return code
    last = [""]

    def log(st: MonitorStatus) -> None:  # one line per change when not on a terminal (a service, a log file)
        line = status_line(st)
        if line != last[0]:
            console.print(line, highlight=False, markup=False, soft_wrap=True)
            last[0] = line

    monitor = Monitor(settings, on_status=log)
    code = monitor.run()
    console.print(status_table(monitor.status))
    _say_if_stopped(monitor, catalogue_path or out_dir / CATALOGUE_NAME)
    return code


def status_line(st: MonitorStatus) -> str:
    """The monitor's figures in one line, as a log (not a terminal) gets them at each change: "12.2 min: 2 filed = …,
    excited 93 % of the last window, last K 890.9 (window 3), ΔK — %, learning baseline, 2.3 MB"; a last window filed
    not excited says so and why, "last window not excited (… but too little between f_a and f_r (coherence 0.66,
    below 0.7))", never its excited share alone."""
    last_k = "—" if st.last_K is None else f"{st.last_K:.1f} (window {st.last_K_window})"
    why = "; ".join(filter(None, (st.last_not_excited_why, st.last_segments)))
    excitation = (f", last window not excited ({why})" if st.last_not_excited_why is not None else
                  f", excited {_pct(st.last_excited_fraction)} of the last window" + (f" ({why})" if why else ""))
    return (f"{duration_text(st.machine_time_s)}: {st.filed_total} filed"
            + (f" in this run ({st.in_folder} in the folder)" if st.resumed else "")
            + (f" = {filed_parts(st)}" if st.filed_total else "")
            + (f", {st.not_captured} not captured (disk budget)" if st.not_captured else "")
            + (f", {st.no_room} not captured (disk full)" if st.no_room else "")
            + (f", {catalogue_text(st)}" if st.catalogue_down_since or st.waiting else "")
            + (f", {st.unfinished} not filed (analysis unfinished)" if st.unfinished else "")
            + (f", {st.damaged_kept} damaged kept" if st.damaged_kept else "")
            + excitation + f", last K {last_k}, ΔK {format_value(st.change_pct, '+.1f')} %, {st.state}"
            + (" (baseline unstable)" if st.baseline_warning else "") + f", {st.disk_bytes / 1e6:.1f} MB"
            + (f" — {st.message}" if st.message else ""))


def _say_if_stopped(monitor: Monitor, catalogue: Path | str) -> None:
    """The one line of a monitor stopped by Ctrl-C / SIGTERM (exit 130): what it kept and that a restart resumes."""
    if monitor.stopped_by is None:
        return
    st = monitor.status
    catalogue = redacted(catalogue) if is_url(catalogue) else catalogue  # type: ignore[arg-type]
    waiting = (f" — {st.waiting} more wait in {monitor.spool} for it ({catalogue_text(st)}), filed by the next start"
               if st.waiting else "")
    click.echo(f"acq: {monitor.stopped_by}: {_filed(st)}, all kept in "
               f"{catalogue}{waiting} (trend state: {st.state}); the same command resumes", err=True)
