"""Speed dither: each full cycle of the triangle at its own factor s_c ∈ [1 − d, 1 + d], on every drive.

The reference's cycles follow the drawn factors and return to their start; on the simulated bench at 2^17
counts/rev the dither breaks the lock between the encoder's quantisation and the periodic motion; the
simulated CANopen drive (real SDO traffic on a python-can ``virtual`` bus, checked in the raw .blf log) and
the serial drive (acq1 frames over a real pty) run the same factors; a recording keeps the seed it used.
"""

from __future__ import annotations

import itertools
import json
import struct
import tomllib
from pathlib import Path

import can
import numpy as np
import pytest
from scipy.signal import find_peaks

from acq.config import load_bench, load_profile
from acq.recording.recorder import Recorder
from acq.recording.reader import load
from drivers.config import Profile
from drivers.motion import (RPM_TO_RAD_S, half_swing_rad, speed_factors, triangle_accel_rad_s2, triangle_speed_rad_s,
                            with_dither_seed)
from drivers.serial_codec import MAX_FRAME_BYTES, Acq1Codec, Command, StreamParser
from drivers.sim.bench import SimBench
from drivers.sim.daq import open_current_source
from drivers.sim.peers import open_canopen_with_sim_node
from tests.helpers import run_cli

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
PAPER = Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=0.2, decel_time_s=0.2, duration_s=10.0)
CPR = 131072
_channels = itertools.count()


def dithered(d: float = 0.02, seed: int | None = 7, **changes: object) -> Profile:
    return Profile.model_validate({**PAPER.model_dump(), "speed_dither": d, "dither_seed": seed if d else None,
                                   **changes})


def cycle_swings(position_counts: np.ndarray, nominal_counts: float) -> np.ndarray:
    """Each complete cycle's swing (peak − the start before it), in units of the nominal swing. The first
    sample is at rest at the start; a peak is a maximum standing out by more than half the nominal swing."""
    peaks, _ = find_peaks(position_counts, prominence=nominal_counts / 2)
    return (position_counts[peaks] - position_counts[0]) / nominal_counts


# ---- the reference --------------------------------------------------------------------------------------
@pytest.mark.parametrize("changes", [{}, {"cruise_s": 0.05, "dwell_s": 0.1, "decel_time_s": 0.3}])
def test_each_cycle_of_the_reference_runs_at_its_factor_and_ends_at_its_start(changes: dict[str, float]) -> None:
    p = dithered(0.05, 11, **changes)
    half = p.accel_time_s + p.cruise_s + p.decel_time_s + p.dwell_s
    dt = 1e-4  # divides every corner time: the trapezoid rule is exact on this piecewise-linear speed
    t = np.arange(0.0, 24 * half + dt / 2, dt)
    v = triangle_speed_rad_s(t, p)
    theta = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 * dt)])
    s = speed_factors(p, np.arange(12))
    np.testing.assert_array_equal(s, np.random.default_rng(11).uniform(0.95, 1.05, 12))
    per_half = np.round(np.arange(0, 25) * half / dt).astype(int)
    swings = np.diff(theta[per_half])
    np.testing.assert_allclose(swings[0::2], s * half_swing_rad(p), rtol=1e-9)   # out at s_c …
    np.testing.assert_allclose(swings[1::2], -s * half_swing_rad(p), rtol=1e-9)  # … and back by as much
    np.testing.assert_allclose(theta[per_half[0::2]], 0.0, atol=1e-9)             # every cycle ends at the start
    top = p.top_speed_rpm * RPM_TO_RAD_S
    peak = np.array([v[i:j].max() for i, j in zip(per_half[0::2], per_half[1::2])])
    np.testing.assert_allclose(peak, s * top, rtol=1e-12)
    acc = triangle_accel_rad_s2(t[per_half[0::2][:-1]] + p.accel_time_s / 2, p)
    np.testing.assert_allclose(acc, s * top / p.accel_time_s, rtol=1e-12)       # the ramp times stay


