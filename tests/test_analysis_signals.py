"""The signal half of the analysis against analytic and simulated truth: encoder, torque, clocks, resampling, chain."""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from analysis import encoder, resample, torque
from analysis.phase_offset import PhaseOffset, phase_offset
from analysis.torque_hilbert import apex_sign, torque_hilbert
from analysis.torque_park import phase_gains, torque_park
from analysis.clock_model import ClockFit
from analysis.chain import PAPER_CHAIN, our_chain
from analysis.recording import Recording
from analysis.signals import prepare_signals
from drivers.config import Bench, Profile
from drivers.sim.bench import SimBench

SIM_TOML = Path(__file__).resolve().parent.parent / "configs" / "benches" / "sim.toml"
PROFILE = Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=0.2, decel_time_s=0.2, duration_s=10.0)
RATE_HZ, P, K_T, THETA0, DC = 25_600.0, 4, 3.0, 0.7, 0.02


# ---- helpers -------------------------------------------------------------------------------------------

def sim_session(duration_s: float = 6.0, channels: tuple[str, ...] = ("i_a",), t_motion_s: float = 0.3,
                **sim_updates: object) -> tuple[Recording, SimBench]:
    """A recording built straight from the simulated bench: DAQ reads of 0.1 s, every encoder cycle."""
    with SIM_TOML.open("rb") as f:
        bench = Bench.model_validate(tomllib.load(f))
    assert bench.sim is not None
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update=sim_updates),
                                     "daq": bench.daq.model_copy(update={"channels": list(channels)})})
    sim = SimBench(bench, realtime=False, keep_history=True)
    sim.start_motion(PROFILE, t_motion_s)
    n = int(duration_s * sim.daq_rate_hz)
    current = sim.current_samples(0, n)
    first = np.arange(0, n, 2560, dtype=np.int64)
    count = np.minimum(2560, n - first)
    block_host = sim.host_ns_at(sim.daq_time_s(first + count - 1), sim.host_jitter_s("daq_host", 0, first.size))
    T = sim.drive_period_s
    k = np.arange(max(0, int(sim.sim.daq_offset_s / T)), int((sim.sim.daq_offset_s + duration_s) / T) + 2)
    enc_host = sim.host_ns_at(k * T, sim.host_jitter_s("drive_host", int(k[0]), k.size))
    rec = Recording({c: current[i] for i, c in enumerate(channels)}, sim.daq_rate_hz, k.astype(np.int64),
                    sim.encoder_counts(int(k[0]), k.size), T, sim.counts_per_rev, bench.motor.pole_pairs,
                    bench.motor.torque_constant_Nm_per_A, first, count, block_host, enc_host)
    return rec, sim


def band_limited_truth(sim: SimBench, rec: Recording, t_s: np.ndarray) -> np.ndarray:
    """The true torque through the same anti-alias chain, read at drive times ``t_s`` via the true clock."""
    n = rec.current_a["i_a"].size
    true_daq = sim.true_state_at(sim.daq_time_s(np.arange(n)))["torque_Nm"]
    truth = sim.truth
    t_daq = (t_s - truth["daq_offset_s"]) / (1.0 + truth["daq_drift_ppm"] * 1e-6)
    return resample.to_instants(true_daq, rec.rate_hz, 0.0, t_daq, 0.4 / rec.period_s, 0.6 / rec.period_s)


def rms_pct(x: np.ndarray, ref: np.ndarray) -> float:
    return float(100.0 * np.sqrt(np.mean((x - ref) ** 2) / np.mean(ref**2)))


