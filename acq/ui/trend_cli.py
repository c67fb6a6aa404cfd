"""``acq trend``: the command line of :mod:`acq.monitoring.trend` (table, JSON, PNG; exit code 3 while in alarm)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import click
from rich.console import Console

from acq.ui.options import CatalogueLocation, Folder, PngPath, alarm_rule_options
from acq.monitoring.trend import EXIT_ALARM, trend_json
from acq.monitoring.trend_catalogue import catalogue_sources, load_trend
from acq.ui.display import trend_table
from acq.ui.trend_plot import render_trend_png
from acqcore.errors import ConfigError


@click.command(name="trend")
@click.argument("folders", nargs=-1, type=Folder(catalogue_option=True))
@click.option("--catalogue", "catalogues", type=CatalogueLocation(), multiple=True,
              help="A catalogue, a file or postgresql:// URL (repeatable; default: FOLDER/catalogue.sqlite of each "
                   "FOLDER, FOLDER defaulting to sessions/). Several: one trend each, never mixed.")
@click.option("--joint", required=True, help="The joint to trend.")
@alarm_rule_options("the joint's")
@click.option("--baseline", "baseline_id", default=None, help="Baseline = this session id (or a unique prefix).")
@click.option("--tag", "tags", multiple=True, metavar="KEY=VALUE",
              help="Only sessions with this tag (repeatable; read as acq record --tag reads it: 2.5 a number, 007 "
                   "text).")
@click.option("--no-monitor", "no_monitor", is_flag=True,
              help="Only the sessions of no monitor (a bench's recordings, imports) where a monitor's windows share "
                   "the joint's name.")
@click.option("--png", "png_path", type=PngPath(), default=None,
              help="Also draw the trend into this PNG.")
@click.option("--json", "as_json", is_flag=True, help="Print the trend as JSON.")
def trend_command(folders: tuple[Path, ...], catalogues: tuple[Path | str, ...], joint: str,
                  baseline_sessions: int | None, baseline_id: str | None, threshold_pct: float | None,
                  ewma_lambda: float | None, tags: tuple[str, ...], no_monitor: bool, png_path: Path | None,
                  as_json: bool) -> int:
    """K of a joint over time (± 95 %), f_a, f_r, baseline and alarms; exit code 3 while in alarm.

    Several FOLDERs / catalogues: the joint's trend in each, judged apart (a table each, --json a list); exit code 3
    while any is in alarm."""
    if baseline_id is not None and baseline_sessions is not None:
        raise ConfigError("--baseline and --baseline-sessions: give one of them")
    sources = catalogue_sources(folders, catalogues)
    if len(sources) > 1 and (png_path is not None or baseline_id is not None):
        raise ConfigError(f"{'--png' if png_path is not None else '--baseline'} is for one trend: give one FOLDER or "
                          "--catalogue")
    trends = []
    for label, location in sources:
        trend = load_trend(None, location, joint, tags, no_monitor, baseline_sessions=baseline_sessions,
                           baseline_id=baseline_id, threshold_pct=threshold_pct, ewma_lambda=ewma_lambda)
        trends.append(replace(trend, joint=f"{joint} ({label})") if len(sources) > 1 else trend)
    out = Console()
    if as_json:
        docs = [trend_json(t) for t in trends]
        click.echo(json.dumps(docs if len(docs) > 1 else docs[0], indent=2))
    else:
        for trend in trends:
            out.print(trend_table(trend))
    if png_path is not None:
        render_trend_png(trends[0], png_path)
        if not as_json:
            out.print(f"plot: {png_path}")
    return EXIT_ALARM if any(t.alarm for t in trends) else 0