def test_undithered_profile_and_seed_handling() -> None:
    t = np.linspace(0, 5, 5001)
    np.testing.assert_array_equal(triangle_speed_rad_s(t, PAPER),
                                  triangle_speed_rad_s(t, PAPER.model_copy(update={"dither_seed": 3})))
    assert with_dither_seed(PAPER) is PAPER
    seeded = dithered(seed=5)
    assert with_dither_seed(seeded) is seeded
    drawn = {with_dither_seed(dithered(seed=None)).dither_seed for _ in range(3)}
    assert len(drawn) == 3 and all(0 <= x < 2**63 for x in drawn)
    with pytest.raises(ValueError, match="needs its dither_seed"):
        speed_factors(dithered(seed=None), np.arange(3))
    assert (dithered(0.04).max_speed_factor, dithered(0.04).min_speed_factor) == (1.04, 0.96)


@pytest.mark.parametrize(("edit", "message"), [
    ("speed_dither = 0.02", "speed_dither = 0.06: must be less than or equal to 0.05"),
    ("dwell_s = 0", "dither_seed = -1: must be greater than or equal to 0"),
    ("top_speed_rpm = 1000", "top_speed_rpm = 99000 with speed_dither = 0.02: the fastest cycle would run at 100980 rpm, "
                             "above 100000 rpm"),
    ("duration_s = 10", "dither_seed = 5 without speed_dither: the seed only chooses the cycles of a dithered motion "
                        "(speed_dither = 0, the default, repeats exactly) — set speed_dither (e.g. 0.02) or remove "
                        "dither_seed"),
])
def test_a_bad_dither_is_one_line_naming_the_file_key_and_value(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                edit: str, message: str) -> None:
    text = (CONFIGS / "profiles" / "triangle_0.2s.toml").read_text()
    new = {"speed_dither = 0.02": "speed_dither = 0.06", "dwell_s = 0": "dwell_s = 0\ndither_seed = -1",
           "top_speed_rpm = 1000": "top_speed_rpm = 99000",
           "duration_s = 10": "duration_s = 10\ndither_seed = 5"}[edit]
    path = tmp_path / "p.toml"
    text = text.replace(edit, new, 1)
    path.write_text(text.replace("speed_dither = 0.02", "speed_dither = 0") if "dither_seed = 5" in text else text)
    run = run_cli(capsys, "record", "--profile", str(path), "--fast", "--out", str(tmp_path))
    assert (run.code, run.err) == (2, f"acq: error: {path}: {message}\n")
    assert not list(tmp_path.glob("*.h5"))


def test_the_shipped_profiles_are_the_papers_triangles_at_two_percent_dither() -> None:
    with (CONFIGS / "profiles" / "triangle_0.2s.toml").open("rb") as f:
        raw = tomllib.load(f)
    p = load_profile("triangle_0.2s")
    assert (p.top_speed_rpm, p.accel_time_s, p.decel_time_s, p.dwell_s, p.cruise_s, p.jerk_time_s) == \
        (1000, 0.2, 0.2, 0, 0, 0)
    assert (p.speed_dither, p.dither_seed, "dither_seed" in raw) == (0.02, None, False)
    slow = load_profile("triangle_0.5s")
    assert (slow.accel_time_s, slow.speed_dither, slow.dither_seed) == (0.5, 0.02, None)


# ---- the simulated bench: the quantisation lock and its break ---------------------------------------------
def test_dither_breaks_the_lock_between_encoder_quantisation_and_the_motion_period() -> None:
    """Encoder counts one motion period (0.8 s = 800 drive cycles) apart, after the first cycle's transient; and the
    quantisation error (counts − true angle) averaged over 11 periods at the same phase of the motion."""
    bench = load_bench()
    assert bench.encoder.counts_per_rev == CPR
    diffs, averaged = {}, {}
    for d in (0.0, 0.02):
        sim = SimBench(bench, realtime=False, keep_history=True)
        sim.start_motion(dithered(d, seed=7), 0.0)
        counts = sim.encoder_counts(0, 10_000).astype(np.int64)
        diffs[d] = np.abs(counts[800:] - counts[:-800])[1000:]
        theta = sim.true_state_at(np.arange(10_000) * bench.drive.period_s)["theta_m_rad"] * CPR / (2 * np.pi)
        error = (counts - counts[0]) - (theta - theta[0])
        periods = error[800:800 + 11 * 800].reshape(11, 800)
        averaged[d] = (periods - periods.mean()).mean(axis=0).std() / (error.std() / np.sqrt(11))  # 1: like white noise
    # Undithered: the same count at the same phase of the motion in 98 % of the samples, never more than 1 count off
    # (measured; the reference counts its phase in whole nanoseconds, as a drive counts cycles — with the phase in
    # floating point an instant at the apex fell on either side of it in different periods, 86 % and 44 counts):
    # the lock. The quantisation error hardly averages: its 11-period mean keeps 3.1× what white noise would.
    assert np.median(diffs[0.0]) == 0 and np.mean(diffs[0.0] == 0) > 0.95 and diffs[0.0].max() <= 1
    assert averaged[0.0] > 2.0
    # Dithered by 2 %: the positions at the same phase differ by thousands of counts (measured median 1127) and the
    # quantisation error averages like white noise (measured 0.99 of the white figure)
    assert np.median(diffs[0.02]) > 20 and np.mean(diffs[0.02] == 0) < 0.02 and 0.85 < averaged[0.02] < 1.15


