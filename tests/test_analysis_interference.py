"""One-phase interference the electrical angle does not modulate: removed with the torque, or named in the verdict."""

from __future__ import annotations

import re

import numpy as np
import pytest

from analysis import torque
from analysis.phase_offset import PhaseOffset
from analysis import AnalysisRequest, analyze
from analysis.quality import assess
from tests.interference import with_interference
from tests.test_analysis_pipeline import sim_recording

NAMES = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2")


def _errors_pct(res, truth: dict) -> list[float]:
    return [100.0 * (getattr(res.fit.values, n) / truth[n] - 1.0) for n in NAMES]


@pytest.fixture(scope="module")
def session_25k():
    return sim_recording(duration_s=6.0, seed=4, daq_offset_s=0.021, daq_drift_ppm=35.0)


@pytest.fixture(scope="module")
def session_10k():
    return sim_recording(duration_s=6.0, seed=5, daq_offset_s=-0.033, daq_drift_ppm=-25.0, daq_rate_hz=10000.0)


def test_hum_with_harmonics_and_a_drifting_offset_are_removed_k_within_1_percent(session_25k):
    rec, truth, nominal = session_25k
    clean = analyze(rec, AnalysisRequest(nominal=nominal))
    res = analyze(with_interference(rec, 4, hum_A=0.020, drift_A=0.040), AnalysisRequest(nominal=nominal))
    err, err_clean = _errors_pct(res, truth), _errors_pct(clean, truth)
    assert res.quality.verdict == "ok"
    assert abs(err[0]) < 1.0 and max(abs(err[1]), abs(err[2])) < 2.0
    # the interference costs at most 0.3 % against the same session without it (before: K +2…3 %, J_m +4…7 %)
    assert np.max(np.abs(np.subtract(err, err_clean))) < 0.3
    note = next(n for n in res.notes if n.startswith("current: removed interference lines"))
    # the mains frequency is drawn within ±0.1 % of 50 Hz; the 3rd harmonic has 6 mA
    assert re.search(r"(49\.9|50\.0|50\.1) Hz \((19|20|21) mA\)", note) and re.search(r"1(49|50)\.\d Hz \(6 mA\)", note)


def test_aliased_pwm_tones_on_a_10ks_current_are_removed_k_within_2_percent(session_10k):
    rec, truth, nominal = session_10k
    clean = analyze(rec, AnalysisRequest(nominal=nominal))
    res = analyze(with_interference(rec, 5, tones_A=0.025, tone_hz=(2350.0, 3720.0)), AnalysisRequest(nominal=nominal))
    err, err_clean = _errors_pct(res, truth), _errors_pct(clean, truth)
    assert res.quality.verdict == "ok"
    assert abs(err[0]) < 2.0 and max(abs(err[1]), abs(err[2])) < 4.0
    assert np.max(np.abs(np.subtract(err, err_clean))) < 0.1  # before: K −1.4…−3.4 %, all ok
    note = next(n for n in res.notes if n.startswith("current: removed interference lines"))
    assert "2350.0 Hz (25 mA)" in note and "3720.0 Hz (25 mA)" in note


def test_no_interference_finds_no_line_and_keeps_the_paper_accuracy(session_25k):
    rec, truth, nominal = session_25k
    res = analyze(rec, AnalysisRequest(nominal=nominal))
    assert not any(n.startswith("current: removed interference lines") for n in res.notes)
    err = _errors_pct(res, truth)
    assert res.quality.verdict == "ok" and abs(err[0]) < 1.0 and max(abs(err[1]), abs(err[2])) < 2.0


def _dwell_record(tone_a: float) -> tuple[np.ndarray, np.ndarray, float]:
    """A phase current of a motor dwelling at 750 rpm (f_e = 50 Hz, p = 4) half the time, with a 50 Hz tone."""
    fs = 25600.0
    t = np.arange(int(6 * fs)) / fs
    ph = (t % 2.0)
    q = ph % 1.0
    w = np.where(ph < 1.0, 1.0, -1.0) * np.clip(np.minimum(q, 1.0 - q) / 0.1, 0.0, 1.0) * 750.0 * 2 * np.pi / 60.0
    theta_e = 4.0 * np.cumsum(w) / fs
    iq = 0.01 * np.gradient(w) * fs + 0.3
    rng = np.random.default_rng(0)
    i_a = -iq * np.sin(theta_e) + 0.01 * rng.standard_normal(t.size) + tone_a * np.sin(2 * np.pi * 50.0 * t + 1.0)
    return i_a, theta_e, fs


def test_a_tone_at_an_electrical_frequency_the_motor_dwells_at_is_inseparable_and_named():
    found: list[torque.Interference] = []
    torque.torque_encoder(*_dwell_record(0.025), 1.0, PhaseOffset(0.0, 0.0, 0), found=found)
    assert found[0].inseparable_hz and found[0].inseparable_hz[0] == pytest.approx(50.0, abs=0.05)
    clean: list[torque.Interference] = []
    torque.torque_encoder(*_dwell_record(0.0), 1.0, PhaseOffset(0.0, 0.0, 0), found=clean)
    assert clean[0].inseparable_hz == () and clean[0].lines_hz == ()


def test_an_inseparable_line_makes_the_verdict_poor_naming_its_frequency(session_25k):
    rec, _, nominal = session_25k
    res = analyze(rec, AnalysisRequest(nominal=nominal))
    q = assess(res.frf, res.fit, clock_residual_s=res.clock.residual_s, inseparable_hz=(50.0,))
    assert res.quality.verdict == "ok" and q.verdict == "poor"
    assert q.reasons[0].startswith("a 50.0 Hz line on the phase current cannot be told apart from the torque")


def test_intervals_from_the_session_hold_the_truth_without_being_several_times_the_error():
    """Six short sessions of the dithered motion the shipped profiles run: the 95 % interval holds the truth in ≥ 5
    of 6 for each of K, J_m, J_l, and its half-width is under 5× the RMS error over the seeds. (A motion that repeats
    exactly gives every seed the same quantisation error — one realisation, not six: its spread over seeds says
    nothing about the intervals.) Measured: 3.7…4.5×, 6 of 6 inside."""
    inside, half, err = [], [], []
    for seed in range(6):
        rec, truth, nominal = sim_recording(duration_s=6.0, seed=20 + seed, daq_offset_s=0.015 + 0.005 * seed,
                                            daq_drift_ppm=30.0, speed_dither=0.02)
        res = analyze(rec, AnalysisRequest(nominal=nominal))
        inside.append([res.fit.ci95[n][0] <= truth[n] <= res.fit.ci95[n][1] for n in NAMES])
        half.append([res.quality.ci_rel_halfwidth[n] for n in NAMES])
        err.append([getattr(res.fit.values, n) / truth[n] - 1.0 for n in NAMES])
    assert np.all(np.sum(inside, axis=0) >= 5)
    rms = np.sqrt(np.mean(np.square(err), axis=0))
    assert np.all(np.median(half, axis=0) < 5.0 * rms), (np.median(half, axis=0), rms)
