"""The ``acq`` command line's group and entry point: the list of commands (each in a module of its own, imported
only when it runs or shows its own --help) and errors for people.

An :class:`~acqcore.errors.AcqError` anywhere becomes one line on stderr and exit code 2 (bad input) or 1 (device,
failed write); a usage error is one line too (exit 2); Ctrl-C is exit 130.
"""

from __future__ import annotations

import difflib
import gc
import importlib
import os
import signal
import sys
import threading
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import click

from acq import __version__
from acq.process_signals import STOP_SIGNALS, StopSignal, deliver_again, handled, repeated_hangup, signal_of
from acqcore.errors import EXIT_INTERRUPTED, AcqError, ConfigError

# numpy, scipy, h5py, pydantic and Qt are imported inside the commands that use them: `acq --help`, a command's
# --help and a mistyped path print at once (1.1 s of imports before; bench/cli_start.py measures it)

#: The commands, each defined in a module of its own: name → (module, attribute, the command's short help). A module
#: is imported only when its command runs or shows its own --help, so the list in `acq --help` carries the short help
#: (tests/test_analyze_cli.py keeps it equal to the command's own).
LAZY_COMMANDS: dict[str, tuple[str, str, str]] = {
    "analyze": ("acq.ui.analyze_cli", "analyze_command",
                "Identify K, J_m, J_l, C of SESSION; write <session>.result.json and <session>.report.png."),
    "check": ("acq.ui.check_cli", "check_command",
              "Verify a session's checksums (every dataset's, the commit table's too) and committed counts; repair "
              "one left by a killed recorder."),
    "devices": ("acq.ui.devices_cli", "devices_command",
                "List NI devices and AI channels, CAN interfaces, serial ports and the simulated bench."),
    "export": ("acq.ui.export_cli", "export_command",
               "Export SESSION to a current CSV, an encoder CSV and the session's metadata (JSON)."),
    "fleet": ("acq.ui.fleet_display", "fleet_command",
              "Every joint (by robot tag): latest K ± 95 %, ΔK to its baseline, sessions of the last day, state "
              "(alarm / stale / no baseline / ok), worst first; exit code 3 if any joint is in alarm."),
    "import": ("acq.ui.import_cli", "import_command",
               "Turn a current file and an encoder CSV recorded by other tools into a session."),
    "info": ("acq.ui.info_cli", "info_command", "Summarise a session: samples, durations, effective rates, gaps."),
    "monitor": ("acq.ui.monitor_cli", "monitor_command",
                "Listen to a running machine window by window, trend K, raise the alarm; exit code 3 if it ends in "
                "alarm."),
    "record": ("acq.ui.record_cli", "record_command",
               "Swing the joint on PROFILE, record current and encoder, write one session file."),
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
    acq says ``acq: interrupted`` in one line. ``signum``: the stop signal that raised it."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _raise_interrupted(signum: int, frame: object) -> None:
    if not repeated_hangup(signum):
        raise _Interrupted(signum)


#: The handlers of Ctrl-C and SIGTERM while a command runs (a KeyboardInterrupt, which a batch or a recording catches to
#: tidy up); around it, in click's own frames, :func:`_raise_interrupted` (:func:`_interrupted_outside_the_command`).
_command_handlers: dict[int, object] = {}


class LazyGroup(click.Group):
    """A group whose commands, :data:`LAZY_COMMANDS`, load on first use (click's documented "lazy loading" pattern)."""

    def invoke(self, ctx: click.Context) -> object:
        outside: dict[int, object] = {}
        try:
            outside.update((s, signal.signal(s, h)) for s, h in _command_handlers.items())  # type: ignore[arg-type]
            return super().invoke(ctx)
        except KeyboardInterrupt as e:
            raise _Interrupted(signal_of(e)) from None
        finally:
            # the command has ended: a Ctrl-C still to be re-delivered would land in the reporting of its outcome
            # (its error line half written, then a traceback and 130 — the review, with a slow stderr)
            _cancel_interrupts_again()
            for s, h in outside.items():
                signal.signal(s, h)  # type: ignore[arg-type]

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(LAZY_COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in LAZY_COMMANDS:
            module, attribute, _ = LAZY_COMMANDS[cmd_name]
            return getattr(importlib.import_module(module), attribute)
        return super().get_command(ctx, cmd_name)

    def resolve_command(self, ctx: click.Context, args: list[str]) -> tuple[str | None, click.Command | None,
                                                                            list[str]]:
        """click's, but a mistyped command names the one meant: "No such command 'analyse'. Did you mean analyze?"
        (click suggests for options only); several near ones are listed, as click lists options."""
        name = args[0] if args else ""
        if name and name not in LAZY_COMMANDS and not name.startswith("-") and not ctx.resilient_parsing:
            near = difflib.get_close_matches(name.lower(), self.list_commands(ctx), n=3)
            if len(near) == 1:
                ctx.fail(f"No such command {name!r}. Did you mean {near[0]}?")
            if near:
                ctx.fail(f"No such command {name!r}. (Possible commands: {', '.join(near)})")
        return super().resolve_command(ctx, args)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list as click writes it, each command's short help taken from :data:`LAZY_COMMANDS`."""
        names = self.list_commands(ctx)
        limit = formatter.width - 6 - max(len(name) for name in names)
        # a command's short help cut as click cuts it, from a stand-in command (no import of its module)
        commands = [click.Command(name, help=LAZY_COMMANDS[name][2]) for name in names]
        rows = [(c.name or "", c.get_short_help_str(limit)) for c in commands]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="acq")
def cli() -> None:
    """Record a robot joint on the bench and identify its stiffness K and inertias J_m, J_l."""


def _exit_now(code: int) -> None:
    """Exit at once after a command, an error or a Ctrl-C: every file and the catalogue were closed on the way out
    (context managers); the interpreter's own teardown of scipy/h5py/Qt and a process pool takes 1–2 s more, which a
    person who pressed Ctrl-C should not wait for — and in which Python has given Ctrl-C and SIGTERM back to the
    system: one then killed acq without a line (exit 130 / 143 in the shell) after its command had done all its work
    (0.8 s after ``acq analyze`` printed ``report:``, load 2), or turned an error's exit 2 into 143. Objects only the
    error's traceback held (a file opened without ``with``) are collected first, as the teardown would have closed
    them. In-process callers (tests) get the usual SystemExit. From here on the stop signals are ignored: a flush
    blocked on a stalled pipe or terminal is ended only by SIGKILL."""
    if threading.current_thread() is not threading.main_thread() or "pytest" in sys.modules:
        sys.exit(code)
    # the command's code is final: a Ctrl-C re-delivered now (:func:`_interrupt_again`) or arriving in the collection
    # and flushes below would replace it (the review: 14 of 15 exits 2 became 130, with a second line)
    _cancel_interrupts_again()
    for s in STOP_SIGNALS:
        if handled(s):
            signal.signal(s, signal.SIG_IGN)
    if code not in (0, EXIT_INTERRUPTED):
        gc.collect()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _stop_as_ctrl_c(signum: int, frame: object) -> None:
    """SIGTERM's and SIGHUP's handler: a KeyboardInterrupt that names its signal (:class:`StopSignal`)."""
    if not repeated_hangup(signum):
        raise StopSignal(signum)


#: Delay of a Ctrl-C delivered again (:func:`_interrupt_again`), s: long enough for the hook to have returned (one
#: raised while the hook still runs is lost again), short beside a person's wait for the line.
INTERRUPT_AGAIN_S = 0.05


def _interrupt_again(unraisable: Any) -> None:
    """``sys.unraisablehook`` while acq runs: a Ctrl-C (SIGTERM, SIGHUP) that Python could not raise where it landed —
    in a weakref callback or a ``__del__`` it printed "Exception ignored in …" with a traceback and the command went
    on as if none had come (1 of 30 ``acq record`` runs, SIGINT during the identification: exit 0) — reaches the main
    thread's handler of the same signal again :data:`INTERRUPT_AGAIN_S` later, from another thread (from here it would
    be raised inside this hook, and lost), to be raised in the command's own code or taken by a recorder's handler
    (with SIGINT's, a SIGTERM stopped a recording as "interrupted by user (Ctrl-C)"); anything else goes to the hook
    there was."""
    if not issubclass(unraisable.exc_type, (KeyboardInterrupt, _Interrupted)):
        _previous_unraisablehook(unraisable)
        return
    again = threading.Timer(INTERRUPT_AGAIN_S, deliver_again, (signal_of(unraisable.exc_value),))
    again.daemon = True
    _interrupts_again.append(again)
    again.start()


#: The Ctrl-Cs :func:`_interrupt_again` is about to deliver: cancelled when the command has its exit code
#: (:func:`_exit_now`) or acq's :func:`main` returns (a command that ended meanwhile did all its work; an in-process
#: caller gets no Ctrl-C of acq's).
_interrupts_again: list[threading.Timer] = []


def _cancel_interrupts_again() -> None:
    for again in _interrupts_again:
        again.cancel()
    _interrupts_again.clear()


_previous_unraisablehook = sys.unraisablehook


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``acq`` console script."""
    global _previous_unraisablehook
    in_main = threading.current_thread() is threading.main_thread()
    # SIGTERM and SIGHUP stop acq as Ctrl-C does (a batch cancels and tidies up, a recording finishes its file and
    # stops the drive); a SIGHUP the process started with ignored (nohup) stays ignored
    previous = {s: signal.signal(s, _stop_as_ctrl_c) for s in STOP_SIGNALS
                if s != signal.SIGINT and handled(s)} if in_main else {}
    if in_main:
        _previous_unraisablehook, sys.unraisablehook = sys.unraisablehook, _interrupt_again
    try:
        _run(argv)
    finally:
        if in_main:
            sys.unraisablehook = _previous_unraisablehook
            _cancel_interrupts_again()
        for s, handler in previous.items():
            signal.signal(s, handler)


@contextmanager
def _interrupted_outside_the_command() -> Iterator[None]:
    """In the block the stop signals (Ctrl-C, SIGTERM, SIGHUP) raise :class:`_Interrupted`, except while
    :meth:`LazyGroup.invoke` runs the command (:data:`_command_handlers`: the handlers they had): click writes an
    empty line before its Abort on a KeyboardInterrupt in its own frames (a Ctrl-C as it made the command's context).
    A signal ignored stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handlers = {s: signal.getsignal(s) for s in STOP_SIGNALS}
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
    """Run the command line; leave through :func:`_exit_now` with its exit code, after its line on stderr if it
    ended in an error or a Ctrl-C (the exception and its traceback let go of first)."""
    _exit_now(_command_code(argv))


def _command_code(argv: list[str] | None) -> int:
    """The command line's exit code: the command's own, or that of its error or Ctrl-C, whose one line is written
    here."""
    try:
        # numpy's floating-point warnings (the filter of acq.monitoring.session_outcome.quiet_numerics, which an analysis adds;
        # numpy is not loaded here yet)
        with _interrupted_outside_the_command(), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            code = cli.main(args=argv, prog_name="acq", standalone_mode=False)
    except AcqError as e:
        click.echo(f"acq: error: {e}", err=True)
        return e.exit_code
    except (click.exceptions.Abort, KeyboardInterrupt, _Interrupted):  # Abort: click's name for a KeyboardInterrupt
        click.echo("acq: interrupted", err=True)
        return EXIT_INTERRUPTED
    except click.UsageError as e:  # one line, like every other error (click's own adds usage and a hint)
        click.echo(f"acq: error: {e.format_message()}", err=True)
        return e.exit_code
    except click.ClickException as e:
        e.show()
        return e.exit_code
    except OSError as e:  # one a command did not name itself: a write the storage refused is a failed write (exit 1)
        error = _os_error(e)
        click.echo(f"acq: error: {error}", err=True)
        return error.exit_code
    # a command that ran to its end, or tidied up after a Ctrl-C (a batch, a recording, a monitor)
    return code if isinstance(code, int) else 0
