"""``acq analyze``: identify one session (its result as a table or JSON, then its report PNG) or, for a folder, a glob
or several sessions, a batch into the catalogue (:mod:`acq.ui.batch_cli`). :func:`identify` and
:func:`print_result_and_draw` serve ``acq record`` too, which identifies the session it has just recorded.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click
from rich.console import Console

from acq.recording.paths import is_batch, require_session_file
from acq.ui.options import CatalogueLocation, Folder
from acqcore.errors import ConfigError, StorageError

if TYPE_CHECKING:
    from analysis import AnalysisRequest
    from acq.offline.analyze import SessionResult

out = Console()
err = Console(stderr=True)


@click.command(name="analyze")
@click.argument("session_paths", metavar="SESSION...", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--torque", type=click.Choice(["encoder", "hilbert", "park"]), default=None,
              help="Torque from current: encoder-angle demodulation (default, one phase), Park (≥ 2 phases), "
                   "or the paper's Hilbert envelope.")
@click.option("--params", type=click.Choice(["K,Jm,Jl", "K"]), default="K,Jm,Jl", show_default=True,
              help="Free parameters besides C; K fixes J_m, J_l to the bench's nominal values.")
@click.option("--fit", "fit_kind", type=click.Choice(["amplitude", "complex"]), default="amplitude",
              show_default=True, help="Fit the FRF amplitude (paper) or the complex FRF.")
@click.option("--band", default=None, help="Fit band LO,HI in Hz (default 10 … min(0.4·f_enc, 500)).")
@click.option("--paper", is_flag=True, help="The paper's chain: Hilbert torque, no clock alignment, linear "
                                            "resampling, uniform weights (for comparison).")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON on stdout (keys: README, \"The result\"; "
                                                    "K, J_m, J_l, C are motor-side).")
@click.option("--no-report", is_flag=True, help="Do not draw <session>.report.png.")
@click.option("--wait-report", is_flag=True,
              help="With --json: exit only once <session>.report.png is written (default: the JSON is printed at "
                   "once and the picture drawn by a background process; a failure goes to <session>.report.log "
                   "and a note in the .result.json).")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Folder or glob: parallel analyses (default: the CPU count).")
@click.option("--catalogue", "catalogue_path", type=CatalogueLocation(), default=None,
              help="The catalogue to fill: a SQLite file (default: catalogue.sqlite in the session's folder) or a "
                   "postgresql://user@host/db URL shared by several hosts.")
@click.option("--partial", is_flag=True, help="Also analyse a session still being recorded (status recording) or "
                                              "damaged: its intact part, the result marked partial.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Folder or glob: run on a Dask distributed cluster (tcp://host:8786); the workers must reach "
                   "the session files at the same paths.")
@click.option("--result-dir", type=Folder(), default=None, metavar="DIR",
              help="Write the .result.json and .report.png (and the default catalogue) into DIR instead of beside "
                   "the session, e.g. for a read-only archive.")
def analyze_command(session_paths: tuple[Path, ...], torque: str | None, params: str, fit_kind: str, band: str | None,
                    paper: bool, as_json: bool, no_report: bool, wait_report: bool, jobs: int | None,
                    catalogue_path: Path | str | None, partial: bool, scheduler: str | None,
                    result_dir: Path | None) -> int:
    """Identify K, J_m, J_l, C of SESSION; write <session>.result.json and <session>.report.png.

    That is the session's result (acq view, the trend). Any other request writes beside it, never over it:
    <session>.<label>.result.json and .report.png, the label saying what differs, its parts in this order:
    paper, torque-<method>, params-K, fit-complex, band-<lo>-<hi>, e.g. --band 10,150 --params K writes
    <session>.params-K.band-10-150.result.json.

    SESSION may be a folder or a glob ('sessions/*.h5'), or several sessions, folders or globs (sessions/*.h5 as
    the shell expands it): every session not yet current in the catalogue (same file hash and options) is analysed
    in parallel and recorded there; exit code 1 if any failed.
    """
    session_path = session_paths[0]
    batch = len(session_paths) > 1 or is_batch(session_path)
    if not batch:
        require_session_file(session_path)  # a mistyped path is one line before the analysis's libraries load
        _note_batch_only_options(scheduler, jobs)
    from analysis import AnalysisRequest

    request = AnalysisRequest(torque_method=torque, params=params, fit=fit_kind,  # type: ignore[arg-type]
                              band_hz=_parse_band(band), pipeline="paper" if paper else "acq", partial=partial)
    if result_dir is not None:
        result_dir = _result_folder(result_dir)
    if batch:
        from acq.ui.batch_cli import analyze_many

        return analyze_many(session_paths, request, jobs=jobs, catalogue_path=catalogue_path, scheduler=scheduler,
                            report=not no_report, as_json=as_json, out=out, result_dir=result_dir)
    from acq.offline.analyze import ResultNotWritten

    try:
        return _analyze_one_session(session_path, request, as_json=as_json, report=not no_report,
                                    wait_report=wait_report, catalogue_path=catalogue_path, result_dir=result_dir)
    except ResultNotWritten as e:  # the numbers first (the analysis ran), then the failed write: exit 1
        if as_json:
            click.echo(json.dumps(e.done.json_dict, indent=2))
        else:
            from acq.ui.display import result_table

            out.print(result_table(e.done.json_dict))
        elsewhere = ("--result-dir DIR writes it elsewhere" if result_dir is None
                     else "give --result-dir a folder acq may write")  # not the option already given
        raise StorageError(f"{e} — the result above is not saved ({elsewhere})") from None


def _note_batch_only_options(scheduler: str | None, jobs: int | None) -> None:
    """One line on stderr when options that only place a batch's analyses (``--scheduler``, ``--jobs``) come with a
    single session, which is analysed here, in this process: they change where the work runs, never the result, so
    the analysis goes on (a script passing the same options for a folder or one file keeps working), but not silently
    elsewhere than asked."""
    given = ([f"--scheduler {scheduler}"] if scheduler is not None else []) + ([f"--jobs {jobs}"] if jobs else [])
    if given:
        click.echo(f"acq: note: {' and '.join(given)} only place{'s' if len(given) == 1 else ''} the analyses of a "
                   "batch (a folder, a glob or several sessions): this one session is analysed here, in this process",
                   err=True)


def _parse_band(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--band {text}: must be LO,HI in Hz, e.g. 10,400") from None
    if not 0 < lo < hi:
        raise ConfigError(f"--band {text}: must be LO,HI in Hz with 0 < LO < HI")
    return lo, hi


def _result_folder(result_dir: Path) -> Path:
    """``--result-dir``: the folder, made if missing, as an absolute path (the batch's workers are handed it)."""
    from acq.recording.storage import make_folders, storage_error

    try:
        make_folders(result_dir)
    except OSError as e:
        if isinstance(e, FileNotFoundError):  # a folder that cannot be made there (e.g. under /proc): bad input
            raise ConfigError(f"--result-dir {result_dir}: cannot make a folder there "
                              f"({(e.strerror or 'no such file or directory').lower()})") from None
        raise storage_error(e, f"--result-dir {result_dir}") from None
    return result_dir.resolve()


def _analyze_one_session(session_path: Path, request: AnalysisRequest, *, as_json: bool, report: bool,
                         wait_report: bool, catalogue_path: Path | str | None, result_dir: Path | None) -> int:
    """``acq analyze SESSION``: the result as a table (or JSON), then its report PNG."""
    if as_json:
        from acq.ui.report_png import draw_report, draw_report_detached

        done = identify(session_path, request, report=report, catalogue_path=catalogue_path, result_dir=result_dir)
        click.echo(json.dumps(done.json_dict, indent=2))
        sys.stdout.flush()  # the numbers reach the reader before the picture is drawn
        # a picture that fails is a note in the .result.json, and a line on stderr (here) or in <session>.report.log
        if wait_report:
            draw_report(done)
        else:
            draw_report_detached(done)
        return 0
    with err.status(f"analysing {session_path} …"):
        done = identify(session_path, request, report=report, catalogue_path=catalogue_path, result_dir=result_dir)
    from acq.offline.analyze import output_paths
    from analysis import AnalysisRequest

    # a variant as answered: an option that named the default is the session's result (as_default_where_it_is)
    variant = done.request.variant_label()
    default_result = output_paths(session_path, AnalysisRequest(), result_dir)[0] if variant else None
    print_result_and_draw(done, default_result)
    return 0


def identify(path: Path, request: AnalysisRequest, *, report: bool, catalogue_path: Path | str | None,
              result_dir: Path | None = None) -> SessionResult:
    """Analyse one session with ``request`` and put the result into its folder's catalogue; the report PNG is drawn
    after both (:func:`acq.ui.report_png.draw_report`: a picture that fails is only a note), by the caller. A result
    that could not be written raises :class:`acq.offline.analyze.ResultNotWritten` (nothing catalogued)."""
    from acq.offline.analyze import analyze_session
    from acq.monitoring.session_outcome import quiet_numerics, record_outcome

    start = time.perf_counter()
    with quiet_numerics():
        done = analyze_session(path, request, report=report, result_dir=result_dir)
    try:
        record_outcome(done, catalogue_path, time.perf_counter() - start)
    except BaseException:  # no result without its catalogue row (a later batch analyses the session again)
        done.json_path.unlink(missing_ok=True)
        raise
    return done


def print_result_and_draw(done: SessionResult, default_result: Path | None = None) -> None:
    """Print the identified values and where the result is (for a request other than the default, also the
    session's ``default_result``, which it left as it was), then draw the report PNG and say where it is (the
    person reads the numbers while the picture is drawn)."""
    from acq.ui.display import result_table
    from acq.ui.report_png import draw_report

    out.print(result_table(done.json_dict))
    kept = "" if default_result is None else f" (beside the session's result {default_result.name}, left as it was)"
    out.print(f"result: {done.json_path}{kept}")
    if done.report_path is None:
        return
    with err.status("drawing the report …"):
        done = draw_report(done)  # a picture that fails is a note in the .result.json and a line on stderr
    if done.report_path is not None:
        out.print(f"report: {done.report_path}")
