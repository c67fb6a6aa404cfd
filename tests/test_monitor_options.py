"""acq monitor's numeric options: nan, inf, negative and zero refused in one line naming the option (exit 2)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from acq.monitoring.retention import parse_size
from acq.ui.monitor_cli import parse_duration
from acqcore.errors import ConfigError
from tests.helpers import run_cli

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"


@pytest.mark.parametrize(("option", "value", "error"), [
    # --window nan ended in a traceback (ValueError: cannot convert float NaN to integer), --window inf in
    # "--every 60: must be at least --window inf s", --threshold-pct nan ran a monitor that never alarms (the trial)
    ("--window", "nan", "Invalid value for '--window': nan is not a finite number."),
    ("--window", "inf", "Invalid value for '--window': inf is not a finite number."),
    ("--window", "-3", "Invalid value for '--window': -3.0 is not in the range x>=1.0."),
    ("--window", "0", "Invalid value for '--window': 0.0 is not in the range x>=1.0."),
    ("--threshold-pct", "nan", "Invalid value for '--threshold-pct': nan is not a finite number."),
    ("--threshold-pct", "-inf", "Invalid value for '--threshold-pct': -inf is not in the range 0<x<=100."),
    ("--every", "nan", "--every nan: not a duration — seconds, or numbers with s, min (m), h or d, summed: "
     "600, 90s, 10min, 1.5h, 2h10min, 2h 10min"),
    ("--every", "inf", "--every inf: not a duration — seconds, or numbers with s, min (m), h or d, summed: "
     "600, 90s, 10min, 1.5h, 2h10min, 2h 10min"),
    ("--every", "0", "--every 0: not a duration — seconds, or numbers with s, min (m), h or d, summed: "
     "600, 90s, 10min, 1.5h, 2h10min, 2h 10min"),
    ("--for", "2h10", "--for 2h10: not a duration — seconds, or numbers with s, min (m), h or d, summed: "
     "600, 90s, 10min, 1.5h, 2h10min, 2h 10min"),
    ("--for", "-1", "--for -1: not a duration — seconds, or numbers with s, min (m), h or d, summed: "
     "600, 90s, 10min, 1.5h, 2h10min, 2h 10min"),
    # a line break between parts was taken as their space and, refused, split the message over two lines (reviewer)
    ("--for", "2h\n10min", "--for 2h\\n10min: not a duration — seconds, or numbers with s, min (m), h or d, summed: "
     "600, 90s, 10min, 1.5h, 2h10min, 2h 10min"),
    ("--max-disk", "nanMB", "--max-disk nanMB: 'nanMB' is not a size (e.g. 2GB, 500MB)"),
    ("--max-disk", "infGB", "--max-disk infGB: 'infGB' is not a size (e.g. 2GB, 500MB)"),
    ("--max-disk", "-5MB", "--max-disk -5MB: '-5MB' is not a size (e.g. 2GB, 500MB)"),
    ("--max-disk", "0MB", "--max-disk 0MB: '0MB' is not a size (e.g. 2GB, 500MB)"),
    ("--keep", "nan", "Invalid value for '--keep': 'nan' is not a valid integer range."),
    ("--keep", "-1", "Invalid value for '--keep': -1 is not in the range x>=0."),
    ("--jobs", "inf", "Invalid value for '--jobs': 'inf' is not a valid integer range."),
    ("--jobs", "0", "Invalid value for '--jobs': 0 is not in the range x>=1."),
    ("--baseline-windows", "nan", "Invalid value for '--baseline-windows': 'nan' is not a valid integer range."),
    ("--baseline-windows", "0", "Invalid value for '--baseline-windows': 0 is not in the range x>=1."),
])
def test_a_numeric_option_out_of_range_is_one_line_naming_it(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                             option: str, value: str, error: str) -> None:
    out = tmp_path / "m"
    run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--fast", "--for", "1m", option, value, "--out", str(out))
    assert (run.code, run.err) == (2, f"acq: error: {error}\n")
    assert not out.exists()


@pytest.mark.parametrize("command", ["trend", "fleet"])
def test_the_alarm_rules_of_trend_and_fleet_refuse_nan_too(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                           command: str) -> None:
    run = run_cli(capsys, command, "--catalogue", str(tmp_path / "c.sqlite"), "--ewma-lambda", "nan")
    assert (run.code, run.err) == (2, "acq: error: Invalid value for '--ewma-lambda': nan is not a finite number.\n")


@pytest.mark.parametrize(("text", "seconds"), [
    ("600", 600.0), ("90s", 90.0), ("10min", 600.0), ("10m", 600.0), ("1.5h", 5400.0), ("1d", 86400.0),
    ("2h10min", 7800.0), ("2h 10min", 7800.0), (" 2H10MIN ", 7800.0), ("1h30m15s", 5415.0), (".5h", 1800.0)])
def test_a_duration_takes_units_and_summed_parts(text: str, seconds: float) -> None:
    """`acq monitor --for 2h10min` was refused ("not a duration"): a compound duration is the parts summed."""
    assert parse_duration("--for", text) == seconds


@pytest.mark.parametrize("text", ["2h 2h", "10m 5min", "1h,10min", "2h10", "h", "1e3", "0s"])
def test_a_duration_with_a_unit_twice_or_a_bare_part_is_refused(text: str) -> None:
    with pytest.raises(ConfigError, match=f"^--for {text}: not a duration — "):
        parse_duration("--for", text)


def test_a_size_of_nan_or_inf_is_not_a_size() -> None:
    for text in ("nanMB", "infGB", "-infB"):
        with pytest.raises(ValueError, match=f"'{text}' is not a size"):
            parse_size(text)


def _parses(command: object, args: list[str]) -> None:
    """``args`` parse with the real click ``command`` (an option it has not raises click's NoSuchOption)."""
    import click

    assert isinstance(command, click.Command)
    command.make_context(command.name or "", args, resilient_parsing=False)


def test_every_command_the_monitor_advises_exists(tmp_path: Path) -> None:
    """The trial: the summary advised "re-baseline with --baseline on a session", the restart refusal "resume with the
    same … --ewma-lambda 0.2": acq monitor had neither option. Each advice, parsed by the command it names."""
    from acq.monitoring.alarm_rules import AlarmRules
    from acq.monitoring.monitor_restart import check_comparable
    from acq.monitoring.trend import REBASELINE
    from acq.ui.monitor_cli import monitor_command
    from acq.ui.trend_cli import trend_command
    from tests.test_monitor import _bench

    assert REBASELINE == ("re-baseline: acq trend --baseline SESSION_ID judges against a session of the joint in a "
                          "known state; a monitor learns a new baseline in a new --out")
    _parses(trend_command, ["--joint", "joint1", "--baseline", "abc123"])
    _parses(monitor_command, ["--bench", str(ROBOT), "--out", str(tmp_path / "new")])

    from acq.monitoring.catalogue import Entry
    filed = AlarmRules(5, 10.0, 0.3)
    entry = Entry("k", "s", "p", "joint1", None, {**filed.as_tags(), "monitor_window": 0}, "ok", [], None, 890.0,
                  (880.0, 900.0), 55.0, 95.0, "r", "", None)
    with pytest.raises(ConfigError) as refusal:
        check_comparable(tmp_path, [entry], _bench(), 10.0, AlarmRules(5, 10.0, 0.2))
    assert str(refusal.value) == (f"{tmp_path}: its windows were judged with --baseline-windows 5 --threshold-pct 10 "
                                  "--ewma-lambda 0.3: resume with the same, or start a new --out")
    _parses(monitor_command, ["--bench", str(ROBOT), "--baseline-windows", "5", "--threshold-pct", "10",
                              "--ewma-lambda", "0.3"])


@pytest.mark.parametrize(("options", "message"), [
    # a 27.8 h window was started although --for said 1 min and docs/monitoring.md limits a window to 24 h
    # (the trial)
    (("--window", "100000", "--every", "100000", "--for", "1min"),
     "acq: error: --window 100000: must be a number of seconds in (0, 86400]\n"),
    # a whole 30 s window was recorded for --for 10s
    (("--window", "30", "--for", "10s"), "acq: error: --for 10: must be at least --window 30 s (the run records "
                                         "whole windows)\n"),
])
def test_a_window_longer_than_the_run_or_a_day_is_refused_before_anything_is_recorded(
        tmp_path: Path, options: tuple[str, ...], message: str) -> None:
    out = tmp_path / "m5"
    run = subprocess.run([sys.executable, "-m", "acq", "monitor", "--bench", str(ROBOT), *options, "--fast",
                          "--out", str(out)], capture_output=True, text=True, timeout=60)
    assert (run.returncode, run.stderr, run.stdout) == (2, message, "")
    assert not out.exists()
