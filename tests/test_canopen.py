"""The CANopen drive adapter against the simulated CiA 402 drive, real canopen traffic on ``virtual``.

Each test records on its own virtual channel. Nothing waits on wall-clock timing for synchronisation:
faults are injected from the recorder's listener when a given block arrives, counts come from the SYNC
counter, and the recording ends by sample count or by the failure it provokes.
"""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import can
import numpy as np
import pytest

from acq.config import load_bench, load_profile, validate
from acq.offline.analyze import request_for, recording_from_session
from acq.recording.recorder import Recorder
from acq.recording.reader import load
from acq.recording.summary import summarize
from drivers.canopen_bus_load import bus_load, check_bus_load
from drivers.canopen_drive import CanopenDrive
from drivers.sim.peers import open_canopen_with_sim_node as open_drive
from analysis.pipeline import analyze
from analysis.sample_instants import stamp_deviation_s
from drivers.canopen_od import HIGH_RES_TIMESTAMP, POSITION_ACTUAL, TPDO_COMM, TPDO_MAP, VELOCITY_ACTUAL, map_entry
from drivers.canopen_stream import SYNC_COB_ID, FrameCapture, SyncUnwrapper, TpdoDecoder
from drivers.config import Bench, DriveCanopen
from acqcore.errors import ConfigError, DeviceError
from drivers.sim.bench import SimBench
from drivers.sim.daq import open_current_source

BENCH_TOML = Path(__file__).parents[1] / "configs" / "benches" / "sim_canopen.toml"
_channels = itertools.count()


def _bench(**drive: object) -> Bench:
    bench = load_bench(BENCH_TOML)
    settings = {"channel": f"acq-test-{next(_channels)}", "state_timeout_s": 0.3, **drive}
    return bench.model_copy(update={"drive": bench.drive.model_copy(update=settings)})


def _parts(bench: Bench) -> tuple[SimBench, object, CanopenDrive]:
    sim = SimBench(bench, realtime=True, keep_history=True)
    return sim, open_current_source(bench, sim, False), open_drive(bench, sim, False)


def _wait_until(condition, timeout_s: float) -> bool:
    """Poll ``condition`` until it holds or ``timeout_s`` (s) passed; its last value."""
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)
    return condition()


def _record(tmp_path: Path, bench: Bench, duration_s: float, on_encoder_block=None):
    sim, current, drive = _parts(bench)
    blocks = itertools.count()

    def listener(kind: str, block: object) -> None:
        if kind == "encoder" and on_encoder_block is not None:
            on_encoder_block(next(blocks), drive)

    profile = load_profile("triangle_0.2s").model_copy(update={"dither_seed": 0})  # the same motion in every run
    result = Recorder(bench, profile, current, drive, tmp_path, duration_s,
                      listeners=[listener]).run()
    return result, load(result.path), sim, drive


def test_mapping_round_trip_position_and_velocity_on_the_chosen_tpdo() -> None:
    bench = _bench(tpdo=2, map_velocity=True)
    _, _, drive = _parts(bench)
    drive.start()
    try:
        node = drive.sim_node.node
        assert node.sdo[TPDO_COMM + 1][2].raw == 1
        assert node.sdo[TPDO_COMM + 1][1].raw & 0x7FF == 0x281
        assert [node.sdo[TPDO_MAP + 1][i].raw for i in range(1, node.sdo[TPDO_MAP + 1][0].raw + 1)] == [
            map_entry(POSITION_ACTUAL, 32), map_entry(VELOCITY_ACTUAL, 32)]
        block = None
        while block is None:
            block = drive.read(1.0)
        assert block.velocity_counts_per_s is not None and np.all(np.diff(block.index) == 1)
    finally:
        drive.stop()


def test_3s_at_1kHz_loses_no_sample_and_each_sample_is_its_sync(tmp_path: Path) -> None:
    result, s, sim, drive = _record(tmp_path / "new" / "folder", _bench(), 3.0)  # .blf and .h5 in a folder made now
    assert result.status == "complete", result.stop_reason
    idx = s.encoder.index
    assert 3000 <= idx.size <= 3000 + 100
    np.testing.assert_array_equal(np.diff(idx), 1)
    assert [e for e in s.events if e.kind in ("gap", "warning", "error")] == []
    truth = sim.encoder_counts(drive.sim_node.first_cycle + int(idx[0]), idx.size)
    np.testing.assert_array_equal(s.encoder.position_counts - s.encoder.position_counts[0], truth - truth[0])
    assert np.ptp(s.encoder.position_counts) > 100_000  # the profile-position triangle really moved the joint
    assert drive.sim_node.state_402 == 0x40  # SWITCH ON DISABLED after the recording
    rebuilt = _rebuild_from_raw_frames(result.path.with_suffix(".can.blf"))
    np.testing.assert_array_equal(rebuilt[idx], s.encoder.position_counts)
    # acq info's rate: the line through the host stamps, whatever the first TPDOs' lateness or burst (first to last
    # stamp it read 1061.35 Hz of this 1000 Hz drive in the new-user trial, 1004.07 Hz in a run here)
    (encoder,) = [x for x in summarize(s).streams if x.name == "encoder"]
    assert encoder.fitted_rate_hz == pytest.approx(1000.0, rel=1e-3)


