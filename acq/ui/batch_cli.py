"""``acq analyze FOLDER|GLOB``: the batch of :mod:`acq.monitoring.batch` with its progress bar, table or JSON."""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import click
from rich.console import Console
from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TaskID, TextColumn, TimeElapsedColumn,
                           TimeRemainingColumn)

from acq.monitoring.batch import BatchReport, OnProgress, report_json, run_batch
from acq.monitoring.session_outcome import CATALOGUE_NAME
from acq.monitoring.session_search import find_all_sessions
from acq.monitoring.catalogue import Catalogue
from acq.ui.display import STILL_RECORDING, batch_table
from acq.ui.report_png import draw_report
from acqcore.errors import EXIT_INTERRUPTED, ConfigError, StorageError
from analysis import AnalysisRequest


@contextmanager
def batch_progress(console: Console | None = None) -> Iterator[OnProgress]:
    """A progress bar (on ``console``, default stderr) for :func:`~acq.monitoring.batch.run_batch`'s ``on_progress``:
    shown from the first call (when analyses start; none when every session is current) to the end of the block."""
    columns = (TextColumn("[bold]analysing"), BarColumn(), MofNCompleteColumn(),
               TextColumn("{task.fields[failed]} failed"), TimeElapsedColumn(), TimeRemainingColumn())
    progress = Progress(*columns, console=console or Console(stderr=True))
    tasks: list[TaskID] = []

    def update(done: int, total: int, failed: int) -> None:
        if not tasks:
            progress.start()
            tasks.append(progress.add_task("analysing", total=total, failed=failed))
        progress.update(tasks[0], completed=done, failed=failed)

    try:
        yield update
    except KeyboardInterrupt:
        if tasks:  # stopped: the bar goes (Progress.stop would leave it, or an empty line), the caller's line says
            progress.live.transient = True  # what was done
            progress.live.stop()
            tasks.clear()
        raise
    finally:
        if tasks:
            progress.stop()


def analyze_many(specs: Sequence[Path], request: AnalysisRequest, *, jobs: int | None,
                 catalogue_path: Path | str | None, scheduler: str | None, report: bool, as_json: bool, out: Console,
                 result_dir: Path | None = None) -> int:
    """``acq analyze FOLDER|GLOB|SESSION…``: the batch, its table (or JSON) on ``out``; 1 when a session failed, else
    0; 130 when Ctrl-C stopped it (one line on stderr says how far it got). With ``result_dir`` the results, reports
    and the default catalogue go there (the sessions' folders may be read-only)."""
    paths, base = find_all_sessions(specs)
    if base is None and catalogue_path is None and result_dir is None:
        folders = sorted({str(p.parent) for p in paths})
        raise ConfigError(f"the sessions lie in {len(folders)} folders ({', '.join(folders[:3])}"
                          f"{', …' if len(folders) > 3 else ''}): give --catalogue FILE for the catalogue they go in")
    if result_dir is not None:
        _one_result_name_each(paths, result_dir)
    done: BatchReport | None = None
    location = catalogue_path if catalogue_path is not None else (result_dir or base or Path()) / CATALOGUE_NAME
    try:
        catalogue = Catalogue(location)
    except StorageError as e:  # e.g. a read-only folder of sessions: the way out, as for one session
        way_out = ("give --catalogue a file acq may write" if catalogue_path is not None else
                   "--result-dir DIR writes the results and the catalogue elsewhere" if result_dir is None else
                   "give --result-dir a folder acq may write")
        raise StorageError(f"{e} — {way_out}") from None
    with catalogue:
        try:
            with batch_progress() as on_progress:
                done = run_batch(paths, catalogue, request, jobs=jobs, scheduler=scheduler,
                                 draw_report=draw_report if report else None, on_progress=on_progress,
                                 result_dir=result_dir)
                if done.interrupted:
                    raise KeyboardInterrupt
        except KeyboardInterrupt:
            click.echo(interrupted_line(paths, done, catalogue.path), err=True)
            return EXIT_INTERRUPTED
    if as_json:
        out.print_json(json.dumps(report_json(done)))
    elif done.outcomes:
        out.print(batch_table(done))
        out.print(f"catalogue: {catalogue.path}")
    else:  # every session current (or still recording): one line, not a table without rows
        out.print(nothing_analysed_line(done, catalogue.path), highlight=False, soft_wrap=True)
    return 1 if done.failed else 0


def nothing_analysed_line(done: BatchReport, catalogue: Path | str) -> str:
    """A batch's one line when it analysed no session: how many were current in ``catalogue``, how many are still
    being recorded."""
    parts = [f"{len(done.skipped)} session{'s' if len(done.skipped) != 1 else ''} already analysed (same file, same "
             f"options) in {catalogue}"] if done.skipped else []
    parts += [f"{len(done.not_ready)} {STILL_RECORDING}"] if done.not_ready else []
    return "nothing to analyse: " + ("; ".join(parts) or "no session")


def _one_result_name_each(paths: list[Path], result_dir: Path) -> None:
    """Refuse a batch whose sessions (from several folders) share a file name: their results would overwrite each
    other in ``result_dir``."""
    seen: dict[str, Path] = {}
    for p in paths:
        if p.name in seen:
            raise ConfigError(f"--result-dir {result_dir}: {seen[p.name]} and {p} have the same name, so their "
                              "results would overwrite each other; analyse them into separate folders")
        seen[p.name] = p


def interrupted_line(paths: list[Path], done: BatchReport | None, catalogue: Path | str) -> str:
    """The one line of a batch stopped by Ctrl-C: how many sessions stand analysed in the catalogue and that the same
    command goes on (a session analysed with the same options is skipped). ``done`` is None when the batch stopped
    before comparing the sessions with the catalogue."""
    if done is None:
        return (f"acq: interrupted before any analysis started ({len(paths)} sessions found); run the same command "
                "again to analyse them")
    analysed = len(done.skipped) + sum(o.error is None for o in done.outcomes)
    by_run = len(done.outcomes) - len(done.failed)
    if analysed == len(paths):  # the Ctrl-C came after the last analysis: nothing is left for another run
        return (f"acq: interrupted after the last analysis: all {analysed} sessions analysed ({by_run} by this run), "
                f"in {catalogue}")
    failed = f", {len(done.failed)} failed" if done.failed else ""
    return (f"acq: interrupted: {analysed} of {len(paths)} sessions analysed ({by_run} by this run{failed}), in "
            f"{catalogue}; run the same command again to analyse the other {len(paths) - analysed}")
