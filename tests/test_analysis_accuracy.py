"""Issue 4's measured criteria on simulated sessions (SimBench straight, no recorder).

* accuracy: |error| ≤ 1 % on K and ≤ 2 % on J_m, J_l on the paper's plant; ≤ 2 % / 4 % on plants
  with K and the inertias scaled, among them the stiff (K ×2, J ×0.5) and soft (K ×0.5, J ×2) ones
  (the bench's nominal values stay the paper's);
* honesty: every excited session here is "ok" and ≥ 90 % of the 95 % intervals hold the truth;
* clock: offset within 50 µs and drift within 5 ppm of the truth at the extremes ±60 ms, ±60 ppm
  (every session below has one of the four sign combinations);
* a gap in the encoder stream: the analysis uses the longest gap-free span and says so.

``bench/accuracy.py`` runs the same over more seeds and scenarios, next to the paper's pipeline.
"""

from __future__ import annotations

import re
from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest

from analysis import AnalysisRequest, Result, analyze
from drivers.config import SimSettings
from tests.test_analysis_pipeline import sim_recording

PAPER = SimSettings()
NAMES = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2")

# (label, seed, DAQ offset s, drift ppm, factors on K, J_m, J_l, tolerance % on K, on J)
CASES = [
    ("paper+60ms+60ppm", 11, +0.060, +60.0, (1.0, 1.0, 1.0), 1.0, 2.0),
    ("paper-60ms-60ppm", 12, -0.060, -60.0, (1.0, 1.0, 1.0), 1.0, 2.0),
    ("paper+60ms-60ppm", 13, +0.060, -60.0, (1.0, 1.0, 1.0), 1.0, 2.0),
    ("scaled-60ms+60ppm", 14, -0.060, +60.0, (0.5, 2.0, 0.5), 2.0, 4.0),
    ("scaled+60ms+60ppm", 15, +0.060, +60.0, (0.5, 2.0, 0.5), 2.0, 4.0),
    # stiff (f_r ≈ 204 Hz: the encoder's fold-over and the torque's bandwidth matter) and soft plants
    ("stiff+41ms-58ppm", 2, -0.0416, -57.8, (2.0, 0.5, 0.5), 2.0, 4.0),
    ("stiff+40ms+24ppm", 3, +0.0406, +24.1, (2.0, 0.5, 0.5), 2.0, 4.0),
    ("stiff-60ms-60ppm", 16, -0.060, -60.0, (2.0, 0.5, 0.5), 2.0, 4.0),
    ("soft+60ms-60ppm", 17, +0.060, -60.0, (0.5, 2.0, 2.0), 2.0, 4.0),
    ("soft-30ms+45ppm", 18, -0.030, +45.0, (0.5, 2.0, 2.0), 2.0, 4.0),
]


@lru_cache(maxsize=None)
def _analysed(seed: int, offset_s: float, drift_ppm: float, factors: tuple[float, float, float]
              ) -> tuple[Result, dict]:
    k, jm, jl = factors
    rec, truth, nominal = sim_recording(
        seed=seed, daq_offset_s=offset_s, daq_drift_ppm=drift_ppm, host_jitter_s=0.0002, current_noise_A=0.01,
        K_Nm_per_rad=PAPER.K_Nm_per_rad * k, Jm_kgm2=PAPER.Jm_kgm2 * jm, Jl_kgm2=PAPER.Jl_kgm2 * jl)
    return analyze(rec, AnalysisRequest(nominal=nominal)), truth


@pytest.mark.parametrize("label, seed, offset_s, drift_ppm, factors, tol_k, tol_j", CASES, ids=[c[0] for c in CASES])
def test_parameters_within_the_issue_tolerances(label, seed, offset_s, drift_ppm, factors, tol_k, tol_j):
    res, truth = _analysed(seed, offset_s, drift_ppm, factors)
    for name, tol in zip(NAMES, (tol_k, tol_j, tol_j)):
        err = 100.0 * (getattr(res.fit.values, name) / truth[name] - 1.0)
        assert abs(err) <= tol, f"{name}: {err:+.2f} % (tolerance {tol} %)"
    assert res.quality.verdict in ("ok", "poor")  # a "failed" verdict would hide a good number


