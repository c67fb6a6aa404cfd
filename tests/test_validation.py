"""Names and numbers are validated at the edge: one line naming what is wrong, exit 2, nothing written."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import pytest

from acq.config import DEFAULT_BENCH, check_memory, load_bench
from acq.recording.paths import new_session_path
from acqcore.errors import ConfigError
from tests.helpers import record_session_in_subprocess, run_cli
from tests.test_import import _with_row_changed, pair, run_import  # noqa: F401 - the fixture is used below


def _record(capsys: pytest.CaptureFixture[str], out: Path, *extra: str):
    return run_cli(capsys, "record", "--profile", "triangle_0.2s", "--fast", "--no-analyze", "--duration", "0.5",
                   "--out", str(out), *extra)


@pytest.mark.parametrize(("joint", "why"), [
    ("x/../../../escaped", "may hold only letters, digits, '-', '_' and '.' (not '/')"),
    ("a/b", "may hold only letters, digits, '-', '_' and '.' (not '/')"),
    ("../../x", "must not start with a dot"),
    ("/etc/passwd", "may hold only letters, digits, '-', '_' and '.' (not '/')"),
    ("a\tb", "may hold only letters, digits, '-', '_' and '.' (not '\\t')"),
    ("", "must not be empty"),
    (".hidden", "must not start with a dot"),
    ("j" * 65, "must be at most 64 characters"),
    ("a\u200fb", "may hold only letters, digits, '-', '_' and '.' (not '\\u200f')"),  # right-to-left mark
    ("e\u0301", "may hold only letters, digits, '-', '_' and '.' (not '\\u0301')"),  # a combining accent
    ("\u1100\u1161", "must be in Unicode NFC form"),  # Hangul jamo that compose to one syllable
])
def test_hostile_joint_names_are_refused_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                        joint: str, why: str) -> None:
    run = _record(capsys, tmp_path / "out", "--joint", joint)
    assert (run.code, run.err) == (2, f"acq: error: --joint {json.dumps(joint, ensure_ascii=False)}: {why}\n")
    assert not (tmp_path / "out").exists() and sorted(tmp_path.iterdir()) == []


@pytest.mark.parametrize("joint", ["wrist-2.b", "Gelenk_ä1", "関節3"])
def test_safe_joint_names_make_a_session_inside_out(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                    joint: str) -> None:
    run = _record(capsys, tmp_path / "out", "--joint", joint)
    assert run.code == 0, run.err
    (path,) = (tmp_path / "out").iterdir()
    assert path.name.endswith(f"_{joint}.h5") and path.parent == tmp_path / "out"


def test_session_path_never_leaves_out_dir(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"not usable in a file name \(the session must stay in"):
        new_session_path(tmp_path, "../x", "2026-01-01T00:00:00+00:00")


@pytest.mark.parametrize(("value", "shown"), [("nan", "nan"), ("inf", "inf"), ("-1", "-1"), ("0", "0"),
                                              ("1e9", "1e+09")])
def test_absurd_durations_are_refused_before_anything_starts(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                              value: str, shown: str) -> None:
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--fast", "--duration", value,
                  "--out", str(tmp_path / "out"))
    assert (run.code, run.err) == (2, f"acq: error: --duration {shown}: must be a number of seconds in (0, 86400]\n")
    assert not (tmp_path / "out").exists()


def test_usage_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--duration", "abc")
    assert (run.code, run.err) == (2, "acq: error: Invalid value for '--duration': 'abc' is not a valid float.\n")


@pytest.mark.parametrize(("old", "new", "message"), [
    ("rate_hz = 25600", "rate_hz = 1e12", "[daq] rate_hz = 1000000000000.0: must be less than or equal to 10000000"),
    ("daq_drift_ppm = 40.0", "daq_drift_ppm = 1e6",
     "[sim] daq_drift_ppm = 1000000.0: must be less than or equal to 1000"),
    ("period_s = 0.001", "period_s = inf", "[drive] period_s = inf: must be a finite number"),
])
def test_absurd_bench_values_are_refused_naming_file_key_value(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                               old: str, new: str, message: str) -> None:
    text = DEFAULT_BENCH.read_text()
    assert old in text
    bench = tmp_path / "b.toml"
    bench.write_text(text.replace(old, new))
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--fast", "--bench", str(bench),
                  "--out", str(tmp_path / "out"))
    assert (run.code, run.err) == (2, f"acq: error: {bench}: {message}\n")


def test_absurd_profile_speed_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from acq.config import resolve_profile_path
    text = resolve_profile_path("triangle_0.2s").read_text()
    profile = tmp_path / "p.toml"
    profile.write_text("\n".join("top_speed_rpm = 1e9" if ln.startswith("top_speed_rpm") else ln
                                 for ln in text.splitlines()) + "\n")
    run = run_cli(capsys, "record", "--profile", str(profile), "--fast", "--out", str(tmp_path / "out"))
    assert (run.code, run.err) == (2, f"acq: error: {profile}: top_speed_rpm = 1000000000.0: must be less than or "
                                      "equal to 100000\n")


def test_memory_is_checked_before_allocating() -> None:
    bench = load_bench()
    daq = bench.daq.model_copy(update={"rate_hz": 10e6, "channels": ["i_a", "i_b", "i_c"], "block_s": 10.0})
    big = bench.model_copy(update={"daq": daq})
    with pytest.raises(ConfigError) as e:
        check_memory(big, available_bytes=8 * 2**30)
    assert str(e.value) == ("[daq] rate_hz = 1e+07 with 3 channels and block_s = 10 needs 17.9 GiB of memory; "
                            "8.0 GiB available")
    check_memory(bench, available_bytes=8 * 2**30)  # the default bench needs ~1.6 MB


def test_csv_value_beyond_a_physical_bound_is_refused_with_file_line_column(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:  # noqa: F811
    cur, enc = pair
    _with_row_changed(cur, 100, "0.003867188,1e300,1.0")
    r = run_import(capsys, cur, enc, tmp_path / "s.h5")
    assert (r.code, r.err) == (2, f"acq: error: {cur}: line 100, column i_a_A: 1e+300 is beyond the physical bound "
                                  "±10000\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cur.csv", "enc.csv"]


# ------------------------------------------------------------------------------------ malformed session files


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return record_session_in_subprocess(tmp_path_factory.mktemp("rec"), 3.0)


def _spoilt(recorded: Path, tmp_path: Path, spoil) -> Path:
    path = tmp_path / "s.h5"
    shutil.copyfile(recorded, path)
    with h5py.File(path, "r+") as f:
        spoil(f)
    return path


@pytest.mark.parametrize(("spoil", "what"), [
    (lambda f: f.__delitem__("encoder"), "malformed session: /encoder is missing or unreadable"),
    (lambda f: f.__delitem__("current/blocks"), "malformed session: /current/blocks/count is missing or unreadable"),
    (lambda f: f.attrs.__setitem__("bench_json", "{not json"),
     "malformed session: attribute bench_json is not a valid bench (Invalid JSON: key must be a string at line 1 "
     "column 2)"),
    (lambda f: f.attrs.__setitem__("bench_json", '{"joint": "x"}'),
     "malformed session: attribute bench_json is not a valid bench (motor: Field required)"),
    (lambda f: f.attrs.__delitem__("profile_json"), "malformed session: attribute profile_json is missing"),
    (lambda f: f["current"].attrs.__delitem__("rate_hz"),
     "malformed session: /current lacks a valid rate_hz, device or channels attribute"),
    (lambda f: f.attrs.__setitem__("format", "other"), "not an acq session (format attribute is 'other')"),
])
@pytest.mark.parametrize("command", ["info", "check", "analyze"])
def test_malformed_session_is_one_line_naming_file_and_fault(recorded: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str], spoil, what: str,
                                                             command: str) -> None:
    path = _spoilt(recorded, tmp_path, spoil)
    run = run_cli(capsys, command, str(path))
    assert (run.code, run.err) == (2, f"acq: error: {path}: {what}\n")


def test_narrow_band_gives_its_error_without_a_numpy_warning(recorded: Path, capsys: pytest.CaptureFixture[str],
                                                            tmp_path: Path) -> None:
    path = tmp_path / "s.h5"
    shutil.copyfile(recorded, path)
    run = run_cli(capsys, "analyze", str(path), "--band", "200,210", "--no-report")
    assert run.code == 2
    assert run.err.count("\n") == 1 and "Warning" not in run.err and run.err.startswith(f"acq: error: {path}: ")
