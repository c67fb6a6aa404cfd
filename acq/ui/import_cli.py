"""``acq import``: the command line of :mod:`acq.offline.importers` (the session's summary, warnings on stderr)."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console
from rich.markup import escape

from acq.recording.tags import parse_tags
from acq.ui.options import tag_option


@click.command("import")
@click.option("--current", "current_path", required=True, type=click.Path(path_type=Path),
              help="Current file: CSV (t_s, i_a_A [, i_b_A, i_c_A]) or TDMS.")
@click.option("--current-channel", "current_channels", multiple=True, metavar="GROUP/CHANNEL",
              help="TDMS channel of a phase, repeat in phase order a, b, c (default: the file's only channel).")
@click.option("--encoder", "encoder_path", required=True, type=click.Path(path_type=Path),
              help="Encoder CSV (t_s, position_counts [, index] [, drive_time_s]).")
@click.option("--bench", "bench_path", default=None, type=click.Path(path_type=Path),
              help="Bench TOML (default: the bench as used, from the acq export metadata beside the files).")
@click.option("--profile", "profile_name", default=None,
              help="Profile name in configs/profiles/ or a TOML path (default: from the acq export metadata; none "
                   "for a bench with [drive] motion = \"external\": a passive recording).")
@click.option("--joint", default=None, help="Joint name (default: the bench config's).")
@click.option("--same-clock", is_flag=True,
              help="Both files' t_s are stamps on one host clock (one tool wrote both): let them narrow the clock "
                   "search. Without it only a pair from acq export (its metadata says so) counts as one clock.")
@click.option("--started", "started", default=None, metavar="ISO-TIME",
              help="When the recording started, ISO 8601 (UTC if no zone), e.g. 2026-11-20T10:15:03Z (default: "
                   "from the acq export metadata, a TDMS wf_start_time, else now). The catalogue and trend sort by it.")
@click.option("-o", "--out", "out_path", required=True, type=click.Path(path_type=Path),
              help="Session file to write, named *.h5 (its folder is made if missing).")
@tag_option
def import_command(current_path: Path, current_channels: tuple[str, ...], encoder_path: Path, bench_path: Path | None,
                   profile_name: str | None, joint: str | None, same_clock: bool, started: str | None, out_path: Path,
                   tags: tuple[str, ...]) -> int:
    """Turn a current file and an encoder CSV recorded by other tools into a session."""
    from acq.config import load_bench, load_profile  # numpy, h5py and pydantic only when the command runs
    from acq.offline.importers import import_session, parse_started
    from acq.recording.reader import load
    from acq.recording.summary import summarize
    from acq.ui.display import summary_table

    result = import_session(current_path, encoder_path, load_bench(bench_path) if bench_path else None,
                            load_profile(profile_name) if profile_name else None, out_path, current_channels,
                            tags=parse_tags(tags), joint=joint, same_clock=same_clock,
                            started_utc=parse_started(started) if started else None)
    console = Console()
    console.print(summary_table(summarize(load(result.path))))
    for warning in result.warnings:
        Console(stderr=True).print(f"[yellow]warning[/]: {escape(warning)}")
    console.print(f"imported → {escape(str(result.path))}")
    return 0
