"""The session file: layout of design §6, read back by h5py; crash repair keeps every flushed sample."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from acq.config import load_bench, load_profile
from acq.recording.layout import FOOTER_TEXT, FOOTER_TEXT_BYTES, FORMAT
from acq.recording.reader import load
from acq.recording.repair import repair
from acq.recording.writer import SessionWriter
from drivers.base import CurrentBlock, CurrentSourceInfo, DriveInfo, EncoderBlock, StreamEvent
from tests.helpers import run_cli


def _writer(path: Path) -> SessionWriter:
    return SessionWriter(
        path,
        bench=load_bench(),
        profile=load_profile("triangle_0.2s"),
        current_info=CurrentSourceInfo(25600.0, ("i_a", "i_b"), "test-daq"),
        drive_info=DriveInfo(0.001, 131072, "sim", "drive_cycle", "test-drive"),
        host_ns_at_start=123,
        operator="ana",
        tags={"payload_kg": 2.0},
    )


def _current(first: int, n: int) -> CurrentBlock:
    idx = np.arange(first, first + n, dtype=float)
    return CurrentBlock(first, np.vstack([idx, -idx]), host_ns=1000 + first)


def _encoder(cycles: np.ndarray) -> EncoderBlock:
    return EncoderBlock(cycles, cycles * 7, cycles * 10, drive_time_s=cycles * 0.001)


def test_round_trip_layout_and_footer(tmp_path: Path) -> None:
    path = tmp_path / "s.h5"
    w = _writer(path)
    w.append_current(_current(0, 100))
    w.append_current(_current(150, 50))  # a gap of 50 samples kept as it is
    w.append_encoder(_encoder(np.arange(0, 10)))
    w.append_encoder(_encoder(np.arange(12, 20)))
    w.add_event(StreamEvent(5, "encoder", "gap", "2 frames missing before cycle 12"))
    w.finish("complete", "recorded 10 s")

    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == FORMAT and f.attrs["status"] == b"complete"  # fixed-length: h5py reads bytes
        assert f.attrs["stop_reason"] == b"recorded 10 s" and len(f.attrs["session_id"]) == 36
        sizes = [f.attrs.get_id(name).dtype.itemsize for name in FOOTER_TEXT]
        assert sizes == [FOOTER_TEXT_BYTES[name] for name in FOOTER_TEXT]
        assert f["current"].attrs["rate_hz"] == 25600.0
        assert f["current/i_a_A"].dtype == np.float64 and f["current/i_a_A"].shape == (150,)
        assert list(f["current/blocks/first_index"][...]) == [0, 150]
        assert f["encoder/position_counts"].dtype == np.int64
        assert f["encoder"].attrs["transport"] == "sim"
        assert "velocity_counts_per_s" not in f["encoder"], "never-filled optional columns are removed"
        assert f.attrs["current_samples"] == 150 and f.attrs["encoder_samples"] == 18

    s = load(path)
    assert s.bench.joint == "joint1" and s.profile.accel_time_s == 0.2 and s.tags == {"payload_kg": 2.0}
    np.testing.assert_array_equal(s.current.sample_index(), np.r_[np.arange(100), np.arange(150, 200)])
    np.testing.assert_array_equal(s.current.phases_a["i_b"], -s.current.sample_index())
    np.testing.assert_array_equal(s.encoder.index, np.r_[np.arange(10), np.arange(12, 20)])
    np.testing.assert_allclose(s.encoder.drive_time_s, s.encoder.index * 0.001)
    assert s.events == [StreamEvent(5, "encoder", "gap", "2 frames missing before cycle 12")]


def test_appends_are_stored_once_in_order_across_flushes_and_bulk_appends(tmp_path: Path) -> None:
    """Small appends are copied into buffers the writer reuses from flush to flush (the block handed in is free at
    once), large ones (an import's) into parts of their own: each sample is stored once, in the order appended, and
    a caller that reuses its arrays before the flush changes nothing stored (large appends were held by reference:
    zeros in the file)."""
    path = tmp_path / "s.h5"
    w = _writer(path)
    w.append_current(_current(0, 100))
    n = (1 << 20) // 8 + 10  # one channel's part above the limit for a part of its own
    bulk = np.arange(100, 100 + n, dtype=float)
    w.append_current_blocks([bulk, -bulk], np.array([100]), np.array([n]), np.array([7]))
    bulk[:] = 0.0
    block = _current(100 + n, 100)
    w.append_current(block)
    block.current_a[:] = 0.0  # the caller reuses its array: what was appended is kept
    large = _current(200 + n, n)
    w.append_current(large)
    large.current_a[:] = 0.0
    w.flush()
    w.append_current(_current(200 + 2 * n, 30))  # into the same buffer again, after the flush
    w.finish("complete", "recorded")
    s = load(path)
    expected = np.arange(230 + 2 * n)
    np.testing.assert_array_equal(s.current.sample_index(), expected)
    np.testing.assert_array_equal(s.current.phases_a["i_a"], expected)
    np.testing.assert_array_equal(s.current.phases_a["i_b"], -expected)
    np.testing.assert_array_equal(s.current.block_count, [100, n, 100, n, 30])


KILLED_WRITER = textwrap.dedent(
    """
    import os, signal, sys
    import numpy as np
    sys.path.insert(0, {tests!r})
    from test_session import _writer, _current, _encoder
    w = _writer(__import__("pathlib").Path({path!r}))
    for k in range(20):
        w.append_current(_current(k * 100, 100))
        w.append_encoder(_encoder(np.arange(k * 4, k * 4 + 4)))
        w.flush()
    w.append_current(_current(2000, 100))  # appended, never flushed
    os.kill(os.getpid(), signal.SIGKILL)
    """
)


def test_killed_writer_leaves_readable_file_and_repair_keeps_all_flushed(tmp_path: Path) -> None:
    path = tmp_path / "killed.h5"
    code = KILLED_WRITER.format(tests=str(Path(__file__).parent), path=str(path))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == -9, proc.stderr
    s = load(path)
    assert s.status == "recording"
    assert s.current.sample_count >= 2000 and s.encoder.index.size == 80
    np.testing.assert_array_equal(s.current.sample_index()[:2000], np.arange(2000))

    repair(path, "recorder killed")
    fixed = load(path)
    assert fixed.status == "interrupted" and fixed.attrs["stop_reason"] == "recorder killed"
    assert fixed.current.sample_count == s.current.sample_count
    np.testing.assert_array_equal(fixed.encoder.position_counts, s.encoder.position_counts)
    with h5py.File(path, "r") as f:  # a normal (non-SWMR) open works again after repair
        assert f.attrs["encoder_samples"] == 80


LIVE_WRITER = textwrap.dedent(
    """
    import sys
    import numpy as np
    sys.path.insert(0, {tests!r})
    from test_session import _writer, _current, _encoder
    w = _writer(__import__("pathlib").Path({path!r}))
    w.append_current(_current(0, 100))
    w.append_encoder(_encoder(np.arange(8)))  # drive time stamps, no velocity: its columns hold NaN until finish
    w.flush()
    print("flushed", flush=True)
    sys.stdin.readline()
    w.finish("complete", "recorded")
    """
)


def test_info_on_a_session_being_recorded_lists_only_the_columns_the_drive_gave(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "120")
    path = tmp_path / "live.h5"
    code = LIVE_WRITER.format(tests=str(Path(__file__).parent), path=str(path))
    with subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                          text=True) as writer:
        assert writer.stdout is not None and writer.stdin is not None
        assert writer.stdout.readline() == "flushed\n"
        seen = [run_cli(capsys, "info", str(path), "--json"), run_cli(capsys, "info", str(path))]
        writer.stdin.write("finish\n")
        writer.stdin.flush()
        assert writer.wait(timeout=60) == 0
    seen += [run_cli(capsys, "info", str(path), "--json"), run_cli(capsys, "info", str(path))]
    for (as_json, table), status in zip((seen[:2], seen[2:]), ("recording", "complete")):
        doc = json.loads(as_json.out)
        assert (doc["status"], doc["encoder_extras"], doc["streams"][1]["samples"]) == (status, ["drive_time_s"], 8)
        assert "encoder also: drive time stamps" in [line.strip() for line in table.out.splitlines()]
        assert "velocity" not in table.out


def test_not_a_session(tmp_path: Path) -> None:
    from acqcore.errors import ConfigError

    other = tmp_path / "other.h5"
    with h5py.File(other, "w", libver=("v110", "latest")) as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(ConfigError, match="not an acq session"):
        load(other)
    with pytest.raises(ConfigError, match="no such session file"):
        load(tmp_path / "missing.h5")
    (tmp_path / "text.h5").write_text("hello")
    with pytest.raises(ConfigError, match="not a readable HDF5 session file"):
        load(tmp_path / "text.h5")


def test_an_empty_file_and_a_file_of_another_kind_are_named_so_not_in_hdf5s_words(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Before: both said '(Unable to synchronously open file (file signature not found))' — HDF5's words."""
    empty, text = tmp_path / "empty.h5", tmp_path / "notes.h5"
    empty.touch()
    text.write_text("K = 891\n")
    for command in ("info", "analyze", "check", "export"):
        extra = ("--csv", str(tmp_path / "csv")) if command == "export" else ()
        runs = [run_cli(capsys, command, str(path), *extra) for path in (empty, text)]
        assert [(r.code, r.err) for r in runs] == [
            (2, f"acq: error: {empty}: empty (0 bytes), not a session file\n"),
            (2, f"acq: error: {text}: not a readable HDF5 session file (no HDF5 signature: another kind of file)\n")]


def test_sessions_started_in_the_same_second_get_distinct_files(tmp_path: Path) -> None:
    from acq.recording.paths import new_session_path

    first = new_session_path(tmp_path, "joint1", "2026-11-22T10:15:03+00:00")
    assert first.name == "2026-11-22T10-15-03_joint1.h5"
    first.touch()
    second = new_session_path(tmp_path, "joint1", "2026-11-22T10:15:03+00:00")
    assert second.name == "2026-11-22T10-15-03_joint1_2.h5"


def test_a_long_event_detail_is_cut_on_a_character_boundary(tmp_path: Path) -> None:
    path = tmp_path / "ev.h5"
    w = _writer(path)
    w.add_event(StreamEvent(1, "drive", "error", "x" * 239 + "— and more"))
    w.finish("failed", "test")
    (event,) = load(path).events
    assert event.detail == "x" * 239
