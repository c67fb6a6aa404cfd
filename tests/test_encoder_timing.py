"""Encoder sample-instant timing (issue 13 item 3): a drive that latches its position when SYNC arrives.

* the simulated drive latches at k·T + δ_k, δ_k ~ N(0, sync_jitter_s), and stamps that instant;
* without time stamps the analysis estimates σ_δ from the position noise growing with |ω| (within
  ±30 % of the realised jitter) and the verdict names it where it costs the FRF;
* with the drive's time stamps (sim transport, serial frame drive time; CANopen 0x1013 in
  tests/test_canopen.py) K is within 1 %, J_m and J_l within 2 %, verdict ok;
* without jitter nothing changes.
"""

from __future__ import annotations

import tomllib
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from acq.offline.analyze import request_for, recording_from_session, result_json, simulated_truth
from acq.recording.reader import load
from analysis import AnalysisRequest, analyze
from analysis.sample_instants import angle_at_nominal_instants, estimate_jitter, stamp_deviation_s
from drivers.config import Bench, Profile
from drivers.sim.bench import LATCH_CLIP, SimBench
from tests.helpers import run_cli, seeded_profile
from tests.test_analysis_pipeline import SIM_TOML, sim_recording

CONFIGS = Path(__file__).parents[1] / "configs" / "benches"
NAMES = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2")
JITTER_REASON = "the drive samples at SYNC arrival with ≈ "
ADVICE = "use a hardware SYNC or map the drive's time stamp (0x1013, [drive] map_timestamp = true)"


def _errors_pct(values: object, truth: dict) -> dict[str, float]:
    return {n: 100.0 * (getattr(values, n) / truth[n] - 1.0) for n in NAMES}


def _sim_bench(*, keep_history: bool = False, **sim: object) -> SimBench:
    with SIM_TOML.open("rb") as f:
        bench = Bench.model_validate(tomllib.load(f))
    return SimBench(bench.model_copy(update={"sim": bench.sim.model_copy(update=sim)}), realtime=False,
                    keep_history=keep_history)


def _realised_jitter_s(seed: int, sync_jitter_s: float, count: int) -> tuple[np.ndarray, float]:
    """The simulated latch instants of cycles 0… (as :func:`sim_recording` has them) and their RMS
    deviation from k·T, s."""
    sim = _sim_bench(seed=seed, sync_jitter_s=sync_jitter_s)
    latch = sim.latch_times_s(0, count)
    return latch, float(np.sqrt(np.mean((latch - np.arange(count) * sim.drive_period_s) ** 2)))


def test_the_simulated_drive_latches_at_sync_arrival_and_stamps_that_instant() -> None:
    sim = _sim_bench(keep_history=True, seed=4, sync_jitter_s=200e-6)
    sim.start_motion(Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=0.2, decel_time_s=0.2,
                             duration_s=3.0), 0.0)
    latch = sim.latch_times_s(0, 3000)
    dev = latch - np.arange(3000) * 1e-3
    assert np.sqrt(np.mean(dev**2)) == pytest.approx(200e-6, rel=0.1)
    assert np.max(np.abs(dev)) <= LATCH_CLIP * 1e-3 + 1e-12  # SYNCs arrive in order
    assert abs(np.mean(dev)) < 10e-6 and abs(np.corrcoef(dev[1:], dev[:-1])[0, 1]) < 0.05  # white, zero mean
    counts = sim.encoder_counts(0, 3000)  # the position at the latch instant, not at k·T
    theta = sim.true_state_at(latch)["theta_m_rad"]
    np.testing.assert_array_equal(counts, np.floor(theta / (2 * np.pi) * sim.counts_per_rev).astype(np.int64))
    np.testing.assert_array_equal(sim.stamp_times_s(0, 3000), latch)
    unstamped = _sim_bench(sync_jitter_s=200e-6, drive_time_stamps=False)
    np.testing.assert_array_equal(unstamped.stamp_times_s(5, 10), np.arange(5, 15) * 1e-3)
    np.testing.assert_array_equal(_sim_bench().latch_times_s(5, 10), np.arange(5, 15) * 1e-3)


