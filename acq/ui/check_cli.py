"""``acq check``: verify a session's checksums and committed counts, repair a session a killed recorder left, copy
the intact part of a damaged one (``--repair``).
"""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console

from acq.recording.paths import require_session_file

out = Console()


@click.command(name="check")
@click.argument("session_path", type=click.Path(path_type=Path))
@click.option("--repair", "write_intact", is_flag=True,
              help="Copy the intact part of a damaged session (a cut copy, a chunk that fails its checksum) into a "
                   "new session beside it, NAME.recovered.h5 (status interrupted, the loss in its stop reason; an "
                   "earlier copy is replaced). The damaged file is not written.")
def check_command(session_path: Path, write_intact: bool) -> int:
    """Verify a session's checksums (every dataset's, the commit table's too) and committed counts; repair one left
    by a killed recorder.

    Exit 0 when the session is intact (or a killed recorder's intact file was repaired, or a running recorder still
    writes it: then it is only read), 1 when damage was found (each damaged span is listed), also when the intact
    part was copied. A damaged file is never rewritten: a killed recorder's damaged file, like ``--repair``, has its
    intact part copied into NAME.recovered.h5 beside it.
    """
    require_session_file(session_path)
    from acq.ui.display import summary_table
    from acq.recording.live import being_recorded
    from acq.recording.reader import load
    from acq.recording.repair import recover, recovered_path, repair
    from acq.recording.summary import summarize

    session = load(session_path)
    if being_recorded(session_path):  # a live file is never rewritten nor copied: report what it holds now
        out.print(summary_table(summarize(session)))
        click.echo(f"{session_path}: being recorded by a running recorder: "
                   f"{session.current.sample_count / session.current.rate_hz:.1f} s committed so far; not modified")
        return 0
    killed = session.status == "recording"
    if killed and not session.damage:
        session = repair(session_path, "recorder stopped without finishing the file (found by acq check)")
        out.print(summary_table(summarize(session)))
        out.print(f"{session_path}: interrupted — the recorder stopped without finishing the file; repaired: "
                  f"status = interrupted, {session.current.sample_count} current and {session.encoder.index.size} "
                  "encoder samples kept")
        return 0
    out.print(summary_table(summarize(session)))
    if not session.damage:
        click.echo(f"{session_path}: {session.status}, checksums and counts verified ({session.current.sample_count} "
                   f"current, {session.encoder.index.size} encoder samples), nothing to repair")
        return 0
    for line in session.damage:
        click.echo(f"{session_path}: {line}")  # plain lines (no wrapping): scripts grep them
    intact = session.current.sample_count > 0 or session.encoder.index.size > 0
    if killed:
        click.echo(f"{session_path}: the recorder stopped without finishing the file, and the file is damaged: not "
                   "rewritten (a rewrite would lose what cannot be read now)")
    if intact and (write_intact or killed):
        copy = recover(session_path)
        click.echo(f"{session_path}: intact part copied into {copy.path}: {copy.current.sample_count} current and "
                   f"{copy.encoder.index.size} encoder samples, status {copy.status}, stop reason: "
                   f"{copy.meta.stop_reason}")
        click.echo(f"acq: damaged: {session_path} ({'; '.join(session.damage)}) — not modified; its intact part is "
                   f"in {copy.path}", err=True)
        return 1
    streams = ("current", "encoder")
    after = ([session.kept_after_first_damage(stream) for stream in streams]
             if any(name in streams for name, _, _ in session.damage_spans) else [0, 0])  # /flushes alone: none
    use = (f" (acq analyze --partial uses it; acq check --repair copies it into {recovered_path(session_path)})"
           if intact else "")
    click.echo(f"acq: damaged: {session_path} ({'; '.join(session.damage)}) — the intact part holds "
               f"{session.current.sample_count} current and {session.encoder.index.size} encoder samples"
               + (f", {after[0]} and {after[1]} of them after the first damaged span" if any(after) else "")
               + use, err=True)
    return 1