def synthetic_phase(seconds: float = 3.0, noise_a: float = 0.01, seed: int = 0) -> dict[str, np.ndarray]:
    """One phase from a known rectangular-ish i_q (steps through a 1.5 kHz lag, plus 102 Hz ringing) and θ(t)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE_HZ)) / RATE_HZ
    top = 1000.0 * 2 * np.pi / 60
    tau = np.mod(t, 0.8)
    ramp = np.where(tau < 0.2, tau, np.where(tau < 0.6, 0.4 - tau, tau - 0.8)) / 0.2
    speed = top * ramp + 0.3 * np.sin(2 * np.pi * 102 * t)
    theta_m = np.cumsum(speed) / RATE_HZ
    accel = np.gradient(speed, 1 / RATE_HZ)
    a = np.exp(-2 * np.pi * 1500 / RATE_HZ)
    from scipy.signal import lfilter
    iq = lfilter([1 - a], [1, -a], (0.0105 * accel + 1.5 * np.cos(theta_m / 10)) / K_T)
    theta_e = P * theta_m
    i_a = -iq * np.sin(theta_e + THETA0) + DC + noise_a * rng.standard_normal(t.size)
    i_b = -iq * np.sin(theta_e + THETA0 - 2 * np.pi / 3) - DC + noise_a * rng.standard_normal(t.size)
    i_c = -iq * np.sin(theta_e + THETA0 + 2 * np.pi / 3) + noise_a * rng.standard_normal(t.size)
    return {"t": t, "iq": iq, "theta_e": theta_e, "i_a": i_a, "i_b": i_b, "i_c": i_c, "speed": speed}


def in_band(x: np.ndarray) -> np.ndarray:
    """The part of a DAQ-rate signal below 400 Hz (zero-phase), ends dropped."""
    from scipy.signal import butter, sosfiltfilt
    return sosfiltfilt(butter(8, 400.0, fs=RATE_HZ, output="sos"), x)[5000:-5000]


@pytest.fixture(scope="module")
def synth() -> dict[str, np.ndarray]:
    return synthetic_phase()


@pytest.fixture(scope="module")
def session3() -> tuple[Recording, SimBench]:
    """Three phases, the default sim clocks (offset 37 ms, drift 40 ppm)."""
    return sim_session(channels=("i_a", "i_b", "i_c"))


# ---- encoder -------------------------------------------------------------------------------------------

def test_unwrap_int32_undoes_register_wraps_both_ways() -> None:
    for true in (np.array([2**31 - 3, 2**31 - 1, 2**31 + 2, 2**31 + 5, 2**31 - 2, 2**31 - 4]),
                 np.array([-(2**31) + 1, -(2**31) - 2, -(2**31) - 9, -(2**31) + 3])):
        raw = ((true + 2**31) % 2**32 - 2**31).astype(np.int32)
        assert np.array_equal(encoder.unwrap_int32(raw), true - true[0] + raw[0])


def test_speed_is_the_backward_difference_on_the_drive_grid() -> None:
    T, cpr = 1e-3, 131072
    k = np.arange(200)
    counts = (50 * k**2).astype(np.int64)
    speed = encoder.speed_from_counts(counts, cpr, T)
    # θ = 50·k²·2π/cpr → (θ[k] − θ[k−1])/T = 50·(2k − 1)·2π/cpr/T, exactly the speed at (k − ½)·T
    assert np.allclose(speed, 50 * (2 * k[1:] - 1) * 2 * np.pi / cpr / T, rtol=0, atol=1e-9)


def test_difference_response_matches_the_operator_on_a_sinusoid() -> None:
    T, f = 1e-3, 137.0
    t = np.arange(4000) * T
    x = np.sin(2 * np.pi * f * t)
    d = np.diff(x) / T
    expected = encoder.difference_response(f, T) * 2j * np.pi * f
    model = np.imag(expected * np.exp(2j * np.pi * f * t[1:]))
    assert np.max(np.abs(d - model)) < 1e-9 * 2 * np.pi * f
    assert encoder.difference_response(0.0, T) == pytest.approx(1.0)


def test_longest_gap_free_span_reports_every_gap() -> None:
    idx = np.array([5, 6, 7, 9, 10, 11, 12, 13, 20, 21])
    span = encoder.longest_gap_free_span(idx)
    assert (span.start, span.stop, span.gaps) == (3, 8, ((7, 9), (13, 20)))


# ---- torque --------------------------------------------------------------------------------------------

def test_phase_offset_recovers_theta0_modulo_pi_and_dc(synth: dict[str, np.ndarray]) -> None:
    off = phase_offset(synth["i_a"], synth["theta_e"], RATE_HZ)
    assert np.angle(np.exp(2j * (off.theta0_rad - THETA0))) / 2 == pytest.approx(0.0, abs=0.01)
    assert off.dc_a == pytest.approx(DC, abs=0.01)


def test_encoder_torque_tracks_a_rectangular_iq_and_beats_pointwise_division(synth: dict[str, np.ndarray]) -> None:
    start = PhaseOffset(THETA0 + 0.005, 0.0, 0)  # θ_0 a little off and no DC: both refined jointly
    est = torque.torque_encoder(synth["i_a"], synth["theta_e"], RATE_HZ, K_T, start)
    true = K_T * synth["iq"]
    err = rms_pct(in_band(est), in_band(true))
    s = np.sin(synth["theta_e"] + THETA0)
    good = np.abs(s) > 0.3
    pointwise = K_T * np.interp(np.arange(s.size), np.flatnonzero(good), (-(synth["i_a"] - DC) / s)[good])
    assert err < 1.0
    assert rms_pct(in_band(pointwise), in_band(true)) > 3 * err


def test_park_torque_is_exact_with_three_and_with_two_phases(synth: dict[str, np.ndarray]) -> None:
    true = K_T * synth["iq"]
    three = torque_park({k: synth[k] for k in ("i_a", "i_b", "i_c")}, synth["theta_e"], K_T, THETA0,
                        {"i_a": DC, "i_b": -DC, "i_c": 0.0})
    two = torque_park({k: synth[k] for k in ("i_a", "i_b")}, synth["theta_e"], K_T, THETA0,
                      {"i_a": DC, "i_b": -DC})
    assert rms_pct(in_band(three), in_band(true)) < 0.2
    assert rms_pct(in_band(two), in_band(true)) < 0.3


def test_park_divides_out_per_phase_gain_errors_estimated_from_the_zero_sum(synth: dict[str, np.ndarray]) -> None:
    rng = np.random.default_rng(3)
    truth = {"i_a": 1.0, "i_b": 1.02, "i_c": 0.98}  # mean 1: the common scale is k_t's, not observable
    dc = {"i_a": DC, "i_b": -DC, "i_c": 0.0}
    measured = {k: truth[k] * (synth[k] - dc[k]) + dc[k] + 2e-3 * rng.standard_normal(synth[k].size) for k in truth}
    est = phase_gains(measured)
    assert est is not None
    for k, g in truth.items():
        assert abs(est.gain[k] - g) < max(3 * est.sigma[k], 2e-4)
        assert 0 < est.sigma[k] < 1e-3
    true = K_T * synth["iq"]
    raw = torque_park(measured, synth["theta_e"], K_T, THETA0, dc)
    fixed = torque_park(measured, synth["theta_e"], K_T, THETA0, dc, est.gain)
    assert rms_pct(in_band(raw), in_band(true)) > 0.8  # the 2·f_e ripple of the unequal gains
    assert rms_pct(in_band(fixed), in_band(true)) < 0.3
    assert phase_gains({k: measured[k] for k in ("i_a", "i_b")}) is None


def test_hilbert_envelope_is_the_current_amplitude_at_constant_speed() -> None:
    t = np.arange(int(RATE_HZ)) / RATE_HZ
    i_a = -1.8 * np.sin(2 * np.pi * 60.0 * t + 0.4)
    est = torque_hilbert(i_a, K_T, np.ones_like(t))
    assert np.allclose(est[2000:-2000], K_T * 1.8, rtol=2e-3)


def test_apex_sign_flips_at_the_speed_extrema(synth: dict[str, np.ndarray]) -> None:
    stride = 32  # 1.25 ms
    speed, t = synth["speed"][::stride], synth["t"][::stride]
    sign = apex_sign(speed, stride / RATE_HZ)
    tau = np.mod(t, 0.8)
    expected = np.where((tau < 0.2) | (tau >= 0.6), 1.0, -1.0)
    away = np.abs((tau % 0.4) - 0.2) > 0.01  # more than 10 ms from an apex (τ = 0.2, 0.6 s)
    assert np.array_equal(sign[away], expected[away])


# ---- resampling ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("f_hz", [5.0, 150.0, 390.0])
def test_resampling_is_flat_and_zero_phase_in_band(f_hz: float) -> None:
    t = np.arange(int(2 * RATE_HZ)) / RATE_HZ
    t_q = 0.3 + np.arange(1400) * 1e-3 * (1 + 40e-6) + 1.234e-4
    y = resample.to_instants(np.sin(2 * np.pi * f_hz * t), RATE_HZ, 0.0, t_q, 400.0, 600.0)
    assert np.max(np.abs(y - np.sin(2 * np.pi * f_hz * t_q))) < 1e-3


def test_resampling_rejects_what_would_alias_into_the_band() -> None:
    t = np.arange(int(2 * RATE_HZ)) / RATE_HZ
    t_q = 0.3 + np.arange(1400) * 1e-3
    y = resample.to_instants(np.sin(2 * np.pi * 700.0 * t), RATE_HZ, 0.0, t_q, 400.0, 600.0)
    assert np.max(np.abs(y)) < 1e-3  # 700 Hz would fold to 300 Hz at 1 kHz


# ---- clocks and the chain on the simulated bench --------------------------------------------------------

@pytest.mark.parametrize("offset_s, drift_ppm", [(0.06, 60.0), (-0.06, -60.0), (-0.021, 35.0), (0.0005, -48.0)])
def test_clock_is_recovered_within_50us_and_5ppm(offset_s: float, drift_ppm: float) -> None:
    rec, _ = sim_session(duration_s=4.0, daq_offset_s=offset_s, daq_drift_ppm=drift_ppm, seed=3)
    clock = prepare_signals(rec).clock
    assert clock.method == "angle"
    assert abs(clock.offset_s - offset_s) < 50e-6
    assert abs(clock.drift_ppm - drift_ppm) < 5.0
    assert clock.residual_s < 100e-6


def test_clock_without_host_stamps_and_with_a_standstill_and_biased_stamps() -> None:
    rec, _ = sim_session(duration_s=5.0, t_motion_s=1.5, daq_offset_s=-0.045, daq_drift_ppm=-30.0, seed=5)
    no_host = prepare_signals(replace(rec, block_host_ns=None, encoder_host_ns=None)).clock
    late_daq = prepare_signals(replace(rec, block_host_ns=rec.block_host_ns + 4_000_000)).clock
    for clock in (no_host, late_daq):
        assert abs(clock.offset_s + 0.045) < 50e-6
        assert abs(clock.drift_ppm + 30.0) < 5.0
    assert abs(late_daq.host_offset_s + 0.045) > 3e-3  # the stamps alone were 4 ms off


def test_chain_torque_methods_against_the_simulated_truth(session3: tuple[Recording, SimBench]) -> None:
    rec, sim = session3
    enc = prepare_signals(rec, our_chain("encoder"))
    park = prepare_signals(rec, our_chain("park"))
    hil = prepare_signals(rec, our_chain("hilbert"))
    assert np.array_equal(enc.t_s, park.t_s) and np.array_equal(enc.t_s, hil.t_s)
    ref = band_limited_truth(sim, rec, enc.t_s)
    assert rms_pct(enc.torque_Nm, ref) < 1.0
    assert rms_pct(park.torque_Nm, ref) < 0.3
    assert rms_pct(hil.torque_Nm, ref) > 10.0  # the paper's bias, kept visible
    assert np.angle(np.exp(1j * (enc.theta0_rad - sim.truth["theta0_encoder_rad"]))) == pytest.approx(0, abs=0.02)


def test_chain_speed_is_the_backward_difference_of_the_true_angle(session3: tuple[Recording, SimBench]) -> None:
    rec, sim = session3
    prep = prepare_signals(rec)
    theta = sim.true_state_at(np.concatenate(([prep.t_s[0] - prep.period_s], prep.t_s)))["theta_m_rad"]
    quantum = 2 * np.pi / rec.counts_per_rev / rec.period_s
    assert np.max(np.abs(prep.speed_rad_s - np.diff(theta) / prep.period_s)) <= 1.01 * quantum
    assert np.allclose(np.diff(prep.t_s), prep.period_s)


def test_paper_chain_is_unaligned_hilbert_with_linear_resampling(session3: tuple[Recording, SimBench]) -> None:
    rec, sim = session3
    paper = prepare_signals(rec, PAPER_CHAIN)
    assert (paper.torque_method, paper.aligned, paper.clock.method) == ("hilbert", False, "none")
    assert any("not aligned" in n for n in paper.notes)
    ours = prepare_signals(rec, our_chain("hilbert"))
    true = sim.true_state_at(paper.t_s)["torque_Nm"]
    assert rms_pct(paper.torque_Nm, true) > rms_pct(ours.torque_Nm, sim.true_state_at(ours.t_s)["torque_Nm"])


def test_gap_in_the_encoder_uses_the_longest_span_and_says_so(session3: tuple[Recording, SimBench]) -> None:
    rec, _ = session3
    keep = np.ones(rec.encoder_index.size, bool)
    keep[1500:1510] = False
    gappy = replace(rec, encoder_index=rec.encoder_index[keep], position_counts=rec.position_counts[keep],
                    encoder_host_ns=rec.encoder_host_ns[keep])
    prep = prepare_signals(gappy)
    assert prep.t_s[0] >= rec.encoder_index[1510] * rec.period_s
    assert any("gap" in n and "longest gap-free span" in n for n in prep.notes)


def test_current_beyond_the_encoder_record_is_not_demodulated(session3: tuple[Recording, SimBench]) -> None:
    rec, sim = session3
    t_enc = rec.encoder_index * rec.period_s
    short = (t_enc > 1.05) & (t_enc < 4.3)  # the motor moves at both ends of the encoder record
    prep = prepare_signals(replace(rec, encoder_index=rec.encoder_index[short],
                                   position_counts=rec.position_counts[short], encoder_host_ns=rec.encoder_host_ns[short]))
    assert rms_pct(prep.torque_Nm, band_limited_truth(sim, rec, prep.t_s)) < 1.0


def test_gap_in_the_daq_uses_the_longest_run(session3: tuple[Recording, SimBench]) -> None:
    rec, _ = session3
    drop = slice(10 * 2560, 12 * 2560)  # two reads lost
    gappy = replace(rec, current_a={k: np.delete(v, drop) for k, v in rec.current_a.items()},
                    block_first_index=np.delete(rec.block_first_index, [10, 11]),
                    block_count=np.delete(rec.block_count, [10, 11]),
                    block_host_ns=np.delete(rec.block_host_ns, [10, 11]))
    prep = prepare_signals(gappy)
    assert abs(prep.clock.offset_s - 0.037) < 50e-6
    assert prep.t_s[0] > 0.037 + 12 * 0.1
    assert any("DAQ sample count" in n for n in prep.notes)


def test_bad_input_is_refused_with_a_clear_message(session3: tuple[Recording, SimBench]) -> None:
    rec, _ = session3
    one_phase = replace(rec, current_a={"i_a": rec.current_a["i_a"]})
    with pytest.raises(ValueError, match="park"):
        prepare_signals(one_phase, our_chain("park"))
    with pytest.raises(ValueError, match="i_a"):
        prepare_signals(replace(rec, current_a={"i_b": rec.current_a["i_b"]}))
    late = rec.encoder_index * rec.period_s > 3.0  # encoder from 3 s on, current only its first 2 s
    with pytest.raises(ValueError, match="overlap"):
        prepare_signals(replace(rec, current_a={k: v[: 20 * 2560] for k, v in rec.current_a.items()},
                                block_first_index=rec.block_first_index[:20], block_count=rec.block_count[:20],
                                block_host_ns=rec.block_host_ns[:20], encoder_index=rec.encoder_index[late],
                                position_counts=rec.position_counts[late], encoder_host_ns=rec.encoder_host_ns[late]))


def test_clockfit_maps_both_ways() -> None:
    c = ClockFit(0.037, 40.0)
    t = np.array([0.0, 1.0, 100.0])
    assert np.allclose(c.daq_time_s(c.drive_time_s(t)), t, atol=1e-12)
    assert c.drive_time_s(10.0) == pytest.approx(0.037 + 10.0 * (1 + 40e-6))