def _rebuild_from_raw_frames(blf: Path) -> np.ndarray:
    """Position (counts) by SYNC index, from the .blf alone: each TPDO pairs with the SYNC before it."""
    counter, frames, first_ns = 0, [], None
    for msg in can.BLFReader(blf):
        if msg.arbitration_id == SYNC_COB_ID:
            counter, first_ns = msg.data[0], first_ns or int(msg.timestamp * 1e9)
        elif msg.arbitration_id == 0x181 and counter:
            frames.append((counter, bytes(msg.data), int(msg.timestamp * 1e9)))
    block = TpdoDecoder(SyncUnwrapper(240, 0.001, first_ns), True, 1.0).decode(frames)
    positions = np.full(int(block.index[-1]) + 1, np.iinfo(np.int64).min)
    positions[block.index] = block.position_counts
    return positions


def test_dropped_tpdos_are_one_gap_event_with_their_count(tmp_path: Path) -> None:
    def drop(n: int, drive: CanopenDrive) -> None:
        if n == 2:
            drive.sim_node.drop_tpdos(7)

    result, s, _, _ = _record(tmp_path, _bench(), 1.0, drop)
    assert result.status == "complete"
    gaps = [e for e in s.events if e.kind == "gap"]
    assert len(gaps) == 1 and gaps[0].detail.startswith("7 frames missing before cycle ")
    assert int(np.sum(np.diff(s.encoder.index) - 1)) == 7


def test_heartbeat_loss_fails_the_session_keeps_data_and_disables_the_drive(tmp_path: Path) -> None:
    def silence(n: int, drive: CanopenDrive) -> None:
        if n == 2:
            drive.sim_node.stop_heartbeat()

    result, s, _, drive = _record(tmp_path, _bench(heartbeat_timeout_s=0.3), 30.0, silence)
    assert result.status == "failed"
    assert result.stop_reason.startswith("CANopen node 1 on virtual:acq-test-")
    assert ": heartbeat lost (none for 0." in result.stop_reason and "timeout 0.3 s)" in result.stop_reason
    assert s.status == "failed" and s.encoder.index.size > 100 and s.current.sample_count > 2560
    np.testing.assert_array_equal(np.diff(s.encoder.index), 1)
    assert drive.sim_node.state_402 == 0x40


@pytest.mark.parametrize("error, status", [(RuntimeError("listener bug"), "failed"), (KeyboardInterrupt(), "interrupted")])
def test_any_exception_or_ctrl_c_while_recording_quick_stops_and_disables(tmp_path: Path, error: BaseException,
                                                                          status: str) -> None:
    def explode(n: int, drive: CanopenDrive) -> None:
        if n == 2:
            raise error

    result, s, _, drive = _record(tmp_path, _bench(), 30.0, explode)
    assert result.status == status and s.encoder.index.size > 0
    assert any(e.detail == "drive quick-stopped and disabled (SWITCH ON DISABLED)" for e in s.events)
    assert drive.sim_node.state_402 == 0x40


def test_refused_mode_switch_is_a_one_line_device_error() -> None:
    bench = _bench()
    _, _, drive = _parts(bench)
    drive.sim_node.refuse_mode_change = True
    with pytest.raises(DeviceError) as err:
        drive.start()
    assert str(err.value) == (f"CANopen node 1 on virtual:{bench.drive.channel}: the drive refused Profile Position: "
                              "0x6061 mode display is 0, not 1, 0.3 s after writing 0x6060")


@pytest.mark.parametrize("mapping, second", [({"map_velocity": True}, "0x606C"),
                                             ({"map_velocity": False, "map_timestamp": True}, "0x1013")])
def test_mapping_that_reads_back_different_is_refused(mapping: dict[str, bool], second: str) -> None:
    bench = _bench(**mapping)
    _, _, drive = _parts(bench)
    drive.sim_node.reject_mapping = True
    with pytest.raises(DeviceError) as err:
        drive.start()
    assert str(err.value) == (f"CANopen node 1 on virtual:{bench.drive.channel}: TPDO1 read back differs from what "
                              f"was written — wrote [0x6064:00/32, {second}:00/32] type 1 COB-ID 0x181, "
                              "read [0x6041:00/16] type 1 COB-ID 0x40000181")


