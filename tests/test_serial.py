"""Serial drive adapter: the acq1 codec, resynchronisation, unwrapping, and whole links over a real pty.

The link tests run :class:`drivers.serial_drive.SerialDrive` against
:class:`drivers.sim.serial_device.SimSerialDevice` on a pseudo-terminal, fed by a ramp position
generator whose every value is known, so each received frame can be checked exactly. They wait on
conditions with timeouts, never on sleeps.
"""

from __future__ import annotations

import binascii
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from acq.config import validate
from acq.recording.reader import load
from drivers.config import DriveSerial, Profile
from acqcore.errors import ConfigError, DeviceError
from drivers.serial_codec import Ack, Acq1Codec, Command, StreamParser, Telemetry
from drivers.serial_drive import FrameUnwrapper, LinkStats, SerialDrive
from drivers.sim.serial_device import FaultLog, SimSerialDevice
from tests.helpers import run_cli

CODEC = Acq1Codec()
PERIOD_S = 0.001
START_COUNTS = 2**31 - 9_000  # the int32 register wraps after ~0.24 s of the ramp
COUNTS_PER_CYCLE = 37
SIM_SERIAL = Path(__file__).resolve().parent.parent / "configs" / "benches" / "sim_serial.toml"
PROFILE = Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=0.2, decel_time_s=0.2, dwell_s=0.0,
                  duration_s=10.0)


class Ramp:
    """A frame source with known values: position = START_COUNTS + 37·k counts (unwrapped) at cycle k."""

    drive_period_s = PERIOD_S

    def __init__(self) -> None:
        self.t0_ns = time.monotonic_ns()
        self.motions: list[tuple[str, float]] = []

    def host_ns_at(self, t_s: np.ndarray | float) -> np.ndarray:
        return self.t0_ns + np.round(np.asarray(t_s, dtype=float) * 1e9).astype(np.int64)

    @staticmethod
    def counts(cycles: np.ndarray) -> np.ndarray:
        return START_COUNTS + COUNTS_PER_CYCLE * np.asarray(cycles, dtype=np.int64)

    def encoder_register(self, first_cycle: int, count: int) -> np.ndarray:
        c = self.counts(np.arange(first_cycle, first_cycle + count))
        return ((c + 2**31) % 2**32 - 2**31).astype(np.int32)

    def stamp_times_s(self, first_cycle: int, count: int) -> np.ndarray:
        return np.arange(first_cycle, first_cycle + count) * PERIOD_S

    def start_motion(self, profile: Profile, t_start_s: float) -> float:
        self.motions.append((f"start {profile.top_speed_rpm:g} rpm {profile.accel_time_s:g} s", t_start_s))
        return t_start_s

    def stop_motion(self, t_s: float) -> float | None:
        self.motions.append(("stop", t_s))
        return t_s

    def hold_history(self, consumer: str, from_t_s: float) -> None:
        pass

    def release_history(self, consumer: str) -> None:
        pass


@pytest.fixture()
def link() -> Iterator[tuple[Ramp, SimSerialDevice, SerialDrive]]:
    source = Ramp()
    device = SimSerialDevice(source, CODEC, baud=921_600, seed=3)
    drive = SerialDrive(DriveSerial(driver="serial", period_s=PERIOD_S, port=device.port_name), 131072)
    yield source, device, drive
    drive.stop()
    device.close()


def collect(drive: SerialDrive, last_index: int, timeout_s: float) -> tuple[dict[str, np.ndarray], int]:
    """Read until the frame of ``last_index`` (or a later one) arrived; return the arrays and the empty reads."""
    blocks, empty = [], 0
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        block = drive.read(0.05)
        if block is None:
            empty += 1
            continue
        blocks.append(block)
        if block.index[-1] >= last_index:
            break
    assert blocks, "no frame arrived"
    cat = {k: np.concatenate([getattr(b, k) for b in blocks]) for k in ("index", "position_counts", "drive_time_s")}
    assert cat["index"][-1] >= last_index, f"timed out at index {cat['index'][-1]} waiting for {last_index}"
    return cat, empty


# ---- codec and parser (no port) ----------------------------------------------------------------------
def test_acq1_frame_layout_and_crc16_ccitt_false() -> None:
    assert binascii.crc_hqx(b"123456789", 0xFFFF) == 0x29B1  # the CRC-16/CCITT-FALSE check value
    frame = CODEC.encode(Telemetry(sequence=0x1234, drive_time_us=0x89ABCDEF, position=-2))
    body = bytes.fromhex("0b 01 3412 efcdab89 feffffff")
    assert frame == b"\xa5\x5a" + body + binascii.crc_hqx(body, 0xFFFF).to_bytes(2, "big")
    assert len(frame) == CODEC.telemetry_bytes == 16


