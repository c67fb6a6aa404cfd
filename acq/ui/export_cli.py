"""``acq export``: the command line of :mod:`acq.offline.exporters` (one line per file written)."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console
from rich.markup import escape

from acq.ui.options import Folder


@click.command("export")
@click.argument("session_path", type=click.Path(path_type=Path))
@click.option("--csv", "csv_dir", required=True, type=Folder(its_folder=False),
              help="Folder for the current and encoder CSV files (the pair `acq import` reads) and the metadata.")
@click.option("--force", is_flag=True, help="Replace files of an earlier export (default: refuse, write nothing).")
@click.option("--partial", is_flag=True, help="Also export a session still being recorded (status recording) or "
                                              "damaged: its intact part, the metadata naming what is missing.")
def export_command(session_path: Path, csv_dir: Path, force: bool, partial: bool) -> int:
    """Export SESSION to a current CSV, an encoder CSV and the session's metadata (JSON)."""
    from acq.offline.exporters import export_csv  # numpy and h5py only when the command runs

    written, left_out, missing = export_csv(session_path, csv_dir, force=force, partial=partial)
    out = Console(soft_wrap=True)  # a path or a list of names stays on one line, whatever the width
    for path in written:
        out.print(f"wrote {escape(str(path))}")
    if left_out:
        out.print(f"note: not in the CSV pair (acq import does not read them yet): {', '.join(left_out)}")
    if missing:
        click.echo(f"acq: warning: {missing}", err=True)
    return 0
