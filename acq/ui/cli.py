"""The ``acq`` command line: record, info, check (more commands register themselves below).

Errors for people: an :class:`~acqcore.errors.AcqError` anywhere becomes one line on stderr and
exit code 2 (bad input) or 1 (device, failed write); a usage error is one line too (exit 2); Ctrl-C is
exit 130.
"""

from __future__ import annotations

import importlib
import json
import math
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import click
from rich.console import Console

from acq import __version__
from acq.recording.paths import is_batch, require_session_file
from acq.recording.tags import parse_tags
from acq.ui.options import CatalogueLocation, tag_option
from acqcore.errors import EXIT_INTERRUPTED, AcqError, ConfigError, StorageError

if TYPE_CHECKING:
    from analysis import AnalysisRequest
    from acq.offline.analyze import SessionResult
    from acq.recording.recorder import Recorder, RecordingResult
    from acq.recording.session import Session
    from drivers.config import Bench
    from drivers.profile import Profile

# numpy, scipy, h5py, pydantic and Qt are imported inside the commands that use them: `acq --help`, a command's
# --help and a mistyped path print at once (1.1 s of imports before; bench/cli_start.py measures it)

out = Console()
err = Console(stderr=True)


#: Commands defined in modules of their own: name → (module, attribute, the command's short help). A module is
#: imported only when its command runs or shows its own --help, so the list in `acq --help` carries the short help
#: (tests/test_analyze_cli.py keeps it equal to the command's own).
LAZY_COMMANDS: dict[str, tuple[str, str, str]] = {
    "devices": ("acq.ui.devices_cli", "devices_command",
                "List NI devices and AI channels, CAN interfaces, serial ports and the simulated bench."),
    "export": ("acq.ui.export_cli", "export_command",
               "Export SESSION to a current CSV, an encoder CSV and the session's metadata (JSON)."),
    "fleet": ("acq.ui.fleet_display", "fleet_command",
              "Every joint (by robot tag): latest K ± 95 %, ΔK to its baseline, sessions of the last day, state "
              "(alarm / stale / no baseline / ok), worst first; exit code 3 if any joint is in alarm."),
    "import": ("acq.ui.import_cli", "import_command",
               "Turn a current file and an encoder CSV recorded by other tools into a session."),
    "monitor": ("acq.ui.monitor_cli", "monitor_command",
                "Listen to a running machine window by window, trend K, raise the alarm; exit code 3 if it ends in "
                "alarm."),
    "selftest": ("acq.ui.selftest_cli", "selftest_command",
                 "Check the bench and its config against the data: devices, streams, a slow move, an identification."),
    "trend": ("acq.ui.trend_cli", "trend_command",
              "K of a joint over time (± 95 %), f_a, f_r, baseline and alarms; exit code 3 while in alarm."),
    "view": ("acq.ui.view", "view_command",
             "Show traces, FRF with the fitted model, coherence and identified values of SESSION(s); or, with "
             "--trend JOINT [FOLDER], the joint's stiffness over time."),
}


class _Interrupted(BaseException):
    """A Ctrl-C inside a command, carried past click (whose own handling writes an empty line before its Abort):
    acq says ``acq: interrupted`` in one line."""


def _raise_interrupted(signum: int, frame: object) -> None:
    raise _Interrupted


#: The handlers of Ctrl-C and SIGTERM while a command runs (a KeyboardInterrupt, which a batch or a recording catches to
#: tidy up); around it, in click's own frames, :func:`_raise_interrupted` (:func:`_interrupted_outside_the_command`).
_command_handlers: dict[int, object] = {}


class LazyGroup(click.Group):
    """A group whose :data:`LAZY_COMMANDS` load on first use (click's documented "lazy loading" pattern)."""

    def invoke(self, ctx: click.Context) -> object:
        outside: dict[int, object] = {}
        try:
            outside.update((s, signal.signal(s, h)) for s, h in _command_handlers.items())  # type: ignore[arg-type]
            return super().invoke(ctx)
        except KeyboardInterrupt:
            raise _Interrupted from None
        finally:
            for s, h in outside.items():
                signal.signal(s, h)  # type: ignore[arg-type]

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted([*super().list_commands(ctx), *LAZY_COMMANDS])

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in LAZY_COMMANDS:
            module, attribute, _ = LAZY_COMMANDS[cmd_name]
            return getattr(importlib.import_module(module), attribute)
        return super().get_command(ctx, cmd_name)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list as click writes it, the lazy commands' short help taken from :data:`LAZY_COMMANDS`."""
        names = self.list_commands(ctx)
        limit = formatter.width - 6 - max(len(name) for name in names)
        # a lazy command's short help cut as click cuts it, from a stand-in command (no import of its module)
        commands = [click.Command(name, help=LAZY_COMMANDS[name][2]) if name in LAZY_COMMANDS else self.commands[name]
                    for name in names]
        rows = [(c.name or "", c.get_short_help_str(limit)) for c in commands]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="acq")
