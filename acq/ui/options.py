"""Command-line options that several commands share: ``--catalogue`` and ``--tag``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

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