@pytest.mark.parametrize("frame", [
    Telemetry(65535, 2**32 - 1, -2**31), Telemetry(0, 0, 2**31 - 1), Command("stream_on"), Command("stream_off"),
    Command("stop_motion"), Command("start_triangle", PROFILE), Ack("start_triangle"), Ack("stream_on", 3),
])
def test_every_frame_type_round_trips(frame: object) -> None:
    assert StreamParser(CODEC).feed(CODEC.encode(frame)) == [frame]  # type: ignore[arg-type]


def test_parser_recovers_every_good_frame_from_garbage_and_corruption_fed_in_any_chunks() -> None:
    good = [Telemetry(k, 1000 * k, 5 - 3 * k) for k in range(40)]
    wire = [CODEC.encode(f) for f in good]
    bad = bytearray(wire[10])
    bad[7] ^= 0x10  # one payload bit: a CRC error
    stream = (b"\x00\x13\xff" + b"".join(wire[:10]) + bytes(bad) + b"".join(wire[11:20])
              + b"\xa5\x5a\x30" + b"".join(wire[20:30])  # false header of a 53-byte frame: a CRC error
              + b"\xa5\x5a\xf0" + b"".join(wire[30:]))   # false header of a 245-byte frame: a bad header
    rng = np.random.default_rng(1)
    for chunk in (1, 7, None):
        parser = StreamParser(CODEC)
        cuts = np.cumsum(rng.integers(1, 40, len(stream))) if chunk is None else np.arange(chunk, len(stream), chunk)
        got = [f for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(stream)]) for f in parser.feed(stream[a:b])]
        assert got == good[:10] + good[11:]
        s = parser.stats
        assert (s.crc_errors, s.bad_headers, s.resyncs, s.bytes_skipped) == (2, 1, 4, 3 + 16 + 3 + 3)


def test_unwrapper_carries_sequence_time_and_position_across_their_wraps() -> None:
    u = FrameUnwrapper(period_us=1000.0)
    assert u.push(Telemetry(65534, 2**32 - 1500, 2**31 - 10)) == 0
    assert u.push(Telemetry(65535, 2**32 - 500, 2**31 - 1)) == 0
    assert u.push(Telemetry(1, 1500, -2**31 + 20)) == 1  # sequence and drive time wrapped, one frame lost
    assert (u.index, u.time_us, u.position) == (65537, 2**32 + 1500, 2**31 + 20)
    assert u.push(Telemetry(2 + 5, 1500 + (65536 + 6) * 1000, 0)) == 65536 + 5  # a silence longer than the u16


def test_baud_below_the_frame_rate_is_refused_with_the_required_rate() -> None:
    with pytest.raises(ConfigError) as e:
        validate(DriveSerial, {"driver": "serial", "period_s": 0.001, "port": "loop://", "baud": 115_200, "parity": "E"},
                 "bench.toml")
    assert str(e.value) == ("bench.toml: [drive] baud = 115200: too low for one 16-byte acq1 frame every 0.001 s; needs at least "
                            "176000 baud (16 bytes × 11 bits / 0.001 s)")


# ---- whole links over the pty --------------------------------------------------------------------------
def test_five_seconds_at_1khz_over_a_pty_lose_no_frame_and_carry_the_motion_commands(
        link: tuple[Ramp, SimSerialDevice, SerialDrive]) -> None:
    source, device, drive = link
    info = drive.start()
    assert (info.transport, info.period_s) == ("serial", PERIOD_S)
    drive.start_motion(PROFILE)
    first = device.next_cycle()
    got, _ = collect(drive, first + 5000, timeout_s=10.0)
    drive.stop_motion()
    idx = got["index"]
    k0 = int(idx[0])
    assert np.array_equal(idx, np.arange(k0, k0 + idx.size)) and idx.size >= 5000
    assert np.array_equal(got["position_counts"], Ramp.counts(idx))  # unwrapped through the int32 wrap
    assert got["position_counts"][-1] > 2**31
    np.testing.assert_allclose(got["drive_time_s"], idx * PERIOD_S, atol=1e-9)
    stats = drive.stats()
    assert (stats.crc_errors, stats.bad_headers, stats.resyncs, stats.gaps, stats.bytes_skipped) == (0, 0, 0, 0, 0)
    (start, t_start), (stop, t_stop) = source.motions
    assert start == "start 1000 rpm 0.2 s" and stop == "stop"
    assert t_start == pytest.approx(first * PERIOD_S + 0.2, abs=0.02) and t_stop > t_start