def cli() -> None:
    """Record a robot joint on the bench and identify its stiffness K and inertias J_m, J_l."""


def _record_with_progress(recorder: Recorder, duration_s: float, label: str) -> RecordingResult:
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    columns = (TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.fields[seconds]}"),
               TimeElapsedColumn(), TimeRemainingColumn())
    with Progress(*columns, console=err, transient=False) as progress:
        task = progress.add_task(label, total=1.0, seconds=f"0.0 / {duration_s:g} s")

        def update(fraction: float) -> None:
            progress.update(task, completed=fraction, seconds=f"{fraction * duration_s:.1f} / {duration_s:g} s")

        recorder.progress = update
        return recorder.run()


@cli.command()
@click.option("--profile", "profile_name", default=None,
              help="Profile name in configs/profiles/ or a TOML path; none on a bench with [drive] motion = "
                   "\"external\" (acq then records passively what the machine's own controller does).")
@click.option("--bench", "bench_path", type=click.Path(path_type=Path), default=None,
              help="Bench TOML (default: the simulated bench configs/benches/sim.toml).")
@click.option("--duration", "duration_s", type=float, default=None,
              help="Seconds to record (default: the profile's duration_s; needed without a profile).")
@click.option("--joint", default=None, help="Joint name (default: the bench config's).")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("sessions"), show_default=True,
              help="Folder for the session file.")
@click.option("--operator", default="", help="Who is at the bench (stored in the session).")
@click.option("--fast", is_flag=True, help="Simulated parts run as fast as possible instead of in real time.")
@click.option("--no-analyze", is_flag=True, help="Only record; do not identify the joint afterwards.")
@click.option("--live", is_flag=True, help="Watch it in a live window: phase current, speed, position, counters, gaps.")
@tag_option
def record(profile_name: str | None, bench_path: Path | None, duration_s: float | None, joint: str | None,
           out_dir: Path, operator: str, fast: bool, no_analyze: bool, tags: tuple[str, ...],
           live: bool) -> int:
    """Swing the joint on PROFILE, record current and encoder, write one session file.

    On a bench whose machine moves the joint itself ([drive] motion = "external") acq commands no motion: it records
    passively, without --profile, and the identification uses the segments that excite (as acq monitor)."""
    from acq.config import bench_label, check_duration, check_memory, load_bench, resolve_profile_path, with_joint
    from acq.ui.display import summary_table
    from acq.recording.recorder import Recorder
    from acq.recording.reader import load
    from acq.recording.summary import summarize
    from drivers.limits import refuse_beyond_limits
    from drivers.registry import open_bench

    session_tags = parse_tags(tags)  # a bad --tag is one line before anything starts
    bench = with_joint(load_bench(bench_path), joint)
    profile = _profile_for(bench, bench_path, profile_name, duration_s)
    if out_dir.exists() and not out_dir.is_dir():  # before any device starts
        raise ConfigError(f"--out {out_dir}: is a file, not a folder")
    duration = check_duration(duration_s) if duration_s is not None else profile.duration_s  # type: ignore[union-attr]
    if not no_analyze:
        from acq.config import min_record_duration_s
        from analysis import AnalysisRequest

        need_s, parts = min_record_duration_s(bench, AnalysisRequest().segment_s)
        if duration < need_s:  # what the analysis will have after its trims, not the raw length
            given = f"--duration {duration:g}" if duration_s is not None else f"the profile's duration_s = {duration:g}"
            raise ConfigError(f"{given}: the identification needs --duration {need_s:g} s or more ({parts}); record "
                              "longer, or add --no-analyze")
        if profile is not None:  # a passive recording's motion is the machine's: judged by the analysis
            _require_enough_motion(profile, str(profile_name), bench.motor.pole_pairs)
    if profile is not None:
        refuse_beyond_limits(profile, bench, str(resolve_profile_path(profile_name)), bench_label(bench_path))
    check_memory(bench)
    current, drive = open_bench(bench, fast=fast)
    recorder = Recorder(bench, profile, current, drive, out_dir, duration, operator=operator, tags=session_tags)
    if live:
        from acq.ui.live import LiveView, require_display  # Qt is imported only when asked for

        require_display()  # before the devices start: no display → one-line error
    recorder.open_session()  # devices and file ready before any progress is drawn; an error is one line
    label = f"recording {bench.joint}"
    try:
        live_view = LiveView(recorder) if live else None  # scaled by what the started devices report
        result = (live_view.record(lambda: _record_with_progress(recorder, duration, label)) if live_view
                  else _record_with_progress(recorder, duration, label))
    except BaseException as e:  # before the recording ran: finish its file, release the devices
        recorder.abort("interrupted by user (Ctrl-C)" if isinstance(e, KeyboardInterrupt)
                       else f"{type(e).__name__}: {e}")
        raise
    if result.write_failed:  # nothing more is written to that disk: no summary read back, no analysis
        click.echo(f"acq: failed: {result.stop_reason} ({result.current_samples} current and "
                   f"{result.encoder_samples} encoder samples stored in {result.path})", err=True)
        return 1
    out.print(summary_table(summarize(load(result.path))))
    identified = True
    if not no_analyze and result.current_samples and result.encoder_samples:
        if result.status == "interrupted":  # Ctrl-C means stop now: no identification to wait for
            click.echo(f"acq: not identified (interrupted): acq analyze {result.path}", err=True)
        else:
            identified = _analyze_after_recording(result.path)
    if result.status == "complete":
        return 0 if identified else 1
    click.echo(f"acq: {result.status}: {result.stop_reason} — everything recorded up to the stop is kept in "
               f"{result.path} ({result.current_samples} current samples, {result.encoder_samples} encoder samples)",
               err=True)  # one plain line (rich would wrap it)
    return EXIT_INTERRUPTED if result.status == "interrupted" else 1


