"""``acq record``: swing the joint on a profile (or listen to a machine that moves it), record current and encoder
into one session file with a progress bar (and the live window if asked), then identify the joint
(:mod:`acq.ui.analyze_cli`).
"""

from __future__ import annotations

import math
import signal
from pathlib import Path
from typing import TYPE_CHECKING

import click
from rich.console import Console

from acq.process_signals import signal_of, signals_deferred, stop_reason
from acq.recording.tags import parse_tags, require_plain_text
from acq.ui.analyze_cli import identify, print_result_and_draw
from acq.ui.options import Folder, tag_option
from acqcore.errors import EXIT_INTERRUPTED, AcqError, ConfigError

if TYPE_CHECKING:
    from acq.recording.recorder import Recorder, RecordingResult
    from drivers.config import Bench
    from drivers.profile import Profile

out = Console()
err = Console(stderr=True)


@click.command(name="record")
@click.option("--profile", "profile_name", default=None,
              help="Profile name in configs/profiles/ or a TOML path; none on a bench with [drive] motion = "
                   "\"external\" (acq then records passively what the machine's own controller does).")
@click.option("--bench", "bench_path", type=click.Path(path_type=Path), default=None,
              help="Bench TOML (default: the simulated bench configs/benches/sim.toml).")
@click.option("--duration", "duration_s", type=float, default=None,
              help="Seconds to record (default: the profile's duration_s; needed without a profile).")
@click.option("--joint", default=None, help="Joint name (default: the bench config's).")
@click.option("--out", "out_dir", type=Folder(), default=Path("sessions"), show_default=True,
              help="Folder for the session file.")
@click.option("--operator", default="", help="Who is at the bench (stored in the session).")
@click.option("--fast", is_flag=True, help="Simulated parts run as fast as possible instead of in real time (the recording on one CPU).")
@click.option("--no-analyze", is_flag=True, help="Only record; do not identify the joint afterwards.")
@click.option("--live", is_flag=True, help="Watch it in a live window: phase current, speed, position, counters, gaps.")
@tag_option
def record_command(profile_name: str | None, bench_path: Path | None, duration_s: float | None, joint: str | None,
           out_dir: Path, operator: str, fast: bool, no_analyze: bool, tags: tuple[str, ...],
           live: bool) -> int:
    """Swing the joint on PROFILE, record current and encoder, write one session file.

    On a bench whose machine moves the joint itself ([drive] motion = "external") acq commands no motion: it records
    passively, without --profile, and the identification uses the segments that excite (as acq monitor)."""
    from acq.config import bench_label, check_duration, check_memory, load_bench, resolve_profile_path, with_joint
    from acq.recording.recorder import Recorder
    from acq.recording.room import require_room
    from drivers.limits import refuse_beyond_limits
    from drivers.registry import open_bench

    require_plain_text("--operator", operator)  # one line before anything starts, as a bad --tag
    session_tags = parse_tags(tags)
    bench = with_joint(load_bench(bench_path), joint)
    profile = _profile_for(bench, bench_path, profile_name, duration_s)
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
    require_room(out_dir, bench, duration)  # before the devices start, not a progress bar run to its end for nothing
    current, drive = open_bench(bench, fast=fast)
    recorder = Recorder(bench, profile, current, drive, out_dir, duration, operator=operator, tags=session_tags,
                        one_cpu=fast)
    if live:
        with signals_deferred():  # a Ctrl-C inside Qt's import: a fatal error of shiboken's start-up, or lost
            from acq.ui.live import LiveView, require_display  # Qt is imported only when asked for

        require_display()  # before the devices start: no display → one-line error
    session = recorder.open_session()  # devices and file ready before any progress is drawn; an error is one line
    label = f"recording {bench.joint}"
    try:
        live_view = LiveView(recorder) if live else None  # scaled by what the started devices report
        result = (live_view.record(lambda: _record_with_progress(recorder, duration, label)) if live_view
                  else _record_with_progress(recorder, duration, label))
    except BaseException as e:  # before the recording ran: finish its file, release the devices
        recorder.abort(stop_reason(e) if isinstance(e, KeyboardInterrupt) else f"{type(e).__name__}: {e}")
        if not isinstance(e, KeyboardInterrupt):
            raise
        # one line naming the file, as for a Ctrl-C while recording (it was "acq: interrupted")
        click.echo(f"acq: interrupted twice: stopped before {session.path} was finished — acq check {session.path} "
                   "repairs it" if recorder.stop_request is not None else
                   f"acq: {_stopped(e)} before the recording started — nothing recorded ({session.path}: no samples, "
                   "status interrupted)", err=True)
        return EXIT_INTERRUPTED
    try:
        return _after_recording(result, analyze=not no_analyze)
    except KeyboardInterrupt as e:  # a Ctrl-C once the recorder had let go of its signals: the file is finished
        click.echo(_interrupted_after_recording(result, e, analyze=not no_analyze), err=True)
        return EXIT_INTERRUPTED


