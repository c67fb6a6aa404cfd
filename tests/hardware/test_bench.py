"""The chain on the bench named by ACQ_HW_BENCH (see conftest.py): devices, recorder, transport, identification.

Each test asserts with the bench's own figures; a failure message is the selftest's line with its fix.
"""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest

from acq.commissioning.selftest_checks import Check
from acq.config import load_profile
from acq.recording.recorder import Recorder
from acq.recording.reader import load
from drivers.config import Bench, DaqNidaqmx, DriveCanopen, DriveSerial
from drivers.registry import open_bench

RECORD_S = 5.0


def _ok(check: Check | None, *, allow_warn: bool = True) -> None:
    assert check is not None, "the selftest stopped before this check (see the failed one)"
    allowed = ("pass", "warn") if allow_warn else ("pass",)
    assert check.status in allowed, f"{check.stage} · {check.name}: {check.figure} → {check.fix}"


def test_devices_are_listed_and_open(selftest_checks: dict[str, Check], hw_bench: Bench) -> None:
    _ok(selftest_checks.get("acq devices"))
    _ok(selftest_checks.get("DAQ"))
    _ok(selftest_checks.get("drive"), allow_warn=False)
    assert selftest_checks["DAQ"].values["channels"] == list(hw_bench.daq.channels)
    assert selftest_checks["drive"].values["period_s"] == pytest.approx(hw_bench.drive.period_s)


def test_ni_daq_runs_at_its_coerced_rate(selftest_checks: dict[str, Check], hw_bench: Bench) -> None:
    if not isinstance(hw_bench.daq, DaqNidaqmx):
        pytest.skip("the bench's DAQ is not an NI-DAQmx device")
    daq = selftest_checks["DAQ"].values
    assert daq["rate_hz"] == pytest.approx(hw_bench.daq.rate_hz, rel=0.01)
    _ok(selftest_checks.get("DAQ blocks"))


def test_standstill_streams_lose_nothing(selftest_checks: dict[str, Check]) -> None:
    rec = selftest_checks.get("recording")
    _ok(rec, allow_warn=False)
    assert rec.values["current_lost"] == 0 and rec.values["encoder_lost"] == 0
    _ok(selftest_checks.get("drive period"), allow_warn=False)
    _ok(selftest_checks.get("SYNC jitter"))  # ⚠: a software SYNC producer; ✗: the drive's own stamps half a cycle off
    _ok(selftest_checks.get("current at standstill"))


def test_canopen_sync_to_tpdo_within_a_period(selftest_checks: dict[str, Check], hw_bench: Bench) -> None:
    if not isinstance(hw_bench.drive, DriveCanopen):
        pytest.skip("the bench's drive is not on CANopen")
    frames = selftest_checks.get("CAN frames")
    _ok(frames)
    assert frames.values["sync_period_s"] == pytest.approx(hw_bench.drive.period_s, rel=0.01)
    assert frames.values["sync_to_tpdo_median_s"] < hw_bench.drive.period_s
    assert frames.values["heartbeat_period_s"] == pytest.approx(hw_bench.drive.heartbeat_period_s, rel=0.2)


def test_serial_link_has_no_crc_errors(selftest_checks: dict[str, Check], hw_bench: Bench) -> None:
    if not isinstance(hw_bench.drive, DriveSerial):
        pytest.skip("the bench's drive is not on a serial link")
    link = selftest_checks.get("serial link")
    _ok(link, allow_warn=False)
    assert link.values["frames"] >= 0.99 * 3.0 / hw_bench.drive.period_s


def test_config_matches_the_motion(selftest_checks: dict[str, Check]) -> None:
    for name in ("encoder speed", "electrical speed", "direction", "phase order"):
        _ok(selftest_checks.get(name), allow_warn=False)


def test_identification_is_not_failed(selftest_checks: dict[str, Check]) -> None:
    ident = next((c for n, c in selftest_checks.items() if n.startswith("identification")), None)
    _ok(ident)
    _ok(selftest_checks.get("torque constant"))


def test_recorder_writes_every_sample_to_a_readable_file(hw_bench: Bench, hw_session_dir) -> None:
    """A plain recording of the bench's profile: complete, every sample by the counters, HDF5 read back."""
    profile = load_profile("triangle_0.2s")
    current, drive = open_bench(hw_bench)
    result = Recorder(hw_bench, profile, current, drive, hw_session_dir, RECORD_S).run()
    assert result.status == "complete", result.stop_reason
    assert result.current_gaps == 0 and result.encoder_gaps == 0
    session = load(result.path)
    assert session.current.sample_count >= math.ceil(RECORD_S * session.current.rate_hz)
    assert session.encoder.index.size >= math.ceil(RECORD_S / session.encoder.period_s)
    assert np.all(np.diff(session.encoder.index) == 1)
    with h5py.File(result.path, "r") as f:  # the file itself, not only acq's reader
        assert f.attrs["status"] == b"complete"  # fixed-length: h5py reads bytes
        assert f["current/i_a_A"].shape[0] == session.current.sample_count
    if isinstance(hw_bench.drive, DriveCanopen):
        import can

        with can.BLFReader(str(result.path.with_suffix(".can.blf"))) as reader:
            assert sum(1 for _ in reader) >= session.encoder.index.size  # every TPDO (and SYNC) kept raw