def test_injected_faults_are_counted_each_in_its_category_and_no_good_frame_is_lost(
        link: tuple[Ramp, SimSerialDevice, SerialDrive]) -> None:
    _, device, drive = link
    drive.start()
    k = device.next_cycle() + 100
    garbage, flipped, dropped = [k, k + 100, k + 200], [k + 300, k + 400, k + 500], [k + 600, *range(k + 700, k + 703)]
    for c in garbage:
        device.inject_garbage(c, 40)
    for c in flipped:
        device.flip_bit(c)
    device.drop_frames(dropped)
    device.inject_bytes(k + 800, b"\xa5\x5a\x30")  # plausible length: waits, fails its CRC
    device.inject_bytes(k + 900, b"\xa5\x5a\xf0")  # impossible length: a bad header at once
    device.pause(k + 1000, 0.2)
    last = k + 1200
    got, empty_reads = collect(drive, last, timeout_s=5.0)
    idx = got["index"]
    lost = set(flipped) | set(dropped)
    expected = np.array([c for c in range(int(idx[0]), last + 1) if c not in lost])
    assert np.array_equal(idx[:expected.size], expected)
    assert np.array_equal(got["position_counts"], Ramp.counts(idx))
    assert empty_reads >= 2  # the 0.2 s pause: reads time out, then the held frames arrive
    assert device.log == FaultLog(garbage_bytes=40 * 3 + 3 + 3, garbage_bursts=5, flipped_frames=3, dropped_frames=4,
                                  pauses=1)
    stats = drive.stats()
    assert stats.frames >= idx.size  # the reader keeps reading after collect() returned
    assert replace(stats, frames=0, bytes_received=0) == LinkStats(
        frames=0, crc_errors=len(flipped) + 1, bad_headers=1, resyncs=len(garbage) + len(flipped) + 2,
        bytes_skipped=40 * len(garbage) + 16 * len(flipped) + 3 + 3, gaps=len(flipped) + 2,
        frames_missing=len(flipped) + 4, bytes_received=0)
    gaps = [e.detail for e in drive.events() if e.kind == "gap"]
    assert gaps[-1] == f"serial sequence gap: 3 frame(s) missing before index {k + 703}"
    assert len(gaps) == len(flipped) + 2


def test_a_device_that_vanishes_mid_stream_ends_reads_with_one_device_error(
        link: tuple[Ramp, SimSerialDevice, SerialDrive]) -> None:
    _, device, drive = link
    drive.start()
    collect(drive, device.next_cycle() + 20, timeout_s=2.0)
    device.close()  # the far end of the pty is gone, as when a USB adapter is pulled
    deadline = time.monotonic() + 2.0
    with pytest.raises(DeviceError, match=rf"^serial port {device.port_name}: link lost: "):
        while time.monotonic() < deadline:
            drive.read(0.05)
    assert [e.kind for e in drive.events() if e.kind == "error"] == ["error"]


def test_a_missing_port_is_one_line_and_exit_code_1(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    bench = tmp_path / "lab_serial.toml"
    bench.write_text(SIM_SERIAL.read_text().replace('port = "/dev/ttyUSB0"', 'port = "/dev/ttyACQ_gone"')
                     .replace("simulated_device = true", "simulated_device = false")
                     + "\n[limits]\nmax_speed_rpm = 1200.0\nmax_travel_deg = 135.0\nmax_torque_Nm = 20.0\n")
    run = run_cli(capsys, "record", "--bench", str(bench), "--profile", "triangle_0.2s", "--out", str(tmp_path))
    assert run.code == 1
    assert run.err == "acq: error: serial port /dev/ttyACQ_gone: no such device (is the drive connected and powered?)\n"
    assert not list(tmp_path.glob("*.h5"))


def test_a_baud_too_low_in_the_bench_is_refused_by_acq_record(capsys: pytest.CaptureFixture[str],
                                                              tmp_path: Path) -> None:
    bench = tmp_path / "slow.toml"
    bench.write_text(SIM_SERIAL.read_text().replace("baud = 921600", "baud = 115200"))
    run = run_cli(capsys, "record", "--bench", str(bench), "--profile", "triangle_0.2s", "--out", str(tmp_path))
    assert run.code == 2
    assert run.err == (f"acq: error: {bench}: [drive] baud = 115200: too low for one 16-byte acq1 frame every 0.001 s; "
                       "needs at least 160000 baud (16 bytes × 10 bits / 0.001 s)\n")


def test_acq_record_over_the_pty_stores_every_frame_of_the_simulated_bench(capsys: pytest.CaptureFixture[str],
                                                                           tmp_path: Path) -> None:
    run = run_cli(capsys, "record", "--bench", str(SIM_SERIAL), "--profile", "triangle_0.2s", "--duration", "1",
                  "--fast", "--no-analyze", "--out", str(tmp_path))
    assert run.code == 0, run.err
    (path,) = tmp_path.glob("*.h5")
    session = load(path)
    enc = session.encoder
    assert (session.status, enc.transport) == ("complete", "serial")
    assert np.array_equal(enc.index, np.arange(enc.index[0], enc.index[0] + enc.index.size)) and enc.index.size >= 1000
    np.testing.assert_allclose(enc.drive_time_s, enc.index * PERIOD_S, atol=1e-9)
    assert [e.kind for e in session.events if e.stream == "drive"] == ["info"]  # the link's closing counters