def test_bus_load_refusal_names_the_figure() -> None:
    # worst-case frame bits: SYNC with counter 65, 8-byte TPDO 135; + heartbeat at 10 Hz, SDO status poll at 100 Hz
    cycle_bits = 65 + 2 * 135
    assert bus_load(500_000, 1 / 4000, [8, 8]) == pytest.approx((cycle_bits * 4000 + 65 * 10 + 2 * 135 * 100) / 500_000)
    settings = DriveCanopen(driver="canopen", period_s=0.00025, bitrate=500_000, map_velocity=True)
    with pytest.raises(ConfigError) as err:
        check_bus_load(settings)
    assert str(err.value) == ("[drive] period_s = 0.00025, bitrate = 500000: CAN bus load 166% > max_bus_load 70% "
                              "(SYNC at 4000 Hz and a TPDO of 8 bytes, worst-case bit stuffing) — raise period_s "
                              "or bitrate")
    assert check_bus_load(DriveCanopen(driver="canopen", period_s=0.001, map_velocity=True)) < 0.3


def test_sync_counter_unwraps_through_wraps_and_long_silences() -> None:
    u = SyncUnwrapper(240, 0.001, first_sync_ns=0)
    assert [u.push(c, ns) for c, ns in ((1, 0), (2, 1_000_000), (240, 239_000_000), (1, 240_000_000))] == [0, 1, 239, 240]
    assert u.push(5, 244_000_000 + 480_000_000) == 244 + 480  # two whole wraps of silence, told by host time