def _after_recording(result: RecordingResult, *, analyze: bool) -> int:
    """The summary of the session ``result`` wrote, its identification (``analyze``) and the one line of a recording
    that did not complete; the command's exit code."""
    from acq.ui.display import summary_table
    from acq.recording.reader import load
    from acq.recording.summary import summarize

    if result.write_failed:  # nothing more is written to that disk: no summary read back, no analysis
        stored = (f" ({result.current_samples} current and {result.encoder_samples} encoder samples stored in "
                  f"{result.path})" if result.path.exists() else "")  # not of a file deleted with its folder
        click.echo(f"acq: failed: {result.stop_reason}{stored}", err=True)
        return 1
    try:
        summary = summarize(load(result.path))
    except AcqError:
        if result.path.exists():
            raise
        click.echo(f"acq: failed: {result.path}: the session file is gone (it or its folder was deleted after the "
                   "recording) — nothing kept", err=True)  # not "not a readable HDF5 session file", exit 2
        return 1
    out.print(summary_table(summary))
    can_identify = analyze and bool(result.current_samples and result.encoder_samples)
    if result.status == "interrupted":  # Ctrl-C means stop now: no identification to wait for, and one line
        identify_later = f"; not identified: acq analyze {result.path}" if can_identify else ""
        click.echo(f"acq: interrupted: {result.stop_reason} — {_kept(result)}{identify_later}", err=True)
        return EXIT_INTERRUPTED
    identified = _analyze_after_recording(result.path) if can_identify else True
    if result.status == "complete":
        return 0 if identified else 1
    click.echo(f"acq: {result.status}: {result.stop_reason} — {_kept(result)}", err=True)  # plain: rich would wrap it
    return 1


def _kept(result: RecordingResult) -> str:
    return (f"everything recorded up to the stop is kept in {result.path} ({result.current_samples} current samples, "
            f"{result.encoder_samples} encoder samples)")


def _stopped(e: BaseException) -> str:
    """What stopped acq, as its line says it: "interrupted" (Ctrl-C), else the signal's stop reason ("stopped by
    SIGTERM")."""
    return "interrupted" if signal_of(e) == signal.SIGINT else stop_reason(e)


def _interrupted_after_recording(result: RecordingResult, e: BaseException, *, analyze: bool) -> str:
    """The one line of a Ctrl-C (``e``: its KeyboardInterrupt) after the recorder finished the file (during its
    summary, identification or report): what the file holds and, with ``analyze``, how far the identification got
    (read from the disk)."""
    from acq.offline.analyze import output_paths
    from analysis import AnalysisRequest

    if result.status == "complete":
        line = (f"acq: {_stopped(e)} after the recording — {result.path} is complete ({result.current_samples} "
                f"current samples, {result.encoder_samples} encoder samples)")
    else:
        line = f"acq: interrupted: {result.stop_reason} — {_kept(result)}"
    if not analyze or not (result.current_samples and result.encoder_samples):
        return line
    json_path, report_path = output_paths(result.path, AnalysisRequest())
    if not json_path.exists():
        return f"{line}; not identified: acq analyze {result.path}"
    return f"{line}; identified: {json_path}" + ("" if report_path.exists() else " (report not drawn)")


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


def _analyze_after_recording(path: Path) -> bool:
    """Identify the joint of a session just recorded; False when no result could be made (said on stderr): the
    recording stands, the command's exit code says the identification did not run."""
    with err.status("identifying the joint …"):
        try:
            from analysis import AnalysisRequest

            done = identify(path, AnalysisRequest(), report=True, catalogue_path=None)
        except AcqError as e:
            click.echo(f"acq: analysis: {e}", err=True)
            return False
        except Exception as e:  # noqa: BLE001 - the recording stands whatever the analysis did
            click.echo(f"acq: analysis failed: {type(e).__name__}: {e} (the session is kept: acq analyze {path})",
                       err=True)
            return False
    print_result_and_draw(done)
    return True