@pytest.mark.parametrize("label, seed, offset_s, drift_ppm, factors, tol_k, tol_j", CASES, ids=[c[0] for c in CASES])
def test_clock_recovered_at_the_extremes(label, seed, offset_s, drift_ppm, factors, tol_k, tol_j):
    res, truth = _analysed(seed, offset_s, drift_ppm, factors)
    assert res.clock.method == "angle"
    assert res.clock.offset_s == pytest.approx(truth["daq_offset_s"], abs=50e-6)
    assert res.clock.drift_ppm == pytest.approx(truth["daq_drift_ppm"], abs=5.0)


def test_most_intervals_hold_the_truth_and_ok_means_it():
    held = []
    for label, seed, offset_s, drift_ppm, factors, _, _ in CASES:
        res, truth = _analysed(seed, offset_s, drift_ppm, factors)
        inside = [res.fit.ci95[n][0] <= truth[n] <= res.fit.ci95[n][1] for n in (*NAMES, "C_Nms_per_rad")]
        held += inside
        assert res.quality.verdict == "ok", f"{label}: {res.quality.reasons}"
    assert np.mean(held) >= 0.9, f"only {sum(held)} of {len(held)} 95 % intervals hold the truth"


def test_encoder_gap_uses_the_longest_gap_free_span_and_says_so():
    """Frames 3000–3019 never arrive (as ``drop_encoder_frames`` makes the sim drive do): 3 s | 7 s."""
    drop = (3000, 20)
    rec, truth, nominal = sim_recording(seed=21, daq_offset_s=0.025, daq_drift_ppm=-35.0,
                                        drop_encoder_frames=[drop])
    keep = ~((rec.encoder_index >= drop[0]) & (rec.encoder_index < drop[0] + drop[1]))
    rec = replace(rec, encoder_index=rec.encoder_index[keep], position_counts=rec.position_counts[keep],
                  encoder_host_ns=rec.encoder_host_ns[keep])
    res = analyze(rec, AnalysisRequest(nominal=nominal))
    note = next((n for n in res.notes if "gap" in n), None)
    assert note is not None and "longest gap-free span" in note, res.notes
    span = re.search(r"span ([\d.]+)–([\d.]+) s", note)
    assert span is not None, note
    gap_end_s = (drop[0] + drop[1]) * rec.period_s
    assert float(span.group(1)) >= gap_end_s - 1e-9
    assert res.figures.t_s[0] >= gap_end_s
    assert any("gap" in r for r in res.to_json_dict()["quality"]["reasons"])  # reaches --json / the table
    assert res.fit.values.K_Nm_per_rad == pytest.approx(truth["K_Nm_per_rad"], rel=0.02)
    assert res.clock.offset_s == pytest.approx(truth["daq_offset_s"], abs=50e-6)


def test_pwm_ripple_on_the_current_does_not_bias_the_plant() -> None:
    """A 10 kHz ripple of 3 % of the current's RMS (a drive's switching) is out of band: the torque-noise
    model must not count it as broadband noise (it did, and biased K by −5 % on the stiff plant)."""
    results = []
    for ripple_a in (0.0, 0.04):
        rec, truth, nominal = sim_recording(seed=1, daq_offset_s=0.03, daq_drift_ppm=30.0, host_jitter_s=0.0002,
                                            current_noise_A=0.01, K_Nm_per_rad=PAPER.K_Nm_per_rad * 2,
                                            Jm_kgm2=PAPER.Jm_kgm2 * 0.5, Jl_kgm2=PAPER.Jl_kgm2 * 0.5)
        t_s = np.arange(rec.current_a["i_a"].size) / rec.rate_hz
        rec.current_a["i_a"] = rec.current_a["i_a"] + ripple_a * np.sin(2 * np.pi * 10_000.0 * t_s + 0.7)
        results.append(analyze(rec, AnalysisRequest(nominal=nominal)))
    clean, rippled = results
    for name in NAMES:
        assert getattr(rippled.fit.values, name) == pytest.approx(truth[name], rel=0.01)
        assert getattr(rippled.fit.values, name) == pytest.approx(getattr(clean.fit.values, name), rel=0.002)
    assert rippled.quality.verdict == "ok"
