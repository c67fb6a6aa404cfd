"""acq import / acq export: CSV and TDMS files from other tools become sessions that analyse like ours."""

from __future__ import annotations

import errno
import hashlib
import json
import threading
import time
from dataclasses import fields
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import pytest
from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

from acq.config import DEFAULT_BENCH
from acq.monitoring.catalogue import Catalogue
from acq.offline.analyze import analyze_session
from acq.offline.export_metadata import read_metadata
from acq.recording.reader import load
from acq.recording.session import SessionHistory
from tests.helpers import run_cli

RATE_HZ = 25600.0
PERIOD_S = 0.001
EXPECTED_COLUMNS = "expected t_s, i_a_A, i_b_A, i_c_A"


def write_csv(path: Path, header: str, columns: list[np.ndarray], fmt: list[str]) -> Path:
    rows = zip(*(c.tolist() for c in columns))
    path.write_text(header + "\n" + "".join(",".join(f % v for f, v in zip(fmt, r)) + "\n" for r in rows))
    return path


def current_columns(duration_s: float = 2.5, rate_hz: float = RATE_HZ, t0_s: float = 0.0) -> list[np.ndarray]:
    t = t0_s + np.arange(int(round(duration_s * rate_hz)) + 1) / rate_hz
    return [t, 3.0 * np.sin(2 * np.pi * 50.0 * t), 3.0 * np.sin(2 * np.pi * 50.0 * t - 2 * np.pi / 3)]


def encoder_columns(duration_s: float = 2.5, start_counts: int = 0) -> list[np.ndarray]:
    k = np.arange(int(round(duration_s / PERIOD_S)) + 1)
    jitter = np.random.default_rng(1).uniform(0.0, 2e-4, k.size)
    return [k * PERIOD_S + 1e-3 + jitter, start_counts + 500 * k, k]


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Path, Path]:
    cur = write_csv(tmp_path / "cur.csv", "t_s,i_a_A,i_b_A", current_columns(), ["%.9f", "%r", "%r"])
    enc = write_csv(tmp_path / "enc.csv", "t_s,position_counts,index", encoder_columns(), ["%.9f", "%d", "%d"])
    return cur, enc


def run_import(capsys: pytest.CaptureFixture[str], cur: Path, enc: Path, out: Path, *extra: str):
    return run_cli(capsys, "import", "--current", str(cur), "--encoder", str(enc), "--bench", str(DEFAULT_BENCH),
                   "--profile", "triangle_0.2s", "-o", str(out), *extra)