def test_receive_queue_overruns_become_warning_events(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("drivers.canopen_drive.QUEUE_FRAMES", 5)
    _, _, drive = _parts(_bench())
    drive.start()
    try:
        assert _wait_until(lambda: drive._capture.overruns >= 3, 5.0)  # nobody reads: the queue fills up
        overruns = drive._capture.overruns
        drive.read(1.0)
        warnings = [e.detail for e in drive.events() if e.kind == "warning"]
        assert warnings and warnings[0].endswith(" TPDO frames dropped: receive queue full (overrun)")
        assert int(warnings[0].split()[0]) >= overruns
    finally:
        drive.stop()


def test_capture_counts_overruns_and_callback_errors_instead_of_raising() -> None:
    capture = FrameCapture(with_counter=True, max_frames=2)
    capture.on_sync(0x80, bytearray([7]), 0.0)
    for _ in range(3):
        capture.on_tpdo(0x181, bytearray(8), 0.0)
    capture.on_sync(0x80, bytearray(), 0.0)  # a SYNC without its counter byte: logged and counted
    assert (capture.frames.qsize(), capture.overruns, capture.errors) == (2, 1, 1)
    assert capture.frames.get_nowait()[:2] == (7, bytes(8))


def _jittered(bench: Bench, sync_jitter_s: float) -> Bench:
    return bench.model_copy(update={"sim": bench.sim.model_copy(update={"sync_jitter_s": sync_jitter_s})})


def test_timestamp_0x1013_mapped_carries_the_latch_instant_and_the_analysis_uses_it(tmp_path: Path) -> None:
    bench = _jittered(_bench(map_velocity=False, map_timestamp=True), 50e-6)
    result, s, sim, drive = _record(tmp_path, bench, 3.5)
    assert result.status == "complete", result.stop_reason
    node = drive.sim_node.node
    assert [node.sdo[TPDO_MAP][i].raw for i in range(1, node.sdo[TPDO_MAP][0].raw + 1)] == [
        map_entry(POSITION_ACTUAL, 32), map_entry(HIGH_RES_TIMESTAMP, 32)]
    idx, stamps = s.encoder.index, s.encoder.drive_time_s
    latch = sim.latch_times_s(drive.sim_node.first_cycle + int(idx[0]), int(idx[-1] - idx[0]) + 1)[idx - idx[0]]
    np.testing.assert_allclose(stamps, np.round(latch * 1e6) * 1e-6, atol=1e-9)  # the drive's clock, µs
    assert np.std(stamp_deviation_s(idx, stamps, 0.001)) == pytest.approx(50e-6, rel=0.15)
    res = analyze(recording_from_session(s), request_for(s))  # with the bus's real arrival stamps
    for name, tol in (("K_Nm_per_rad", 0.01), ("Jm_kgm2", 0.02), ("Jl_kgm2", 0.02)):
        assert getattr(res.fit.values, name) == pytest.approx(getattr(bench.sim, name), rel=tol), name
    assert res.quality.verdict == "ok", res.quality.reasons
    assert res.quality.encoder_time_stamps and res.quality.encoder_jitter_s < 1e-6


def test_a_drive_without_0x1013_is_refused_when_the_timestamp_is_asked_for() -> None:
    bench = _bench(map_velocity=False, map_timestamp=True)
    _, _, drive = _parts(bench)
    drive.sim_node.has_timestamp = False
    with pytest.raises(DeviceError) as err:
        drive.start()
    assert str(err.value) == (f"CANopen node 1 on virtual:{bench.drive.channel}: the drive has no 0x1013 "
                              "high-resolution time stamp (SDO abort 0x06020000) — set [drive] map_timestamp = false")


def test_position_velocity_and_timestamp_do_not_fit_one_tpdo() -> None:
    settings = {"driver": "canopen", "period_s": 0.001, "map_velocity": True, "map_timestamp": True}
    with pytest.raises(ConfigError) as err:
        validate(DriveCanopen, settings, "bench.toml")
    assert str(err.value) == ("bench.toml: [drive] map_velocity = true and map_timestamp = true need a TPDO of 12 bytes, a CAN "
                              "frame carries 8 — set one of them to false")
    with_stamp = check_bus_load(DriveCanopen(driver="canopen", period_s=0.001, map_timestamp=True))
    assert with_stamp == pytest.approx(bus_load(1_000_000, 0.001, [8]))  # the load counts the 8-byte TPDO


def test_timestamp_unwraps_across_the_32_bit_microsecond_wrap() -> None:
    decoder = TpdoDecoder(SyncUnwrapper(240, 0.001, first_sync_ns=0), False, 1.0, with_timestamp=True)
    stamps_us = [2**32 - 1500, 2**32 - 480, 530, 1470]
    frames = [(c + 1, np.array([100 * c, s], dtype="<u4").tobytes(), c * 1_000_000) for c, s in enumerate(stamps_us)]
    first = decoder.decode(frames[:2])
    second = decoder.decode(frames[2:])
    np.testing.assert_allclose(np.r_[first.drive_time_s, second.drive_time_s] * 1e6,
                               [2**32 - 1500, 2**32 - 480, 2**32 + 530, 2**32 + 1470])
    np.testing.assert_array_equal(second.position_counts, [200, 300])


@pytest.mark.parametrize(("edit", "message"), [
    (("heartbeat_period_s = 0.1", "heartbeat_period_s = 0.5"),
     "[drive] heartbeat_timeout_s = 0.5 must exceed heartbeat_period_s = 0.5"),
    (('interface = "virtual"', 'interface = "socketcan"'),
     "[drive] simulated_node = true needs interface = \"virtual\", not 'socketcan'"),
])
def test_rules_between_drive_keys_name_the_bench_file(tmp_path: Path, edit: tuple[str, str], message: str) -> None:
    text = BENCH_TOML.read_text()
    assert edit[0] in text
    bench = tmp_path / "bench.toml"
    bench.write_text(text.replace(*edit))
    with pytest.raises(ConfigError) as err:
        load_bench(bench)
    assert str(err.value) == f"{bench}: {message}"


def test_a_raw_frame_log_the_disk_refuses_finishes_the_new_session_as_failed_and_releases_the_bus(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The session file exists before the drive's raw log is opened: a disk that refuses the .can.blf (the disk is
    the hardware faked here: the BLF writer's open fails with ENOSPC) leaves no file "recording" nor a bus held."""
    import errno
    import os

    from tests.helpers import run_cli

    def disk_full(path: object, *args: object, **kwargs: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(can, "BLFWriter", disk_full)
    bench = tmp_path / "canopen.toml"
    bench.write_text(BENCH_TOML.read_text().replace('"acq-sim-canopen"', f'"acq-test-{next(_channels)}"'))
    run = run_cli(capsys, "record", "--bench", str(bench), "--profile", "triangle_0.2s", "--duration", "1",
                  "--no-analyze", "--out", str(tmp_path / "s"))
    (session,) = (tmp_path / "s").glob("*.h5")
    blf = session.with_suffix(".can.blf")
    assert run.code == 1
    assert run.err == (f"acq: error: raw frame log not kept: disk full: {blf} (nothing recorded; {session.name} finished "
                       "as failed)\n")
    s = load(session)
    assert (s.status, s.attrs["stop_reason"]) == ("failed", f"raw frame log not kept: disk full: {blf}")
    assert (s.current.sample_count, s.encoder.index.size) == (0, 0)
    assert not blf.exists() and sorted(p.name for p in (tmp_path / "s").iterdir()) == [session.name]
    # the bus was released: the same channel opens again, and a drive there starts (nobody holds its node)
    sim, current, drive = _parts(load_bench(bench))
    assert drive.start().transport == "canopen"
    drive.stop()
