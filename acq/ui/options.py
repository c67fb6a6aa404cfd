"""Command-line options that several commands share: ``--catalogue``, ``--tag`` and the trend's alarm rules."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from acq.monitoring.catalogue_backends import is_url


class CatalogueLocation(click.ParamType):
    """``--catalogue``: a SQLite file (a :class:`Path`) or a ``postgresql://`` URL (kept a str)."""

    name = "PATH|URL"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Path | str:
        """The URL as given, anything else as a path."""
        return value if is_url(value) or isinstance(value, Path) else Path(value)


#: ``--tag KEY=VALUE`` (repeatable) of the commands that make a session; read by
#: :func:`acq.recording.tags.parse_tags`.
tag_option = click.option("--tag", "tags", multiple=True, metavar="KEY=VALUE",
                          help="Tag the session (repeatable), e.g. --tag pose=home --tag payload_kg=2.5 "
                               "--tag temperature_C=31.")


F = TypeVar("F", bound=Callable[..., Any])


def alarm_rule_options(whose: str) -> Callable[[F], F]:
    """``--baseline-sessions``, ``--threshold-pct``, ``--ewma-lambda`` of :class:`acq.monitoring.alarm_rules.AlarmRules`,
    each None unless given (then the rules acq monitor filed with ``whose`` windows, else acq's defaults)."""
    default = f"default: as acq monitor judged {whose} windows, else"

    def apply(command: F) -> F:
        for option in reversed((
                click.option("--baseline-sessions", type=click.IntRange(min=1), default=None,
                             help=f"Baseline = mean K of the first N good sessions ({default} 1)."),
                click.option("--threshold-pct", type=click.FloatRange(0, 100, min_open=True), default=None,
                             help=f"Alarm when K is this many % below the baseline ({default} 10)."),
                click.option("--ewma-lambda", type=click.FloatRange(0, 1, min_open=True), default=None,
                             help=f"EWMA weight of the newest session, alarm at the 3σ control limit ({default} "
                                  "0.2)."))):
            command = option(command)
        return command
    return apply
