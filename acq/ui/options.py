"""Command-line options that several commands share: ``--catalogue``, ``--tag`` and the trend's alarm rules."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from acq.monitoring.catalogue_backends import URL_SCHEMES, folder_error, is_url, redacted
from acq.recording.paths import is_catalogue_file
from acqcore.errors import ConfigError


class CatalogueLocation(click.ParamType):
    """``--catalogue``: a SQLite file (a :class:`Path`) or a ``postgresql://`` URL (kept a str)."""

    name = "PATH|URL"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Path | str:
        """The URL as given, anything else as a path; a URL of another scheme (``mysql://…``, which as a path read
        ``mysql:/…``) is refused naming its scheme and the ones acq reads; so is a folder (:func:`folder_error`)."""
        if is_url(value) or isinstance(value, Path):
            return value
        scheme = re.match(r"([A-Za-z][A-Za-z0-9+.-]*)://", value)
        if scheme:
            option = param.opts[0] if param is not None else "--catalogue"
            raise ConfigError(f"{option} {redacted(value)}: {scheme.group(1)}:// is not a catalogue acq can use — "
                              f"give a SQLite file's path or a {URL_SCHEMES[0]} URL (or {', '.join(URL_SCHEMES[1:])})")
        if Path(value).is_dir():  # before an analysis runs: SQLite would say only "unable to open database file"
            raise folder_error(Path(value))
        return Path(value)


class FiniteFloatRange(click.FloatRange):
    """A :class:`click.FloatRange` that refuses ``nan`` and ``inf``: click's range lets both through (every comparison
    with nan is false; inf is above any min) — ``acq monitor --window nan`` ended in a traceback, ``--window inf`` in a
    refusal of --every, ``--threshold-pct nan`` ran a monitor that never alarms (the trial)."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        """The float, or click's one-line "Invalid value for '--window': nan is not a finite number." (exit 2)."""
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value} is not a finite number.", param, ctx)
        return number


class PngPath(click.ParamType):
    """A PNG acq writes on request (``--png``, ``--screenshot``): a :class:`Path` named ``*.png`` that is not a folder,
    refused in one line (bad input, exit 2) before anything is drawn. A write that then fails is a failed write
    (:func:`acq.ui.qt_app.grab_png`, exit 1)."""

    name = "PATH"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Path:
        """``value`` as a Path; :class:`ConfigError` naming the option for another suffix or a folder."""
        path, option = Path(value), param.opts[0] if param is not None else "PNG"
        if path.is_dir():
            raise ConfigError(f"{option} {value}: is a folder — give the PNG's file name, e.g. {path / 'out.png'}")
        if path.suffix.lower() != ".png":
            raise ConfigError(f"{option} {value}: acq writes PNG only — name the file *.png, e.g. "
                              f"{path.with_suffix('.png') if path.suffix else f'{path}.png'}")
        return path


def require_folder(path: Path, option: str | None = None, *, catalogue_option: bool = False,
                   its_folder: bool = True) -> None:
    """Refuse ``path`` in one line (bad input) when it exists but is not a folder, naming ``option`` (``--out``) or,
    for an argument, the path alone. A catalogue (a SQLite file, e.g. FOLDER/catalogue.sqlite given for FOLDER) is
    called one, with the folder it lies in as the way out where that is the folder meant (``its_folder``: a catalogue
    lives in the folder the option names) and ``--catalogue PATH`` where the command reads one (``catalogue_option``).
    """
    if not path.exists() or path.is_dir():
        return
    named = f"{option} {path}" if option else str(path)
    if not is_catalogue_file(path):  # unreadable: a file all the same
        raise ConfigError(f"{named}: is a file, not a folder")
    folder = f"{option} {path.parent}" if option else str(path.parent)
    raise ConfigError(f"{named}: is a catalogue (SQLite) file, not a folder — give "
                      + (f"the folder, e.g. {folder}" if its_folder else "a folder")
                      + (f", or --catalogue {path}" if catalogue_option else ""))


class Folder(click.ParamType):
    """A folder acq reads or writes (``--out``, ``--result-dir``, ``--csv``, trend's FOLDER): a :class:`Path` that is
    a folder or does not exist yet; a file there is refused (:func:`require_folder`) before anything starts."""

    name = "FOLDER"

    def __init__(self, catalogue_option: bool = False, its_folder: bool = True) -> None:
        self.catalogue_option, self.its_folder = catalogue_option, its_folder

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Path:
        """``value`` as a Path; :class:`ConfigError` naming the option (or, for an argument, the path) for a file."""
        path = Path(value)
        option = param.opts[0] if isinstance(param, click.Option) else None
        require_folder(path, option, catalogue_option=self.catalogue_option, its_folder=self.its_folder)
        return path


#: ``--tag KEY=VALUE`` (repeatable) of the commands that make a session; read by
#: :func:`acq.recording.tags.parse_tags`.
tag_option = click.option("--tag", "tags", multiple=True, metavar="KEY=VALUE",
                          help="Tag the session (repeatable), e.g. --tag pose=home --tag payload_kg=2.5 "
                               "--tag temperature_C=31. A value spelt as a decimal number (2.5, -3, 31, 1e3) is "
                               "stored as a number, any other (home, 007, +5) as text; each key once, no empty value, "
                               "no nan or inf.")


F = TypeVar("F", bound=Callable[..., Any])


def alarm_rule_options(whose: str) -> Callable[[F], F]:
    """``--baseline-sessions``, ``--threshold-pct``, ``--ewma-lambda`` of :class:`acq.monitoring.alarm_rules.AlarmRules`,
    each None unless given (then the rules acq monitor filed with ``whose`` windows, else acq's defaults)."""
    default = f"default: as acq monitor judged {whose} windows, else"

    def apply(command: F) -> F:
        for option in reversed((
                click.option("--baseline-sessions", type=click.IntRange(min=1), default=None,
                             help=f"Baseline = mean K of the first N good sessions ({default} 1)."),
                click.option("--threshold-pct", type=FiniteFloatRange(0, 100, min_open=True), default=None,
                             help=f"Alarm when K is this many % below the baseline ({default} 10)."),
                click.option("--ewma-lambda", type=FiniteFloatRange(0, 1, min_open=True), default=None,
                             help=f"EWMA weight of the newest session, alarm at the 3σ control limit ({default} "
                                  "0.2)."))):
            command = option(command)
        return command
    return apply
