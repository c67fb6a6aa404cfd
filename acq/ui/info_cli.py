"""``acq info``: a session's summary (samples, durations, effective rates, gaps) as a table or JSON, and a warning
when the session is damaged or still marked as being recorded.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import click
from rich.console import Console

from acq.recording.paths import require_session_file

if TYPE_CHECKING:
    from acq.recording.session import Session

out = Console()


@click.command(name="info")
@click.argument("session_path", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def info_command(session_path: Path, as_json: bool) -> int:
    """Summarise a session: samples, durations, effective rates, gaps."""
    require_session_file(session_path)
    from acq.ui.display import summary_table
    from acq.recording.reader import load
    from acq.recording.summary import summarize

    session = load(session_path)
    summary = summarize(session)
    warning = _integrity_warning(session)
    if as_json:
        doc = summary.to_json_dict()
        doc["damage"] = list(session.damage)
        click.echo(json.dumps(doc, indent=2))
    else:
        out.print(summary_table(summary))
    if warning:
        click.echo(f"acq: warning: {warning}", err=True)
    return 0


def _integrity_warning(session: Session) -> str | None:
    """One line when a session is damaged (saying to run acq check) or still ``recording`` (what to do then)."""
    if session.damage:
        return f"{session.path}: damaged ({'; '.join(session.damage)}) — run acq check {session.path}"
    if session.status == "recording":
        return f"{session.path}: {session.unfinished_note()}"
    return None