def test_stamp_deviation_ignores_offset_rate_and_microsecond_quantisation() -> None:
    rng = np.random.default_rng(1)
    k = np.arange(5000) + 123
    dev = rng.normal(0.0, 30e-6, k.size)
    stamps = np.round((17.25 + k * 1e-3 * (1 + 80e-6) + dev) * 1e6) * 1e-6  # other origin, 80 ppm, 1 µs steps
    got = stamp_deviation_s(k, stamps, 1e-3)
    assert np.sqrt(np.mean((got - (dev - dev.mean())) ** 2)) < 0.35e-6  # 1 µs quantisation: 0.29 µs RMS
    assert stamp_deviation_s(k, np.where(k == 2000, stamps + 0.6e-3, stamps), 1e-3) is None  # not a jitter
    assert stamp_deviation_s(k, np.where(k == 2000, np.nan, stamps), 1e-3) is None


def test_a_sample_moved_to_its_nominal_instant_is_the_angle_there() -> None:
    t = np.arange(2000) * 1e-3
    dev = np.random.default_rng(2).normal(0.0, 100e-6, t.size)
    theta = lambda x: 50.0 * x + 3.0 * np.sin(2 * np.pi * 40.0 * x)  # noqa: E731 - rad, 50 rad/s + 40 Hz swing
    moved = angle_at_nominal_instants(theta(t + dev), np.arange(t.size), 1e-3, dev)
    assert np.max(np.abs(moved - theta(t))[5:-5]) < 1e-4 < np.max(np.abs(theta(t + dev) - theta(t)))


@pytest.mark.parametrize("jitter_s", [20e-6, 50e-6, 200e-6])
def test_without_time_stamps_the_jitter_is_estimated_and_named_in_the_verdict(jitter_s: float) -> None:
    rec, truth, nominal = sim_recording(duration_s=4.0, seed=7, sync_jitter_s=jitter_s)
    _, realised = _realised_jitter_s(7, jitter_s, rec.encoder_index.size)
    res = analyze(rec, AnalysisRequest(nominal=nominal))
    assert res.quality.encoder_jitter_s == pytest.approx(realised, rel=0.3)
    assert not res.quality.encoder_time_stamps
    assert res.quality.verdict == "failed"  # at 1000 rpm 20 µs and more wreck the speed spectrum
    first = res.quality.reasons[0]
    assert first.startswith(f"{JITTER_REASON}{1e6 * res.quality.encoder_jitter_s:.0f} µs jitter (coherence ")
    assert first.endswith(ADVICE)


@pytest.mark.parametrize("jitter_s", [20e-6, 200e-6])
def test_with_the_drives_time_stamps_the_identification_is_accurate_and_ok(jitter_s: float) -> None:
    rec, truth, nominal = sim_recording(duration_s=4.0, seed=8, sync_jitter_s=jitter_s)
    latch, _ = _realised_jitter_s(8, jitter_s, rec.encoder_index.size)
    stamps = np.round((latch + 42.5) * 1e6) * 1e-6  # the drive's own origin, 1 µs resolution
    res = analyze(replace(rec, drive_time_s=stamps), AnalysisRequest(nominal=nominal))
    err = _errors_pct(res.fit.values, truth)
    assert abs(err["K_Nm_per_rad"]) <= 1.0 and abs(err["Jm_kgm2"]) <= 2.0 and abs(err["Jl_kgm2"]) <= 2.0, err
    assert res.quality.verdict == "ok", res.quality.reasons
    assert res.quality.encoder_time_stamps and res.quality.encoder_jitter_s < 1e-6  # what remains: quantisation


def test_without_jitter_time_stamps_and_the_estimate_change_nothing() -> None:
    rec, truth, nominal = sim_recording(duration_s=4.0, seed=9)
    plain = analyze(rec, AnalysisRequest(nominal=nominal))
    on_grid = rec.encoder_index * rec.period_s + 5.0  # stamps of a drive without jitter, its own origin
    stamped = analyze(replace(rec, drive_time_s=on_grid), AnalysisRequest(nominal=nominal))
    for name in (*NAMES, "C_Nms_per_rad"):
        assert getattr(stamped.fit.values, name) == getattr(plain.fit.values, name)
    assert plain.quality.verdict == stamped.quality.verdict == "ok"
    assert plain.quality.encoder_jitter_s < 0.5e-6