def test_a_fast_recording_keeps_the_seed_its_simulated_drive_used(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--fast", "--duration", "3", "--no-analyze",
                  "--out", str(tmp_path))
    assert run.code == 0, run.err
    (path,) = tmp_path.glob("*.h5")
    session = load(path)
    p = session.profile
    assert p.speed_dither == 0.02 and isinstance(p.dither_seed, int)
    swings = cycle_swings(session.encoder.position_counts, half_swing_rad(p) / (2 * np.pi) * CPR)
    assert swings.size >= 3
    np.testing.assert_allclose(swings, speed_factors(p, np.arange(swings.size)), atol=1e-3)  # the loop lags ~4e-4
    # a user finds the seed to repeat the motion with: acq info (table and --json)
    info = run_cli(capsys, "info", str(path))
    assert f"motion: speed dither ±2 % per cycle, dither_seed {p.dither_seed}" in [
        line.strip() for line in info.out.splitlines()]
    doc = json.loads(run_cli(capsys, "info", str(path), "--json").out)
    assert (doc["commanded"], doc["speed_dither"], doc["dither_seed"]) == (True, 0.02, p.dither_seed)


# ---- CANopen: Profile Position on the simulated drive, checked on the wire ------------------------------
def sdo_downloads(blf: Path, node_id: int) -> list[tuple[int, int]]:
    """(index, value) of every expedited 4-byte SDO download to ``node_id`` in the raw CAN log, in order."""
    writes = []
    for msg in can.BLFReader(blf):
        if msg.arbitration_id == 0x600 + node_id and msg.data[0] == 0x23:
            index, value = struct.unpack_from("<H", msg.data, 1)[0], struct.unpack_from("<i", msg.data, 4)[0]
            writes.append((index, value))
    return writes