def _profile_for(bench: Bench, bench_path: Path | None, profile_name: str | None,
                 duration_s: float | None) -> Profile | None:
    """The profile ``acq record`` executes; None on a bench that listens (``[drive] motion = "external"``), where a
    profile is refused in one line (acq must not command motion there) and ``--duration`` is needed instead."""
    from acq.config import load_profile

    if not bench.listens():
        if profile_name is None:
            raise click.UsageError("Missing option '--profile' (only a bench with [drive] motion = \"external\" "
                                   "records without one).")
        return load_profile(profile_name)
    if profile_name is not None:
        raise ConfigError(f"--profile {profile_name}: {bench_path} has [drive] motion = \"external\": the machine's "
                          "own controller moves the joint and acq never commands motion — leave out --profile to "
                          "record passively what the machine does")
    if duration_s is None:
        raise ConfigError(f"{bench_path} has [drive] motion = \"external\": a passive recording has no profile to take "
                          "its length from — give --duration (seconds)")
    return None


def _require_enough_motion(profile: Profile, name: str, pole_pairs: int) -> None:
    """Refuse a profile whose own numbers make the identification certain to fail: the motor must turn half an
    electrical revolution within the torque estimator's window (:func:`analysis.phase_offset.min_speed_rpm`); at most
    the top speed for the whole window, and never more than one half-cycle's swing (a slower drive only moves less).
    A speed-dithered profile is judged by its slowest cycle (``min_speed_factor`` times top speed and swing)."""
    from analysis import PHASE_WINDOW_S, min_speed_rpm
    from drivers.motion import half_swing_rad

    need_rpm, window_ms = min_speed_rpm(pole_pairs), 1e3 * PHASE_WINDOW_S
    slowest = profile.min_speed_factor
    dithered = f" (× {slowest:g} in the slowest cycle, speed_dither = {profile.speed_dither:g})" if profile.speed_dither else ""
    if profile.top_speed_rpm * slowest < need_rpm:
        raise ConfigError(f"profile {name}: top_speed_rpm = {profile.top_speed_rpm:g}{dithered}: the identification needs "
                          f"the motor faster than {need_rpm:.0f} rpm for {window_ms:.0f} ms at a time (half an electrical "
                          f"revolution, {pole_pairs} pole pairs) — raise top_speed_rpm, or add --no-analyze")
    swing_deg, half_turn_deg = math.degrees(half_swing_rad(profile) * slowest), 180.0 / pole_pairs
    if swing_deg < half_turn_deg:
        raise ConfigError(f"profile {name}: the motor swings {swing_deg:.0f}° per half-cycle (top_speed_rpm, "
                          f"accel_time_s, cruise_s, decel_time_s), the identification needs half an electrical revolution "
                          f"({half_turn_deg:.0f}°, {pole_pairs} pole pairs) — lengthen the ramps or raise top_speed_rpm, "
                          "or add --no-analyze")