def test_jitter_estimate_on_an_angle_without_motion_noise_is_the_truth() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(20_000) * 1e-3
    speed = 100.0 * np.sin(2 * np.pi * 0.5 * t)  # rad/s
    theta = lambda x: -100.0 / (np.pi) * np.cos(np.pi * x)  # noqa: E731 - its integral, rad
    lsb = 2 * np.pi / 10_000
    sampled = np.floor(theta(t + rng.normal(0.0, 40e-6, t.size)) / lsb) * lsb
    got = estimate_jitter(sampled, 1e-3)
    assert got.sigma_s == pytest.approx(40e-6, rel=0.1)
    assert got.mean_speed2 == pytest.approx(np.mean(speed**2), rel=0.01)


def test_a_joint_at_rest_gives_no_jitter_estimate_and_no_warning() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a standstill made 1/0 weights and a LAPACK error (robot pauses)
        got = estimate_jitter(np.full(20_000, 1.2345), 1e-3)
    assert np.isnan(got.sigma_s) and got.mean_speed2 == 0.0


def _bench_file(tmp_path: Path, source: str, **sim: object) -> Path:
    text = (CONFIGS / source).read_text()
    assert text.rstrip().splitlines()[-1].strip() and "\n[sim]" in text and text.rindex("\n[") == text.index("\n[sim]")
    path = tmp_path / source
    path.write_text(text + "".join(f"{k} = {str(v).lower() if isinstance(v, bool) else v}\n" for k, v in sim.items()))
    return path


@pytest.mark.parametrize("source", ["sim.toml", "sim_serial.toml"])
def test_recorded_sessions_carry_the_drive_time_and_analyse_on_it(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                                   source: str) -> None:
    bench = _bench_file(tmp_path, source, sync_jitter_s=100e-6)
    run = run_cli(capsys, "record", "--bench", str(bench), "--profile", str(seeded_profile(bench.parent)),
                  "--duration", "4", "--fast", "--no-analyze", "--out", str(tmp_path))
    assert run.code == 0, run.err
    (path,) = tmp_path.glob("*.h5")
    session = load(path)
    enc = session.encoder
    dev = stamp_deviation_s(enc.index, enc.drive_time_s, enc.period_s)
    assert np.sqrt(np.mean(dev**2)) == pytest.approx(100e-6, rel=0.15)
    res = analyze(recording_from_session(session), request_for(session))  # with the pty's real arrival stamps
    err = _errors_pct(res.fit.values, simulated_truth(session))
    assert abs(err["K_Nm_per_rad"]) <= 1.0 and abs(err["Jm_kgm2"]) <= 2.0 and abs(err["Jl_kgm2"]) <= 2.0, err
    assert res.quality.verdict == "ok", res.quality.reasons
    assert res.quality.encoder_time_stamps and res.quality.encoder_jitter_s < 1e-6
    doc = result_json(session, res)["quality"]
    assert doc["encoder_time_stamps"] is True and doc["encoder_jitter_us"] == pytest.approx(1e6 * res.quality.encoder_jitter_s)


def test_coarse_stamps_that_would_add_noise_are_ignored_with_a_note() -> None:
    rec, truth, nominal = sim_recording(duration_s=4.0, seed=10)
    coarse = np.round((rec.encoder_index * rec.period_s + 0.00037) / 3e-4) * 3e-4  # 0.3 ms steps, no jitter
    res = analyze(replace(rec, drive_time_s=coarse), AnalysisRequest(nominal=nominal))
    plain = analyze(rec, AnalysisRequest(nominal=nominal))
    assert res.fit.values.K_Nm_per_rad == plain.fit.values.K_Nm_per_rad and not res.quality.encoder_time_stamps
    assert any(n.startswith("encoder: the drive's time stamps (RMS ") and n.endswith("sample instants taken as k·T")
               for n in res.notes)


def test_stamps_that_are_only_the_cycle_count_do_not_hide_the_jitter() -> None:
    rec, _, nominal = sim_recording(duration_s=4.0, seed=11, sync_jitter_s=50e-6)
    res = analyze(replace(rec, drive_time_s=rec.encoder_index * rec.period_s), AnalysisRequest(nominal=nominal))
    assert not res.quality.encoder_time_stamps and res.quality.reasons[0].startswith(JITTER_REASON)
