"""``acq trend``: the command line of :mod:`acq.monitoring.trend` (table, JSON, PNG; exit code 3 while in alarm)."""

from __future__ import annotations

import json
from pathlib import Path

import click
from rich.console import Console

from acq.ui.options import CatalogueLocation, alarm_rule_options
from acq.monitoring.trend import EXIT_ALARM, load_trend, trend_json
from acq.ui.display import trend_table
from acq.ui.trend_plot import render_trend_png
from acqcore.errors import ConfigError


@click.command(name="trend")
@click.argument("folder", required=False, type=click.Path(path_type=Path, file_okay=False))
@click.option("--catalogue", "catalogue_path", type=CatalogueLocation(), default=None,
              help="The catalogue, a file or postgresql:// URL (default: FOLDER/catalogue.sqlite, FOLDER defaulting "
                   "to sessions/).")
@click.option("--joint", required=True, help="The joint to trend.")
@alarm_rule_options("the joint's")
@click.option("--baseline", "baseline_id", default=None, help="Baseline = this session id (or a unique prefix).")
@click.option("--tag", "tags", multiple=True, metavar="KEY=VALUE", help="Only sessions with this tag (repeatable).")
@click.option("--png", "png_path", type=click.Path(path_type=Path), default=None,
              help="Also draw the trend into this PNG.")
@click.option("--json", "as_json", is_flag=True, help="Print the trend as JSON.")
def trend_command(folder: Path | None, catalogue_path: Path | str | None, joint: str, baseline_sessions: int | None,
                  baseline_id: str | None, threshold_pct: float | None, ewma_lambda: float | None, tags: tuple[str, ...],
                  png_path: Path | None, as_json: bool) -> int:
    """K of a joint over time (± 95 %), f_a, f_r, baseline and alarms; exit code 3 while in alarm."""
    if baseline_id is not None and baseline_sessions is not None:
        raise ConfigError("--baseline and --baseline-sessions: give one of them")
    trend = load_trend(folder, catalogue_path, joint, tags, baseline_sessions=baseline_sessions,
                       baseline_id=baseline_id, threshold_pct=threshold_pct, ewma_lambda=ewma_lambda)
    out = Console()
    if as_json:
        click.echo(json.dumps(trend_json(trend), indent=2))
    else:
        out.print(trend_table(trend))
    if png_path is not None:
        render_trend_png(trend, png_path)
        if not as_json:
            out.print(f"plot: {png_path}")
    return EXIT_ALARM if trend.alarm else 0