def _identify(path: Path, request: AnalysisRequest, *, report: bool, catalogue_path: Path | str | None,
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


def _print_result_and_draw(done: SessionResult, default_result: Path | None = None) -> None:
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


def _analyze_after_recording(path: Path) -> bool:
    """Identify the joint of a session just recorded; False when no result could be made (said on stderr): the
    recording stands, the command's exit code says the identification did not run."""
    with err.status("identifying the joint …"):
        try:
            from analysis import AnalysisRequest

            done = _identify(path, AnalysisRequest(), report=True, catalogue_path=None)
        except AcqError as e:
            click.echo(f"acq: analysis: {e}", err=True)
            return False
        except Exception as e:  # noqa: BLE001 - the recording stands whatever the analysis did
            click.echo(f"acq: analysis failed: {type(e).__name__}: {e} (the session is kept: acq analyze {path})",
                       err=True)
            return False
    _print_result_and_draw(done)
    return True


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


@cli.command(name="analyze")
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
@click.option("--result-dir", type=click.Path(path_type=Path), default=None, metavar="DIR",
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


def _result_folder(result_dir: Path) -> Path:
    """``--result-dir``: the folder, made if missing, as an absolute path (the batch's workers are handed it)."""
    if result_dir.exists() and not result_dir.is_dir():
        raise ConfigError(f"--result-dir {result_dir}: is a file, not a folder")
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

        done = _identify(session_path, request, report=report, catalogue_path=catalogue_path, result_dir=result_dir)
        click.echo(json.dumps(done.json_dict, indent=2))
        sys.stdout.flush()  # the numbers reach the reader before the picture is drawn
        # a picture that fails is a note in the .result.json, and a line on stderr (here) or in <session>.report.log
        if wait_report:
            draw_report(done)
        else:
            draw_report_detached(done)
        return 0
    with err.status(f"analysing {session_path} …"):
        done = _identify(session_path, request, report=report, catalogue_path=catalogue_path, result_dir=result_dir)
    from acq.offline.analyze import output_paths
    from analysis import AnalysisRequest

    # a variant as answered: an option that named the default is the session's result (as_default_where_it_is)
    variant = done.request.variant_label()
    default_result = output_paths(session_path, AnalysisRequest(), result_dir)[0] if variant else None
    _print_result_and_draw(done, default_result)
    return 0


@cli.command()
@click.argument("session_path", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def info(session_path: Path, as_json: bool) -> int:
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
    """One line when a session is damaged or still ``recording`` (killed recorder), saying to run acq check."""
    if session.damage:
        return f"{session.path}: damaged ({'; '.join(session.damage)}) — run acq check {session.path}"
    if session.status == "recording":
        return (f"{session.path}: status recording (still being recorded, or the recorder was killed) — "
                f"run acq check {session.path}")
    return None


@cli.command()
@click.argument("session_path", type=click.Path(path_type=Path))
@click.option("--repair", "write_intact", is_flag=True,
              help="Copy the intact part of a damaged session (a cut copy, a chunk that fails its checksum) into a "
                   "new session beside it, NAME.recovered.h5 (status interrupted, the loss in its stop reason; an "
                   "earlier copy is replaced). The damaged file is not written.")
def check(session_path: Path, write_intact: bool) -> int:
    """Verify a session's checksums and committed counts; repair one left by a killed recorder.

    Exit 0 when the session is intact (or was repaired, or --repair copied its intact part), 1 when damage remains
    (each damaged span is listed).
    """
    require_session_file(session_path)
    from acq.ui.display import summary_table
    from acq.recording.reader import load
    from acq.recording.repair import recover, recovered_path, repair
    from acq.recording.summary import summarize

    session = load(session_path)
    if session.status == "recording":
        session = repair(session_path, "recorder stopped without finishing the file (found by acq check)")
        out.print(summary_table(summarize(session)))
        out.print(f"{session_path}: interrupted — the recorder stopped without finishing the file; repaired: "
                  f"status = interrupted, {session.current.sample_count} current and {session.encoder.index.size} "
                  "encoder samples kept")
        return 0
    out.print(summary_table(summarize(session)))
    if session.damage:
        for line in session.damage:
            click.echo(f"{session_path}: {line}")  # plain lines (no wrapping): scripts grep them
        intact = session.current.sample_count > 0 or session.encoder.index.size > 0
        if write_intact and intact:
            copy = recover(session_path)
            click.echo(f"{session_path}: intact part copied into {copy.path}: {copy.current.sample_count} current and "
                       f"{copy.encoder.index.size} encoder samples, status {copy.status}, stop reason: "
                       f"{copy.meta.stop_reason}")
            return 0
        after = [session.kept_after_first_damage(stream) for stream in ("current", "encoder")]
        use = (f" (acq analyze --partial uses it; acq check --repair copies it into {recovered_path(session_path)})"
               if intact else "")
        click.echo(f"acq: damaged: {session_path} ({'; '.join(session.damage)}) — the intact part holds "
                   f"{session.current.sample_count} current and {session.encoder.index.size} encoder samples"
                   + (f", {after[0]} and {after[1]} of them after the first damaged span" if any(after) else "")
                   + use, err=True)
        return 1
    click.echo(f"{session_path}: {session.status}, checksums and counts verified ({session.current.sample_count} "
               f"current, {session.encoder.index.size} encoder samples), nothing to repair")
    return 0


def _exit_now(code: int) -> None:
    """Exit at once after a Ctrl-C: every file and the catalogue were closed on the way out (context managers);
    the interpreter's own teardown of scipy/h5py/Qt and a process pool takes 1–2 s more, which a person who
    pressed Ctrl-C should not wait for. In-process callers (tests) get the usual SystemExit."""
    if threading.current_thread() is not threading.main_thread() or "pytest" in sys.modules:
        sys.exit(code)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _sigterm_as_ctrl_c(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``acq`` console script."""
    in_main = threading.current_thread() is threading.main_thread()
    # SIGTERM stops acq as Ctrl-C does (a batch cancels and tidies up, a recording finishes its file)
    previous = signal.signal(signal.SIGTERM, _sigterm_as_ctrl_c) if in_main else None
    try:
        _run(argv)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


@contextmanager
def _interrupted_outside_the_command() -> Iterator[None]:
    """In the block Ctrl-C and SIGTERM raise :class:`_Interrupted`, except while :meth:`LazyGroup.invoke` runs the
    command (:data:`_command_handlers`: the handlers they had): click writes an empty line before its Abort on a
    KeyboardInterrupt in its own frames (a Ctrl-C as it made the command's context). A signal ignored stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    _command_handlers.clear()
    _command_handlers.update((s, h) for s, h in handlers.items() if h not in (signal.SIG_IGN, None))
    try:
        for s in _command_handlers:
            signal.signal(s, _raise_interrupted)
        yield
    finally:
        for s, h in _command_handlers.items():
            signal.signal(s, h)  # type: ignore[arg-type]
        _command_handlers.clear()  # a group invoked otherwise (click's test runner) leaves the handlers alone


def _os_error(e: OSError) -> AcqError:
    """An :class:`OSError` as acq's one line: a write the storage refused (read-only, full, no permission) is a
    failed write, ``<cause>: <path>`` (:func:`acq.recording.storage.storage_error`), anything else bad input."""
    from acq.recording.storage import WRITE_FAILURES, storage_error

    if e.errno in WRITE_FAILURES and e.filename is not None:
        return storage_error(e, e.filename)
    if e.strerror and e.filename is not None:
        return ConfigError(f"{e.filename}: {e.strerror[0].lower()}{e.strerror[1:]}")
    return ConfigError(str(e))


def _run(argv: list[str] | None) -> None:
    try:
        # numpy's floating-point warnings (the filter of acq.monitoring.session_outcome.quiet_numerics, which an analysis adds;
        # numpy is not loaded here yet)
        with _interrupted_outside_the_command(), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            code = cli.main(args=argv, prog_name="acq", standalone_mode=False)
    except AcqError as e:
        click.echo(f"acq: error: {e}", err=True)
        sys.exit(e.exit_code)
    except click.exceptions.Abort:  # click's name for a KeyboardInterrupt inside a command
        click.echo("acq: interrupted", err=True)
        _exit_now(EXIT_INTERRUPTED)
    except (KeyboardInterrupt, _Interrupted):
        click.echo("acq: interrupted", err=True)
        _exit_now(EXIT_INTERRUPTED)
    except click.UsageError as e:  # one line, like every other error (click's own adds usage and a hint)
        click.echo(f"acq: error: {e.format_message()}", err=True)
        sys.exit(e.exit_code)
    except click.ClickException as e:
        e.show()
        sys.exit(e.exit_code)
    except OSError as e:  # one a command did not name itself: a write the storage refused is a failed write (exit 1)
        error = _os_error(e)
        click.echo(f"acq: error: {error}", err=True)
        sys.exit(error.exit_code)
    if code == EXIT_INTERRUPTED:  # a command that tidied up after a Ctrl-C (a batch, a recording, a monitor)
        _exit_now(code)
    sys.exit(code if isinstance(code, int) else 0)