def test_canopen_profile_position_runs_each_cycle_at_its_factor_and_targets_the_start_exactly(tmp_path: Path) -> None:
    bench = load_bench(CONFIGS / "benches" / "sim_canopen.toml")
    drive_settings = bench.drive.model_copy(update={"channel": f"acq-dither-{next(_channels)}", "state_timeout_s": 0.3})
    bench = bench.model_copy(update={"drive": drive_settings})
    p = dithered(0.02, seed=2024)
    sim = SimBench(bench, realtime=True, keep_history=True)
    current, drive = open_current_source(bench, sim, False), open_canopen_with_sim_node(bench, sim, False)
    result = Recorder(bench, p, current, drive, tmp_path, 2.6).run()
    assert result.status == "complete", result.stop_reason
    session = load(result.path)
    assert session.profile == p
    writes = sdo_downloads(result.path.with_suffix(".can.blf"), drive_settings.node_id)
    targets = [v for i, v in writes if i == 0x607A]
    swing = round(half_swing_rad(p) / (2 * np.pi) * CPR)
    s = speed_factors(p, np.arange(len(targets) // 2))
    assert len(targets) >= 6
    p0 = targets[1]
    assert targets[1::2] == [p0] * len(targets[1::2])  # every cycle returns exactly to the start
    assert targets[0::2] == [p0 + round(x * swing) for x in s[:len(targets[0::2])]]
    ramps = [v for i, v in writes if i in (0x6081, 0x6083, 0x6084)]
    units = drive_settings.velocity_units_per_rpm, drive_settings.acceleration_units_per_rpm_per_s
    expected = [round(x * 1000.0 * k) for x in s for k in (units[0], units[1] / 0.2, units[1] / 0.2)]
    assert ramps[:len(expected)] == expected[:len(ramps)] and len(ramps) >= 3 * (len(targets) // 2)
    swings = cycle_swings(session.encoder.position_counts, swing)
    assert swings.size >= 2
    np.testing.assert_allclose(swings, s[:swings.size], atol=1e-3)


# ---- serial: the start_triangle frame carries d and the seed; the device over a pty runs them ------------
def test_start_triangle_carries_dither_and_seed_and_still_fits_a_frame() -> None:
    codec = Acq1Codec()
    plain = codec.encode(Command("start_triangle", PAPER))
    assert len(plain) == 2 + 1 + 1 + 20 + 2  # the undithered frame keeps its layout
    cmd = Command("start_triangle", dithered(0.0125, seed=2**63 - 1))
    wire = codec.encode(cmd)
    assert len(wire) == 2 + 1 + 1 + 32 + 2 <= MAX_FRAME_BYTES
    assert StreamParser(codec).feed(wire) == [cmd]
    with pytest.raises(ValueError, match="needs its dither_seed"):
        codec.encode(Command("start_triangle", dithered(seed=None)))


def test_serial_drive_over_a_pty_runs_each_cycle_at_its_factor(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    profile = tmp_path / "dither.toml"
    profile.write_text((CONFIGS / "profiles" / "triangle_0.2s.toml").read_text() + "dither_seed = 3\n")
    run = run_cli(capsys, "record", "--bench", str(CONFIGS / "benches" / "sim_serial.toml"), "--profile", str(profile),
                  "--duration", "3", "--fast", "--no-analyze", "--out", str(tmp_path))
    assert run.code == 0, run.err
    (path,) = tmp_path.glob("*.h5")
    session = load(path)
    assert (session.encoder.transport, session.profile.dither_seed) == ("serial", 3)
    nominal = half_swing_rad(session.profile) / (2 * np.pi) * CPR
    swings = cycle_swings(session.encoder.position_counts, nominal)
    s = speed_factors(session.profile, np.arange(swings.size))
    assert swings.size >= 3 and np.ptp(s) > 0.02  # seed 3: factors far enough apart for the check to see them
    np.testing.assert_allclose(swings, s, atol=1e-3)


# ---- the scenario family can run a dithered motion ---------------------------------------------------------
def test_a_scenario_runs_the_shipped_dithered_profile_with_the_runs_seed_unless_it_says_otherwise() -> None:
    from bench.scenarios import SCENARIOS, Scenario, scenario_bench

    _, p = scenario_bench(Scenario("dithered", profile={"speed_dither": 0.02}), 5, 0.01, 20.0)
    assert (p.speed_dither, p.dither_seed) == (0.02, 5)
    _, p = scenario_bench(Scenario("dithered", profile={"speed_dither": 0.02, "dither_seed": 8}), 5, 0.01, 20.0)
    assert p.dither_seed == 8
    assert all((scenario_bench(sc, 3, 0.01, 20.0)[1].speed_dither, scenario_bench(sc, 3, 0.01, 20.0)[1].dither_seed)
               == (0.02, 3) for sc in SCENARIOS)
    _, p = scenario_bench(Scenario("undithered", profile={"speed_dither": 0.0}), 5, 0.01, 20.0)
    assert p.speed_dither == 0.0


def test_a_drive_that_refuses_or_ignores_a_dithered_start_is_told_what_to_change() -> None:
    from drivers.serial_codec import Command
    from drivers.serial_drive import _dither_hint

    assert _dither_hint(Command("start_triangle", dithered(0.02, seed=3))) == (
        " — the profile dithers (speed_dither = 0.02): a drive firmware that predates the dithered start_triangle "
        "frame refuses it; set speed_dither = 0 in the profile or update the firmware")
    assert _dither_hint(Command("start_triangle", dithered(0.0))) == ""
    assert _dither_hint(Command("stream_on")) == ""