def test_csv_pair_becomes_a_complete_session_with_rate_indices_host_stamps_and_origin(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    cur, enc = pair
    r = run_import(capsys, cur, enc, tmp_path / "s.h5", "--joint", "wrist")
    assert r.code == 0, r.err
    s = load(tmp_path / "s.h5")
    assert s.status == "complete" and s.attrs["joint"] == "wrist"
    assert s.current.rate_hz == pytest.approx(RATE_HZ, rel=1e-9)
    t, i_a, i_b = current_columns()
    np.testing.assert_array_equal(s.current.phases_a["i_a"], i_a)
    np.testing.assert_array_equal(s.current.phases_a["i_b"], i_b)
    np.testing.assert_array_equal(s.current.sample_index(), np.arange(t.size))
    last = s.current.block_first_index + s.current.block_count - 1
    np.testing.assert_allclose(s.current.block_host_ns * 1e-9, t[last], atol=1e-9)
    t_enc, counts, k = encoder_columns()
    np.testing.assert_array_equal(s.encoder.host_ns, np.rint(t_enc * 1e9).astype(np.int64))
    np.testing.assert_array_equal(s.encoder.position_counts, counts)
    np.testing.assert_array_equal(s.encoder.index, k)
    assert s.encoder.period_s == PERIOD_S and s.encoder.transport == "imported"
    origin = json.loads(s.attrs["origin_json"])
    assert origin["kind"] == "imported" and origin["host_timeline"].startswith("separate: the files come from separate "
                                                                               "tools")
    assert s.attrs["host_clock_shared"] is False and origin["started_from"] == "the time of import"
    assert [(f["role"], f["name"], f["sha256"]) for f in origin["files"]] == [
        ("current", "cur.csv", hashlib.sha256(cur.read_bytes()).hexdigest()),
        ("encoder", "enc.csv", hashlib.sha256(enc.read_bytes()).hexdigest())]
    assert s.events == []


def test_encoder_int32_wrap_is_unwrapped_and_index_gaps_become_events(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    cur, _ = pair
    t, counts, k = encoder_columns(start_counts=2**31 - 300_000)
    keep = np.ones(k.size, dtype=bool)
    keep[[1000, 1001, 1002, 2000]] = False  # 3 cycles lost, then 1
    wrapped = (counts + 2**31) % 2**32 - 2**31
    enc = write_csv(tmp_path / "enc.csv", "t_s,position_counts,index",
                    [t[keep], wrapped[keep], k[keep]], ["%.9f", "%d", "%d"])
    assert wrapped.min() < 0 < wrapped.max()
    assert run_import(capsys, cur, enc, tmp_path / "s.h5").code == 0
    s = load(tmp_path / "s.h5")
    np.testing.assert_array_equal(s.encoder.position_counts, counts[keep])
    assert [(e.stream, e.kind, e.detail) for e in s.events] == [
        ("encoder", "gap", "3 drive cycles missing before index 1003"),
        ("encoder", "gap", "1 drive cycles missing before index 2001")]


def test_files_on_separate_clocks_start_together_and_the_origin_says_so(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    _, enc = pair
    cur = write_csv(tmp_path / "cur.csv", "t_s,i_a_A", current_columns(t0_s=5000.0)[:2], ["%.9f", "%r"])
    assert run_import(capsys, cur, enc, tmp_path / "s.h5").code == 0
    s = load(tmp_path / "s.h5")
    assert json.loads(s.attrs["origin_json"])["host_timeline"].startswith("separate: the files' time columns do not "
                                                                          "overlap; the current was shifted by -4999.99")
    first_block_end_s = s.current.block_host_ns[0] * 1e-9
    assert first_block_end_s == pytest.approx(encoder_columns()[0][0] + 2559 / RATE_HZ, abs=1e-9)


def _with_row_changed(path: Path, line: int, text: str) -> Path:
    lines = path.read_text().splitlines()
    lines[line - 1] = text
    path.write_text("\n".join(lines) + "\n")
    return path


BAD_CURRENT = [
    pytest.param(lambda p: p.write_bytes(b""), "the file is empty (expected a header line t_s, i_a_A, i_b_A, i_c_A, "
                 "then data rows)", id="empty-file"),  # said "line 1, column (empty): unknown column (…)"
    pytest.param(lambda p: p.write_text("\n \r\n\n"), "the file is empty (expected a header line t_s, i_a_A, i_b_A, "
                 "i_c_A, then data rows)", id="blank-lines-only"),
    pytest.param(lambda p: p.write_text("\n" + p.read_text()), "line 1: empty, the header must be the first line "
                 f"({EXPECTED_COLUMNS})", id="header-not-on-line-1"),
    pytest.param(lambda p: p.write_text(p.read_text().replace("t_s,i_a_A,i_b_A", "i_a_A,i_b_A", 1)),
                 "line 1, column t_s: missing (the header is 'i_a_A,i_b_A')", id="missing-header"),
    pytest.param(lambda p: p.write_text(p.read_text().replace("t_s,i_a_A,i_b_A", "t_s,i_a_a,i_b_A", 1)),
                 f"line 1, column i_a_a: unknown column (did you mean i_a_A? {EXPECTED_COLUMNS})",
                 id="misspelt-header"),
    pytest.param(lambda p: p.write_text(p.read_text().replace(",", ";")),
                 "line 1, column t_s;i_a_A;i_b_A: unknown column (the columns are separated by ';'; acq reads "
                 f"comma-separated files: {EXPECTED_COLUMNS})", id="semicolons"),
    pytest.param(lambda p: p.write_text(p.read_text().replace(",", ";").replace(".", ",")),
                 "line 1, column t_s;i_a_A;i_b_A: unknown column (the columns are separated by ';' and the numbers have "
                 "decimal commas (line 2: '0,000000000'); acq reads comma-separated files with '.' decimals: "
                 f"{EXPECTED_COLUMNS})", id="semicolons-decimal-commas"),
    pytest.param(lambda p: p.write_text(p.read_text().replace(".", ",")),
                 "line 2 has 6 fields for 3 columns — decimal commas? (0,000000000,0,0,-2,598076211353316): write the "
                 "file with '.' decimals (acq reads ',' between columns and '.' as the decimal point)",
                 id="decimal-commas"),
    pytest.param(lambda p: p.write_text(p.read_text().replace("\n", ",1.0\n").replace("i_b_A,1.0", "i_b_A")),
                 "line 2: 4 fields, the header has 3", id="every-row-wider-than-the-header"),
    pytest.param(lambda p: _with_row_changed(p, 57, "0.002187500,abc,1.0"),
                 "line 57, column i_a_A: 'abc' is not a number", id="non-numeric"),
    pytest.param(lambda p: _with_row_changed(p, 100, "0.003867188,0.5,"),
                 "line 100, column i_b_A: empty cell", id="empty-cell"),
    pytest.param(lambda p: _with_row_changed(p, 100, "0.003867188,nan,1.0"),
                 "line 100, column i_a_A: NaN", id="nan"),
    pytest.param(lambda p: _with_row_changed(p, 11, "0.000300000,0.5,1.0"),
                 "line 11, column t_s: 0.0003 does not increase (previous row: 0.0003125)", id="non-monotonic"),
    pytest.param(lambda p: write_csv(p, "t_s,i_a_A,i_b_A", current_columns(1.5), ["%.9f", "%r", "%r"]),
                 "line 38402, column t_s: only 1.500 s of data (at least 2 s needed)", id="too-short"),
    pytest.param(lambda p: write_csv(p, "t_s,i_a_A,i_b_A", current_columns(rate_hz=25000.0), ["%.9f", "%r", "%r"]),
                 "lines 2–62502, column t_s: sample rate 25000 Hz disagrees with the bench's [daq] rate_hz = 25600 by "
                 "2.34 % (more than 1 %)", id="rate"),
]


@pytest.mark.parametrize(("spoil", "message"), BAD_CURRENT)
def test_bad_current_csv_is_one_line_naming_file_line_and_column_exit_2_and_no_session(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path], spoil, message: str) -> None:
    cur, enc = pair
    spoil(cur)
    r = run_import(capsys, cur, enc, tmp_path / "s.h5")
    assert (r.code, r.err) == (2, f"acq: error: {cur}: {message}\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cur.csv", "enc.csv"]


BAD_ENCODER = [
    pytest.param(lambda p: p.write_bytes(b""), "the file is empty (expected a header line t_s, position_counts, index, "
                 "drive_time_s, then data rows)", id="empty-file"),
    pytest.param(lambda p: p.write_text(p.read_text().replace("position_counts", "position", 1)),
                 "line 1, column position: unknown column (did you mean position_counts? expected t_s, "
                 "position_counts, index, drive_time_s)", id="misspelt-header"),
    pytest.param(lambda p: _with_row_changed(p, 1000, "0.300000000,499000,998"),
                 "line 1000, column t_s: 0.3 does not increase (previous row: 0.998003753)", id="non-monotonic-t"),
    pytest.param(lambda p: _with_row_changed(p, 30, "0.029100000,1000.5,28"),
                 "line 30, column position_counts: 1000.5 is not an integer", id="fractional-counts"),
    pytest.param(lambda p: _with_row_changed(p, 30, "0.029100000,3000000000,28"),
                 "line 30, column position_counts: jumps from 13500 to 3000000000, more than half the 32-bit register "
                 "range, and is not a wrap", id="jump"),
    pytest.param(lambda p: _with_row_changed(p, 30, "0.029100000,inf,28"),
                 "line 30, column position_counts: inf is not finite", id="infinite"),
    pytest.param(lambda p: _with_row_changed(p, 30, "0.029100000,14000,27"),
                 "line 30, column index: 27 does not increase (previous row: 27)", id="index-repeated"),
    pytest.param(lambda p: write_csv(p, "t_s,position_counts,index", encoder_columns(1.899), ["%.9f", "%d", "%d"]),
                 "line 1901, column t_s: only 1.900 s of data (at least 2 s needed)", id="too-short"),
    pytest.param(lambda p: p.write_text("t_s,position_counts,index\n" + "".join(
        f"{t:.3f},{c}\n".replace(".", ",") for t, c in zip(*encoder_columns()[:2]))),
                 "line 2: '0,001' looks like a number with a decimal comma — write the file with '.' decimals (acq "
                 "reads ',' between columns and '.' as the decimal point)", id="decimal-commas-as-many-fields"),
]


@pytest.mark.parametrize(("spoil", "message"), BAD_ENCODER)
def test_bad_encoder_csv_is_one_line_naming_file_line_and_column_exit_2_and_no_session(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path], spoil, message: str) -> None:
    cur, enc = pair
    spoil(enc)
    r = run_import(capsys, cur, enc, tmp_path / "s.h5")
    assert (r.code, r.err) == (2, f"acq: error: {enc}: {message}\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cur.csv", "enc.csv"]


# ------------------------------------------------------------------------------------ TDMS


def write_tdms(path: Path, columns: list[np.ndarray], segments: int = 5, rate_hz: float = RATE_HZ) -> Path:
    props = {"wf_increment": 1.0 / rate_hz, "wf_start_offset": 0.0}
    with TdmsWriter(path) as w:
        for part in zip(*(np.array_split(c, segments) for c in columns)):
            w.write_segment([RootObject(), GroupObject("DAQ"),
                             *(ChannelObject("DAQ", f"ai{i}", data, properties=props) for i, data in enumerate(part))])
    return path


def test_tdms_round_trip_picks_channels_in_phase_order_and_takes_rate_from_wf_increment(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    _, enc = pair
    _, i_a, i_b = current_columns()
    cur = write_tdms(tmp_path / "cur.tdms", [i_b, i_a])
    r = run_import(capsys, cur, enc, tmp_path / "s.h5", "--current-channel", "DAQ/ai1", "--current-channel", "DAQ/ai0")
    assert r.code == 0, r.err
    s = load(tmp_path / "s.h5")
    assert s.current.rate_hz == RATE_HZ
    np.testing.assert_array_equal(s.current.phases_a["i_a"], i_a)
    np.testing.assert_array_equal(s.current.phases_a["i_b"], i_b)
    assert json.loads(s.attrs["origin_json"])["files"][0]["channels"] == ["DAQ/ai1", "DAQ/ai0"]


def _cut_in_last_line(path: Path, keep: int) -> str:
    """Cut ``path`` ``keep`` characters into its last line (after the first comma), as a copy stopped there; return
    the line as it was."""
    *lines, last, _ = path.read_text().split("\n")
    path.write_text("\n".join(lines) + "\n" + last[:last.index(",") + keep])
    return last


def test_a_csv_cut_in_its_last_line_leaves_that_line_out_with_a_warning_naming_file_and_line(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    t, i_a, _ = current_columns()
    cur = write_csv(tmp_path / "cur.csv", "t_s,i_a_A", [t, i_a], ["%.9f", "%r"])
    assert _cut_in_last_line(cur, 4) == "2.500000000,9.999802871917556e-14"  # left as "2.500000000,9.9"
    t_enc, counts, k = encoder_columns()
    enc = write_csv(tmp_path / "enc.csv", "t_s,position_counts,index", [t_enc, counts, k], ["%.9f", "%d", "%d"])
    _cut_in_last_line(enc, 2)
    r = run_import(capsys, cur, enc, tmp_path / "s.h5")
    assert r.code == 0, r.err
    s = load(tmp_path / "s.h5")
    np.testing.assert_array_equal(s.current.phases_a["i_a"], i_a[:-1])
    np.testing.assert_array_equal(s.encoder.position_counts, counts[:-1])
    details = [f"cur.csv: line {t.size + 1} has no end of line (the file was cut in it): left out, {t.size - 1} rows "
               "read", f"enc.csv: line {k.size + 1} has no end of line (the file was cut in it): left out, "
               f"{k.size - 1} rows read"]
    assert [(e.stream, e.kind, e.detail) for e in s.events] == [("current", "warning", details[0]),
                                                                 ("encoder", "warning", details[1])]
    assert all(f"warning: {d}" in " ".join(r.err.split()) for d in details)


def test_a_bad_cell_before_the_cut_is_still_named(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                  pair: tuple[Path, Path]) -> None:
    cur, enc = pair
    _with_row_changed(cur, 5, "0.000156250,abc,1.0")
    _cut_in_last_line(cur, 4)
    r = run_import(capsys, cur, enc, tmp_path / "s.h5")
    assert (r.code, r.err) == (2, f"acq: error: {cur}: line 5, column i_a_A: 'abc' is not a number\n")


def test_truncated_tdms_is_read_up_to_the_cut_with_a_warning_event(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    _, enc = pair
    _, i_a, _ = current_columns(3.0)
    cur = write_tdms(tmp_path / "cur.tdms", [i_a], segments=3)
    data = cur.read_bytes()
    cur.write_bytes(data[:-8000 * 8 - 4])  # the last segment loses 8000.5 samples
    r = run_import(capsys, cur, enc, tmp_path / "s.h5")
    assert r.code == 0, r.err
    s = load(tmp_path / "s.h5")
    n = i_a.size - 8001
    np.testing.assert_array_equal(s.current.phases_a["i_a"], i_a[:n])
    detail = f"cur.tdms: truncated last segment; read {n} samples per channel, the rest of that segment is missing"
    assert [(e.stream, e.kind, e.detail) for e in s.events] == [("current", "warning", detail)]
    assert f"warning: {detail}" in " ".join(r.err.split())


@pytest.mark.parametrize("into_header", [10, 123])
def test_a_tdms_cut_in_a_segment_header_is_read_up_to_the_cut_with_a_warning_event(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path], into_header: int) -> None:
    """10 segments, the file cut 10 bytes (in the lead-in) or 123 bytes (in the metadata) into the 7th. npTDMS drops
    that segment with only a log line; before: exit 0, status complete, no event, 40 % of the current missing."""
    _, enc = pair
    _, i_a, _ = current_columns(5.0)
    cur = write_tdms(tmp_path / "cur.tdms", [i_a], segments=10)
    data = cur.read_bytes()
    header = [i for i in range(len(data)) if data.startswith(b"TDSm", i)][6]
    assert header > len(data) * 0.59
    cur.write_bytes(data[:header + into_header])
    r = run_import(capsys, cur, enc, tmp_path / "s.h5")
    assert r.code == 0, r.err
    s = load(tmp_path / "s.h5")
    n = sum(part.size for part in np.array_split(i_a, 10)[:6])
    np.testing.assert_array_equal(s.current.phases_a["i_a"], i_a[:n])
    detail = f"cur.tdms: truncated last segment; read {n} samples per channel, the rest of that segment is missing"
    assert [(e.stream, e.kind, e.detail) for e in s.events] == [("current", "warning", detail)]
    assert f"warning: {detail}" in " ".join(r.err.split())


def _nan_at(values: np.ndarray, i: int) -> np.ndarray:
    out = values.copy()
    out[i] = np.nan
    return out


BAD_TDMS = [
    pytest.param(lambda p, i: write_tdms(p, [_nan_at(i, 1234)]), (), "channel DAQ/ai0, sample 1234: NaN", id="nan"),
    pytest.param(lambda p, i: write_tdms(p, [i[:40000]]), (),
                 "channel DAQ/ai0, sample 39999: only 1.562 s of data (at least 2 s needed)", id="too-short"),
    pytest.param(lambda p, i: write_tdms(p, [i], rate_hz=24000.0), (),
                 "channel DAQ/ai0, wf_increment: sample rate 24000 Hz disagrees with the bench's [daq] rate_hz = 25600 "
                 "by 6.25 % (more than 1 %)", id="rate"),
    pytest.param(lambda p, i: write_tdms(p, [i]), ("--current-channel", "DAQ/ia0"),
                 "channel DAQ/ia0: not in the file (channels: DAQ/ai0)", id="unknown-channel"),
]


@pytest.mark.parametrize(("make", "options", "message"), BAD_TDMS)
def test_bad_tdms_is_one_line_naming_file_channel_and_sample_exit_2_and_no_session(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path], make, options, message) -> None:
    _, enc = pair
    _, i_a, _ = current_columns()
    cur = make(tmp_path / "cur.tdms", i_a)
    r = run_import(capsys, cur, enc, tmp_path / "s.h5", *options)
    assert (r.code, r.err) == (2, f"acq: error: {cur}: {message}\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cur.csv", "cur.tdms", "enc.csv"]


def test_tdms_with_several_channels_and_none_picked_names_them(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    _, enc = pair
    _, i_a, i_b = current_columns()
    cur = write_tdms(tmp_path / "cur.tdms", [i_a, i_b])
    r = run_import(capsys, cur, enc, tmp_path / "s.h5")
    assert (r.code, r.err) == (2, f"acq: error: {cur}: 2 channels; pick the phases (a, b, c in that order) with "
                                  "--current-channel GROUP/CHANNEL (channels: DAQ/ai0, DAQ/ai1)\n")
    assert not (tmp_path / "s.h5").exists()


# ------------------------------------------------------------------------------------ round trip


def test_simulated_session_exported_and_imported_back_keeps_its_history_and_K(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    r = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--duration", "10", "--fast", "--no-analyze",
                "--out", str(tmp_path / "rec"), "--tag", "pose=home", "--tag", "payload_kg=2.5")
    assert r.code == 0, r.err
    (recorded,) = (tmp_path / "rec").glob("*.h5")
    exported = run_cli(capsys, "export", str(recorded), "--csv", str(tmp_path / "csv"))
    assert exported.code == 0
    assert exported.out.splitlines()[-1] == ("note: not in the CSV pair (acq import does not read them yet): "
                                             "velocity_demand_counts_per_s")
    cur, enc = (tmp_path / "csv" / f"{recorded.stem}.{kind}.csv" for kind in ("current", "encoder"))
    assert (tmp_path / "csv" / f"{recorded.stem}.session.json").is_file()
    r = run_cli(capsys, "import", "--current", str(cur), "--encoder", str(enc), "-o", str(tmp_path / "imported.h5"),
                "--tag", "temperature_C=31")  # bench and profile from the metadata
    assert r.code == 0, r.err
    original, imported = load(recorded), load(tmp_path / "imported.h5")
    np.testing.assert_array_equal(imported.current.phases_a["i_a"], original.current.phases_a["i_a"])
    np.testing.assert_array_equal(imported.encoder.position_counts, original.encoder.position_counts)
    np.testing.assert_allclose(imported.encoder.host_ns,
                               original.encoder.host_ns - original.attrs["host_monotonic_ns_at_start"], atol=1)
    for key in ("session_id", "created_utc", "joint", "bench_json", "profile_json"):
        assert imported.attrs[key] == original.attrs[key], key
    assert original.tags == {"pose": "home", "payload_kg": 2.5}
    assert imported.tags == {**original.tags, "temperature_C": 31}
    assert imported.host_clock_shared is True
    origin = json.loads(imported.attrs["origin_json"])
    assert origin["started_from"] == "acq export metadata"
    assert origin["host_timeline"].startswith(f"shared ({recorded.stem}.session.json)")
    k_recorded = analyze_session(recorded, write=False).result.fit.values.K_Nm_per_rad
    k_imported = analyze_session(tmp_path / "imported.h5", write=False).result.fit.values.K_Nm_per_rad
    # the CSV keeps the host stamps relative to the start (to 1 ns), which seed the clock search, but its current
    # column is DAQ time placed on the host timeline, not the blocks' arrival stamps: the recording's drift also takes
    # in its host stamps' (analysis.clocks._with_prior), the import's is the data's alone — K 5.5e-5 relative apart
    # (session 13; ~1e-9 before), ~100 times below K's 95 % interval
    assert abs(k_imported / k_recorded - 1.0) < 1e-4
    # a file changed since export is not the pair the metadata describes: nothing restored, no shared clock
    enc.write_text(enc.read_text() + "\n")
    r = run_import(capsys, cur, enc, tmp_path / "edited.h5")
    assert r.code == 0, r.err
    edited = load(tmp_path / "edited.h5")
    assert edited.host_clock_shared is False and edited.attrs["session_id"] != original.attrs["session_id"]
    assert (f"warning: {recorded.stem}.session.json describes another encoder file than {enc.name} (SHA-256 "
            "differs): its metadata is not used, the time columns are not taken as one host clock") in " ".join(
        r.err.split())
    # without --bench the configs would come from that metadata: the error says why it is not used
    r = run_cli(capsys, "import", "--current", str(cur), "--encoder", str(enc), "-o", str(tmp_path / "no_bench.h5"))
    assert r.code == 2 and r.err.strip() == (
        f"acq: error: --bench: needed ({recorded.stem}.session.json describes another encoder file than {enc.name} "
        "(SHA-256 differs): its metadata is not used, the time columns are not taken as one host clock)")


def test_export_refuses_to_replace_files_unless_forced_and_a_failed_export_changes_nothing(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path],
        monkeypatch: pytest.MonkeyPatch) -> None:
    assert run_import(capsys, *pair, tmp_path / "s.h5").code == 0
    out = tmp_path / "csv"
    assert run_cli(capsys, "export", str(tmp_path / "s.h5"), "--csv", str(out)).code == 0
    names = ["s.current.csv", "s.encoder.csv", "s.session.json"]
    exported = {name: (out / name).read_bytes() for name in names}
    (out / "s.current.csv").unlink()
    (out / "s.session.json").unlink()
    (out / "s.encoder.csv").write_text("t_s,position_counts\n0,1\n")  # another tool's file of the same name
    refused = run_cli(capsys, "export", str(tmp_path / "s.h5"), "--csv", str(out))
    assert refused.code == 2
    assert refused.err == f"acq: error: {out / 's.encoder.csv'}: exists (not overwritten; --force replaces it)\n"
    assert sorted(p.name for p in out.iterdir()) == ["s.encoder.csv"]  # nothing written, no temp file
    assert (out / "s.encoder.csv").read_text() == "t_s,position_counts\n0,1\n"

    def disk_full(*args: object) -> str:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("acq.offline.exporters.metadata_text", disk_full)  # the last of the three writes fails
    failed = run_cli(capsys, "export", str(tmp_path / "s.h5"), "--csv", str(out), "--force")
    assert failed.code == 1
    assert failed.err == f"acq: error: disk full: {out / 's.session.json'}\n"
    assert sorted(p.name for p in out.iterdir()) == ["s.encoder.csv"]  # the two CSVs written were not renamed
    assert (out / "s.encoder.csv").read_text() == "t_s,position_counts\n0,1\n"
    monkeypatch.undo()
    forced = run_cli(capsys, "export", str(tmp_path / "s.h5"), "--csv", str(out), "--force")
    assert forced.code == 0, forced.err
    assert sorted(p.name for p in out.iterdir()) == names
    assert {name: (out / name).read_bytes() for name in names[:2]} == {n: exported[n] for n in names[:2]}
    meta = json.loads((out / "s.session.json").read_text())
    assert meta["files"]["current"] == {"name": "s.current.csv",
                                        "sha256": hashlib.sha256(exported["s.current.csv"]).hexdigest()}


def test_an_export_whose_file_another_writer_makes_meanwhile_refuses_and_keeps_that_file(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    """Two exports of sessions of one name into one folder at once both find the names free before writing; the one
    that renames second must not replace the other's files. Here the other writer is a thread that makes
    s.current.csv as soon as this export's temp files appear (while it formats its CSVs). Before: exit 0, "wrote",
    the other file silently replaced (the trial: 3 of 6 simultaneous exports lost)."""
    assert run_import(capsys, *pair, tmp_path / "s.h5").code == 0
    out = tmp_path / "csv"
    out.mkdir()
    other = "t_s,i_a_A\n0,1\n"

    def other_writer() -> None:
        deadline = time.monotonic() + 30.0
        while not any(out.glob(".s.current.csv.*")) and time.monotonic() < deadline:
            time.sleep(0.0005)
        (out / "s.current.csv").write_text(other)

    thread = threading.Thread(target=other_writer)
    thread.start()
    refused = run_cli(capsys, "export", str(tmp_path / "s.h5"), "--csv", str(out))
    thread.join()
    assert (refused.code, refused.out, refused.err) == (
        2, "", f"acq: error: {out / 's.current.csv'}: exists (not overwritten; --force replaces it)\n")
    assert sorted(p.name for p in out.iterdir()) == ["s.current.csv"]  # nothing of this export's, no temp file
    assert (out / "s.current.csv").read_text() == other


def test_a_failed_rename_of_a_forced_export_keeps_the_metadata_and_names_the_target_in_one_line(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    """A folder where the encoder CSV goes: exit 1, one line naming that path (not the temp file), and the old
    <stem>.session.json kept (it was renamed first and replaced before)."""
    assert run_import(capsys, *pair, tmp_path / "s.h5").code == 0
    out = tmp_path / "csv"
    assert run_cli(capsys, "export", str(tmp_path / "s.h5"), "--csv", str(out)).code == 0
    meta_before = (out / "s.session.json").read_bytes()
    (out / "s.encoder.csv").unlink()
    (out / "s.encoder.csv").mkdir()
    (out / "s.encoder.csv" / "keep").write_text("x")  # a non-empty folder: no rename replaces it
    (out / "s.session.json").write_bytes(meta_before.replace(b'"joint"', b'"joint" ', 1))  # marks the old file
    marked = (out / "s.session.json").read_bytes()
    failed = run_cli(capsys, "export", str(tmp_path / "s.h5"), "--csv", str(out), "--force")
    assert failed.code == 1
    assert failed.err == f"acq: error: is a directory: {out / 's.encoder.csv'}\n"
    assert (out / "s.session.json").read_bytes() == marked
    assert sorted(p.name for p in out.iterdir()) == ["s.current.csv", "s.encoder.csv", "s.session.json"]  # no temp


def test_export_metadata_carries_every_field_of_the_sessions_history(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    imported = run_import(capsys, *pair, tmp_path / "s.h5", "--tag", "pose=home", "--started", "2026-11-20T10:15:03Z")
    assert imported.code == 0, imported.err
    assert run_cli(capsys, "export", str(tmp_path / "s.h5"), "--csv", str(tmp_path / "csv")).code == 0
    read, warning = read_metadata(tmp_path / "csv" / "s.current.csv", tmp_path / "csv" / "s.encoder.csv")
    assert warning is None and read is not None
    session = load(tmp_path / "s.h5").meta
    history = [f.name for f in fields(SessionHistory)]
    assert history == ["session_id", "joint", "created_utc", "operator", "origin", "tags", "host_clock_shared"]
    assert {n: getattr(read, n) for n in history} == {n: getattr(session, n) for n in history}
    assert (read.created_utc, read.tags, read.origin["kind"]) == ("2026-11-20T10:15:03+00:00", {"pose": "home"},
                                                                  "imported")


def test_import_tags_the_session(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                 pair: tuple[Path, Path]) -> None:
    cur, enc = pair
    r = run_import(capsys, cur, enc, tmp_path / "t.h5", "--tag", "pose=home", "--tag", "temperature_C=31.5")
    assert r.code == 0, r.err
    assert load(tmp_path / "t.h5").tags == {"pose": "home", "temperature_C": 31.5}
    bad = run_import(capsys, cur, enc, tmp_path / "u.h5", "--tag", "pose")
    assert bad.code == 2 and bad.err.strip() == "acq: error: --tag pose: must be KEY=VALUE, e.g. payload_kg=2.5"
    assert not (tmp_path / "u.h5").exists()


def test_import_makes_the_missing_folder_of_its_session_file_as_record_does_for_its_out_folder(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    """Before: ``-o new/deeper/s.h5`` was refused (``new/deeper: no such folder for the session file``, exit 2) while
    ``acq record --out`` and ``acq export --csv`` make theirs. Bad input still makes nothing; a file where the folder
    must be is one line before the inputs are read."""
    cur, enc = pair
    made = run_import(capsys, cur, enc, tmp_path / "new" / "deeper" / "s.h5")
    assert made.code == 0, made.err
    assert "".join(made.out.split()).endswith(f"imported→{tmp_path / 'new' / 'deeper' / 's.h5'}")  # rich wraps
    assert load(tmp_path / "new" / "deeper" / "s.h5").status == "complete"
    assert sorted(p.name for p in (tmp_path / "new" / "deeper").iterdir()) == ["s.h5"]  # no temp file left
    cur.write_text(cur.read_text().replace("i_a_A", "i_a_a", 1))
    bad = run_import(capsys, cur, enc, tmp_path / "other" / "s.h5")
    assert bad.code == 2 and bad.err.startswith(f"acq: error: {cur}: line 1, column i_a_a: unknown column")
    assert not (tmp_path / "other").exists()
    (tmp_path / "plain").write_text("not a folder")
    for out in (tmp_path / "plain" / "s.h5", tmp_path / "plain" / "sub" / "s.h5"):
        refused = run_import(capsys, tmp_path / "cur.csv", enc, out)
        assert (refused.code, refused.err) == (2, f"acq: error: -o {out}: {tmp_path / 'plain'} is a file, not a "
                                                  "folder\n")


def test_import_refuses_a_session_name_that_a_batch_would_not_see(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    """Before: ``-o imports/`` (a folder meant; the slash is gone once a path) wrote a session *file* named
    ``imports``, and ``-o s.csv`` an HDF5 file named s.csv: exit 0, and ``acq analyze FOLDER`` never saw either."""
    cur, enc = pair
    for given, example in ((f"{tmp_path / 'imports'}/", f"{tmp_path / 'imports' / 'session.h5'} or "
                                                        f"{tmp_path / 'imports'}.h5"),
                           (str(tmp_path / "s.csv"), str(tmp_path / "s.h5"))):
        refused = run_cli(capsys, "import", "--current", str(cur), "--encoder", str(enc), "--bench",
                          str(DEFAULT_BENCH), "--profile", "triangle_0.2s", "-o", given)
        out = given.rstrip("/")
        assert (refused.code, refused.err) == (2, f"acq: error: -o {out}: a session file's name must end in .h5 "
                                                  f"(acq analyze FOLDER finds only *.h5), e.g. {example}\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cur.csv", "enc.csv"]  # nothing written
    made = run_import(capsys, cur, enc, tmp_path / "imports" / "s.h5")
    assert made.code == 0, made.err
    assert [p.name for p in (tmp_path / "imports").iterdir()] == ["s.h5"]


# ------------------------------------------------------------------------------------ files as real tools write them


def test_jittered_encoder_stamps_that_step_back_are_taken_in_row_order_with_a_warning(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    cur, _ = pair
    t, counts, k = encoder_columns()
    t[[100, 1700]] -= [1.2e-3, 1.5e-3]  # stamped before the row above: 0.21 ms and 0.52 ms back
    enc = write_csv(tmp_path / "enc.csv", "t_s,position_counts,index", [t, counts, k], ["%.9f", "%d", "%d"])
    r = run_import(capsys, cur, enc, tmp_path / "s.h5")
    assert r.code == 0, r.err
    s = load(tmp_path / "s.h5")
    np.testing.assert_array_equal(s.encoder.index, k)
    detail = ("enc.csv: host stamps t_s step back 2 time(s), by up to 0.524 ms (first at line 102); rows taken in "
              "file order as the drive cycle order")
    assert [(e.stream, e.kind, e.detail) for e in s.events] == [("encoder", "warning", detail)]
    assert f"warning: {detail}" in " ".join(r.err.split())


def test_without_an_index_column_the_host_stamps_show_the_gaps(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    cur, _ = pair
    t, counts, k = encoder_columns()
    keep = np.ones(k.size, dtype=bool)
    keep[1000:1050] = False  # 50 rows lost
    keep[2000] = False  # and one
    t_batched = t.copy()
    t_batched[300:310] = t[309]  # ten rows stamped together, as a USB adapter delivers them: no gap
    enc = write_csv(tmp_path / "enc.csv", "t_s,position_counts", [t_batched[keep], counts[keep]], ["%.9f", "%d"])
    assert run_import(capsys, cur, enc, tmp_path / "s.h5").code == 0
    s = load(tmp_path / "s.h5")
    np.testing.assert_array_equal(s.encoder.index, k[keep])
    assert [(e.stream, e.kind, e.detail) for e in s.events] == [
        ("encoder", "warning", "enc.csv: no index or drive_time_s column; drive cycles taken as row numbers, gaps "
                               "found where the host stamps step by 1.5 periods or more"),
        ("encoder", "gap", "50 drive cycles missing before index 1050"),
        ("encoder", "gap", "1 drive cycles missing before index 2001")]


def test_a_file_of_exactly_2s_is_long_enough_and_a_shorter_one_says_by_how_much(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    t, i_a, _ = current_columns(2.0)
    exact = write_csv(tmp_path / "cur.csv", "t_s,i_a_A", [t[:-1], i_a[:-1]], ["%.9f", "%r"])  # 51 200 samples
    t_e, counts, k = encoder_columns(2.0)
    enc = write_csv(tmp_path / "enc.csv", "t_s,position_counts,index", [t_e[:-1], counts[:-1], k[:-1]],
                    ["%.9f", "%d", "%d"])  # 2000 drive cycles
    assert run_import(capsys, exact, enc, tmp_path / "s.h5").code == 0
    short = write_csv(tmp_path / "short.csv", "t_s,i_a_A", [t[:-2], i_a[:-2]], ["%.9f", "%r"])
    r = run_import(capsys, short, enc, tmp_path / "u.h5")
    assert (r.code, r.err) == (2, f"acq: error: {short}: line 51200, column t_s: only 1.99996 s of data (at least 2 s "
                                  "needed)\n")


# ------------------------------------------------------------------------------------ clocks of separate tools


def write_pair(folder: Path, rec, enc_rows: np.ndarray | None = None, index: bool = True) -> tuple[Path, Path]:
    """The recording as two tools write it: each file's t_s its own time from 0 (current: its sample clock)."""
    folder.mkdir(exist_ok=True)
    i_a = rec.current_a["i_a"]
    cur = write_csv(folder / "cur.csv", "t_s,i_a_A", [np.arange(i_a.size) / rec.rate_hz, i_a], ["%.9f", "%r"])
    rows = np.arange(rec.encoder_index.size) if enc_rows is None else enc_rows
    t = (rec.encoder_host_ns[rows] - rec.encoder_host_ns[0]) * 1e-9
    columns = [t, rec.position_counts[rows], rec.encoder_index[rows]]
    header = "t_s,position_counts,index" if index else "t_s,position_counts"
    enc = write_csv(folder / "enc.csv", header, columns if index else columns[:2], ["%.9f", "%d", "%d"])
    return cur, enc


@pytest.fixture(scope="module")
def separate_tools():
    """10 s simulated; DAQ sample 0 at drive time 0.7 s, 40 ppm drift; K = 891 N·m/rad."""
    from tests.test_clocks import separate_records
    return separate_records(0.7, 40.0, duration_s=10.0)


def test_two_files_from_separate_tools_both_starting_at_0_align_from_the_data(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, separate_tools) -> None:
    cur, enc = write_pair(tmp_path / "csv", separate_tools)
    assert run_import(capsys, cur, enc, tmp_path / "s.h5").code == 0
    assert load(tmp_path / "s.h5").host_clock_shared is False
    doc = analyze_session(tmp_path / "s.h5", write=False).json_dict
    assert doc["quality"]["verdict"] == "ok"
    assert doc["K_Nm_per_rad"] == pytest.approx(891.0, rel=0.01)
    assert doc["clock"]["offset_s"] == pytest.approx(0.7, abs=50e-6)
    assert doc["clock"]["drift_ppm"] == pytest.approx(40.0, abs=5.0)


def test_a_gap_seen_only_in_the_host_stamps_leaves_the_longest_span_analysed(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, separate_tools) -> None:
    rows = np.setdiff1d(np.arange(separate_tools.encoder_index.size), np.arange(3000, 3050))
    cur, enc = write_pair(tmp_path / "csv", separate_tools, rows, index=False)
    assert run_import(capsys, cur, enc, tmp_path / "s.h5").code == 0
    doc = analyze_session(tmp_path / "s.h5", write=False).json_dict
    assert "note: encoder: 1 gap(s), first after cycle 2999: using the longest gap-free span 3.050–9.999 s" in \
        doc["quality"]["reasons"]
    assert doc["quality"]["verdict"] == "ok"
    assert doc["K_Nm_per_rad"] == pytest.approx(891.0, rel=0.01)


# ------------------------------------------------------------------------------------ history through export/import


def test_started_dates_an_import_so_the_catalogue_sorts_by_recording_time(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, pair: tuple[Path, Path]) -> None:
    cur, enc = pair
    folder = tmp_path / "sessions"
    folder.mkdir()
    for name, started in (("later.h5", "2026-03-02T09:00:00+01:00"), ("earlier.h5", "2026-03-01T10:15:03")):
        r = run_import(capsys, cur, enc, folder / name, "--started", started)
        assert r.code == 0, r.err
    assert load(folder / "later.h5").attrs["created_utc"] == "2026-03-02T08:00:00+00:00"
    assert json.loads(load(folder / "later.h5").attrs["origin_json"])["started_from"] == "--started"
    run_cli(capsys, "analyze", str(folder), "--no-report")
    with Catalogue(folder / "catalogue.sqlite") as catalogue:
        assert [Path(e.path).name for e in catalogue.entries()] == ["earlier.h5", "later.h5"]
    bad = run_import(capsys, cur, enc, tmp_path / "x.h5", "--started", "yesterday")
    assert (bad.code, bad.err) == (2, "acq: error: --started yesterday: not an ISO 8601 time (e.g. "
                                      "2026-11-20T10:15:03Z)\n")
    ahead = run_import(capsys, cur, enc, tmp_path / "y.h5", "--started", "2030-01-01T00:00:00Z")
    assert ahead.code == 2 and ahead.err.startswith("acq: error: --started 2030-01-01T00:00:00Z: after now (")
    assert ahead.err.endswith("): a recording cannot start in the future — a typo in the year, or a local time "
                              "with the wrong zone?\n") and not (tmp_path / "y.h5").exists()
    local_east = (datetime.now(UTC) + timedelta(hours=13)).replace(tzinfo=None).isoformat(timespec="seconds")
    assert run_import(capsys, cur, enc, tmp_path / "z.h5", "--started", local_east).code == 0  # UTC+13 without zone


def test_a_tdms_wf_start_time_dates_the_import(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                               pair: tuple[Path, Path]) -> None:
    _, enc = pair
    _, i_a, _ = current_columns()
    props = {"wf_increment": 1.0 / RATE_HZ, "wf_start_offset": 0.0,
             "wf_start_time": np.datetime64("2026-02-03T04:05:06.789")}
    with TdmsWriter(tmp_path / "cur.tdms") as w:
        w.write_segment([RootObject(), GroupObject("DAQ"), ChannelObject("DAQ", "ai0", i_a, properties=props)])
    assert run_import(capsys, tmp_path / "cur.tdms", enc, tmp_path / "s.h5").code == 0
    s = load(tmp_path / "s.h5")
    assert s.attrs["created_utc"] == "2026-02-03T04:05:06+00:00"
    assert json.loads(s.attrs["origin_json"])["started_from"] == "TDMS wf_start_time"


def test_acq_import_applies_the_rules_between_config_keys(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                          pair: tuple[Path, Path]) -> None:
    serial = DEFAULT_BENCH.parent / "sim_serial.toml"
    bench = tmp_path / "slow.toml"
    bench.write_text(serial.read_text().replace("baud = 921600", "baud = 115200"))
    cur, enc = pair
    run = run_cli(capsys, "import", "--current", str(cur), "--encoder", str(enc), "--bench", str(bench),
                  "--profile", "triangle_0.2s", "-o", str(tmp_path / "imported.h5"))
    assert (run.code, run.err) == (2, f"acq: error: {bench}: [drive] baud = 115200: too low for one 16-byte acq1 "
                                      "frame every 0.001 s; needs at least 160000 baud (16 bytes × 10 bits / 0.001 s)\n")
    assert not (tmp_path / "imported.h5").exists()


def test_a_mistyped_current_file_is_named_before_the_bench_is_asked_for(capsys: pytest.CaptureFixture[str],
                                                                         tmp_path: Path, pair: tuple[Path, Path]) -> None:
    _, enc = pair
    run = run_cli(capsys, "import", "--current", str(tmp_path / "nofile.csv"), "--encoder", str(enc),
                  "-o", str(tmp_path / "imported.h5"))
    assert (run.code, run.err) == (2, f"acq: error: {tmp_path / 'nofile.csv'}: no such file\n")


def test_a_current_in_milliamperes_is_named_as_a_scale_mistake_not_an_ok_stiffness(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, separate_tools) -> None:
    from dataclasses import replace
    in_mA = replace(separate_tools, current_a={"i_a": 1000.0 * separate_tools.current_a["i_a"]})
    cur, enc = write_pair(tmp_path / "csv", in_mA)
    assert run_import(capsys, cur, enc, tmp_path / "s.h5").code == 0
    r = run_cli(capsys, "analyze", str(tmp_path / "s.h5"), "--json", "--no-report")
    doc = json.loads(r.out)
    factors = [doc[n] / v for n, v in (("K_Nm_per_rad", 891.0), ("Jm_kgm2", 0.003027), ("Jl_kgm2", 0.00748))]
    assert factors == pytest.approx([1000.0] * 3, rel=0.02)  # the data hold together: only the scale is wrong
    assert doc["quality"]["verdict"] == "poor"
    assert doc["quality"]["reasons"][0] == (
        f"K is {factors[0]:.0f}× the bench's nominal 891 N·m/rad (J_m {factors[1]:.0f}×, J_l {factors[2]:.0f}×): "
        "the torque is scaled — check the current's unit and scale (amperes: [daq] sensor_A_per_V or sensor_A_per_A; "
        "an imported current column in A) and the torque constant ([motor] torque_constant_Nm_per_A)")


#: The trial's three recordings of [sim] K_Nm_per_rad = 8910 on the sim bench (nominal 891): K and its 95 % interval.
K10_FITS = ((8904.130227208767, (8620.778433262452, 9196.79536098328)),
            (8944.037820281703, (8580.357391190286, 9323.132928328094)),
            (8932.998046317456, (8673.084845882577, 9200.700271414347)))
K10_WORDS = ("K is 10× the bench's nominal 891 N·m/rad: check the [nominal] values (motor-side, SI units: a load-side "
             "value is [gear] ratio² larger) and that the bench file is this joint's")


@pytest.mark.parametrize(("K", "ci"), K10_FITS)
def test_nominal_fault_gives_one_verdict_to_a_decade_mistake_on_either_side_of_ten(
        K: float, ci: tuple[float, float]) -> None:
    """The trial's K 8910 on a nominal 891, recorded 3 times: before, 8904 (9.99×, interval 9.68…10.32×) was ok —
    below 10× — and 8944, 8933 poor. Now each interval lies beyond 7.7× (√(6 × 10)): poor each time."""
    from analysis.diagnose import nominal_fault
    from analysis.model import TwoMassParams
    nominal = TwoMassParams(891.0, 0.003027, 0.00748, 0.0)
    assert nominal_fault(TwoMassParams(K, 0.003027, 0.00748, 0.1), nominal, ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2"),
                         {"K_Nm_per_rad": ci, "Jm_kgm2": (0.0029, 0.0031), "Jl_kgm2": (0.0072, 0.0077)}) == K10_WORDS


def test_nominal_fault_at_the_threshold_with_the_intervals_of_a_well_determined_K() -> None:
    """The interval (±2.6 %, the trial's) must lie wholly beyond 7.7×: a real joint strays up to 6× (an arm left out
    of J_l), never flagged; one pinned down 8× or more off is."""
    from analysis.diagnose import nominal_fault
    from analysis.model import TwoMassParams
    nominal = TwoMassParams(891.0, 0.003027, 0.00748, 0.0)
    free = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2")

    def fault(factor: float) -> str | None:
        K = factor * 891.0
        return nominal_fault(TwoMassParams(K, 0.003027, 0.00748, 0.1), nominal, free,
                             {"K_Nm_per_rad": (0.9745 * K, 1.0262 * K), "Jm_kgm2": (0.0029, 0.0031),
                              "Jl_kgm2": (0.0072, 0.0077)})

    assert fault(6.0) is None and fault(1 / 6.0) is None
    assert fault(7.8) is None  # its interval reaches down to 7.6×
    assert fault(9.9) == fault(10.05) == K10_WORDS
    assert fault(11.0) == (
        "K is 11× the bench's nominal 891 N·m/rad: check the [nominal] values (motor-side, SI units: a load-side "
        "value is [gear] ratio² larger) and that the bench file is this joint's")
    assert fault(1 / 10.05) is not None and fault(1 / 9.9) is not None


def test_nominal_fault_names_an_order_of_magnitude_and_not_the_scenario_familys_factor_two() -> None:
    from analysis.diagnose import nominal_fault
    from analysis.model import TwoMassParams
    nominal = TwoMassParams(891.0, 0.003027, 0.00748, 0.0)
    free = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")
    assert nominal_fault(TwoMassParams(2 * 891.0, 0.5 * 0.003027, 2 * 0.00748, 0.1), nominal, free) is None
    assert nominal_fault(TwoMassParams(6.0 * 891.0, 0.003027, 0.00748, 0.1), nominal, free) is None
    assert nominal_fault(TwoMassParams(891.0, 0.003027, 0.00748 / 100.0, 0.1), nominal, free) == (
        "J_l is 1/100 of the bench's nominal 0.00748 kg·m²: check the [nominal] values (motor-side, SI units: a "
        "load-side value is [gear] ratio² larger) and that the bench file is this joint's")
    assert nominal_fault(TwoMassParams(0.1 * 891.0, 0.003027, 0.00748, 0.1), nominal, ("K_Nm_per_rad",)).startswith(
        "K is 1/10 of the bench's nominal 891 N·m/rad: the torque is scaled")
    # a value the data hardly determine (its interval reaches within √10 = 3.16× of nominal) is no evidence of a mistake
    assert nominal_fault(TwoMassParams(891.0, 0.003027, 0.00748 / 100.0, 0.1), nominal, free,
                         {"Jl_kgm2": (0.00748 / 300.0, 0.00748 / 3.0)}) is None
    assert nominal_fault(TwoMassParams(891.0, 0.003027, 0.00748 / 100.0, 0.1), nominal, free,
                         {"Jl_kgm2": (0.00748 / 120.0, 0.00748 / 80.0)}) is not None
