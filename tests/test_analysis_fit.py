"""FRF, two-mass model, fit and quality verdict on a two-mass plant simulated here.

The plant is simulated on a fine 20 kHz grid (bilinear, exact enough: warping < 1e-4 at f_r);
the torque is the triangle profile's rectangular feed-forward through a 0.2 ms current loop plus an
unmeasured torque disturbance (cogging, friction); the measured torque is that plus sensor noise,
anti-alias filtered and taken at the 1 kHz encoder instants; the speed is the backward
difference of the quantised encoder angle (131072 counts/rev) on the same instants.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest
from scipy import signal

from analysis.fit import FitInputError, FitOptions, _bracketed, fit_two_mass, initial_guess, default_band_hz
from analysis.fit_problem import VIBRATION_DAMPING, unbracketed_note
from analysis.frf import RecordTooShortError, estimate_frf
from analysis.model import TwoMassParams, frequency_response, transfer_function
from analysis.quality import assess

PAPER = TwoMassParams(891.0, 0.003027, 0.00748, 0.1)
FS_SIM_HZ = 20_000.0
PERIOD_S = 0.001
COUNTS_PER_REV = 131072
TOP_RAD_S = 1000.0 * 2.0 * np.pi / 60.0
# zero-phase anti-alias FIR for 20 kHz → 1 kHz: flat to 0.005 % up to 400 Hz, −84 dB at 500 Hz
ANTI_ALIAS = signal.firwin(2001, 460.0, fs=FS_SIM_HZ, window=("kaiser", 8.0))


@dataclass(frozen=True)
class SimRecord:
    """Measured torque (N·m) and backward-difference speed (rad/s) on the 1 kHz grid."""

    torque_Nm: np.ndarray
    speed_rad_s: np.ndarray


def simulate(
    plant: TwoMassParams,
    seed: int,
    *,
    accel_time_s: float = 0.2,
    duration_s: float = 10.0,
    disturbance_Nm: float = 0.3,
    sensor_noise_Nm: float = 0.03,
    friction_Nms_per_rad: float = 0.002,
) -> SimRecord:
    """Simulate the joint driven by the triangle profile's rectangular torque, open loop.

    ``disturbance_Nm`` and ``sensor_noise_Nm`` are white-noise RMS values on the 20 kHz grid (a
    disturbance of 0.3 N·m there is ≈ 0.05 N·m RMS in the 0…400 Hz band, 1 % of the 5.5 N·m
    feed-forward of the paper's plant).
    """
    rng = np.random.default_rng(seed)
    n = int(duration_s * FS_SIM_HZ)
    t = np.arange(n) / FS_SIM_HZ
    half = 2.0 * accel_time_s
    u = np.mod(t, 2.0 * half)
    accel = np.where(np.mod(u, half) < accel_time_s, 1.0, -1.0) * np.where(u < half, 1.0, -1.0)
    j_tot = plant.Jm_kgm2 + plant.Jl_kgm2
    b, a = signal.bilinear([1.0], [2e-4, 1.0], FS_SIM_HZ)
    torque = signal.lfilter(b, a, j_tot * TOP_RAD_S / accel_time_s * accel)
    applied = torque + disturbance_Nm * rng.standard_normal(n)
    p = replace(plant, bm_Nms_per_rad=friction_Nms_per_rad, bl_Nms_per_rad=friction_Nms_per_rad)
    num, den = transfer_function(p)
    z, pz, k = signal.bilinear_zpk(*signal.tf2zpk(num, den), FS_SIM_HZ)
    speed = signal.sosfilt(signal.zpk2sos(z, pz, k), applied)
    angle = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1])) / FS_SIM_HZ))
    q = int(round(PERIOD_S * FS_SIM_HZ))
    counts = np.floor(angle[::q] / (2.0 * np.pi) * COUNTS_PER_REV + rng.uniform())
    measured = signal.resample_poly(torque + sensor_noise_Nm * rng.standard_normal(n), 1, q, window=ANTI_ALIAS)
    speed_meas = np.diff(counts) * (2.0 * np.pi / COUNTS_PER_REV) / PERIOD_S
    return SimRecord(measured[1:], speed_meas)


def scaled(k_factor: float, j_factor: float) -> TwoMassParams:
    """The paper's plant with K and both inertias scaled."""
    return TwoMassParams(PAPER.K_Nm_per_rad * k_factor, PAPER.Jm_kgm2 * j_factor,
                         PAPER.Jl_kgm2 * j_factor, PAPER.C_Nms_per_rad)


def identify(rec: SimRecord, **kw):
    """FRF → fit with the default options unless overridden."""
    frf = estimate_frf(rec.torque_Nm, rec.speed_rad_s, PERIOD_S)
    return frf, fit_two_mass(frf, **kw)


def rel_err(fit, truth: TwoMassParams) -> dict[str, float]:
    """Relative errors of K, J_m, J_l, C."""
    return {n: getattr(fit.values, n) / getattr(truth, n) - 1.0
            for n in ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")}


def covers(fit, truth: TwoMassParams, names=("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2")) -> bool:
    """Whether the 95 % intervals of ``names`` contain the true values."""
    return all(fit.ci95[n][0] <= getattr(truth, n) <= fit.ci95[n][1] for n in names)


def test_model_resonances_are_the_extrema_of_the_undamped_amplitude():
    p = replace(PAPER, C_Nms_per_rad=1e-6)
    f = np.linspace(20.0, 200.0, 180_001)
    m = np.abs(frequency_response(p, f))
    assert f[np.argmin(m[f < 80])] == pytest.approx(p.antiresonance_hz, abs=2e-3)
    assert f[np.argmax(m)] == pytest.approx(p.resonance_hz, abs=2e-3)
    assert p.antiresonance_hz == pytest.approx(54.96, abs=0.05)  # the paper rounds
    assert p.resonance_hz == pytest.approx(102.39, abs=0.1)


def test_frf_of_a_clean_record_matches_the_model_away_from_the_resonances():
    rec = simulate(PAPER, 0, disturbance_Nm=0.0, sensor_noise_Nm=0.0)
    frf = estimate_frf(rec.torque_Nm, rec.speed_rad_s, PERIOD_S)
    assert frf.segment_s == pytest.approx(0.5) and frf.n_segments == 38
    sel = (frf.f_hz > 150) & (frf.f_hz < 350)  # smooth |H|, where |D(f)| is 0.75…0.96
    ratio = np.abs(frf.H[sel] / frequency_response(PAPER, frf.f_hz[sel]))
    assert np.median(ratio) == pytest.approx(1.0, abs=0.01)
    assert np.median(frf.coherence[sel]) > 0.9  # what the encoder quantisation leaves


def test_too_short_record_names_the_duration_needed():
    rec = simulate(PAPER, 0, duration_s=0.7)
    with pytest.raises(RecordTooShortError, match=r"needs at least 0\.750 s") as info:
        estimate_frf(rec.torque_Nm, rec.speed_rad_s, PERIOD_S)
    assert isinstance(info.value, ValueError) and "\n" not in str(info.value)


def test_initial_guess_from_the_frf_alone_is_within_15_percent():
    truth = scaled(2.0, 0.5)
    frf = estimate_frf(*vars(simulate(truth, 3)).values(), PERIOD_S)
    guess = initial_guess(frf, default_band_hz(PERIOD_S))
    for name in ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2"):
        assert getattr(guess, name) == pytest.approx(getattr(truth, name), rel=0.15)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_recovers_the_papers_plant(seed):
    _, fit = identify(simulate(PAPER, seed))
    err = rel_err(fit, PAPER)
    assert fit.status == "converged"
    assert abs(err["K_Nm_per_rad"]) < 0.01
    assert abs(err["Jm_kgm2"]) < 0.02 and abs(err["Jl_kgm2"]) < 0.02
    assert abs(err["C_Nms_per_rad"]) < 0.10
    assert covers(fit, PAPER)
    assert fit.f_a == pytest.approx(PAPER.antiresonance_hz, rel=0.01)
    assert fit.f_r == pytest.approx(PAPER.resonance_hz, rel=0.01)


@pytest.mark.parametrize("k_factor,j_factor", [(0.5, 2.0), (2.0, 0.5), (2.0, 2.0), (0.5, 1.0)])
def test_fit_recovers_scaled_plants_from_wrong_nominal_values(k_factor, j_factor):
    truth = scaled(k_factor, j_factor)
    _, fit = identify(simulate(truth, 7), nominal=PAPER)
    err = rel_err(fit, truth)
    assert abs(err["K_Nm_per_rad"]) < 0.02
    assert abs(err["Jm_kgm2"]) < 0.04 and abs(err["Jl_kgm2"]) < 0.04
    assert covers(fit, truth)


def test_complex_fit_agrees_with_the_amplitude_fit():
    frf = estimate_frf(*vars(simulate(PAPER, 4)).values(), PERIOD_S)
    amp = fit_two_mass(frf)
    cpx = fit_two_mass(frf, FitOptions(kind="complex"))
    for name in ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2"):
        assert getattr(cpx.values, name) == pytest.approx(getattr(PAPER, name), rel=0.01)
        assert getattr(cpx.values, name) == pytest.approx(getattr(amp.values, name), rel=0.01)


def test_vibration_damping_damps_the_resonance_and_leaves_the_anti_resonance_to_c():
    """b_v adds J_l b_v to H's s² denominator term only: the zeros (the anti-resonance) are C's alone, and the resonance's
    damping grows by the share J_l b_v/((J_m+J_l) C) of C's."""
    plain, damped = transfer_function(PAPER), transfer_function(replace(PAPER, bv_Nms_per_rad=0.05))
    np.testing.assert_array_equal(damped[0], plain[0])
    np.testing.assert_allclose(damped[1] - plain[1], [0.0, PAPER.Jl_kgm2 * 0.05, 0.0, 0.0], atol=1e-15)


def test_c_interval_holds_the_anti_resonances_reading_when_the_resonance_is_damped_beyond_c():
    """A plant whose resonance is damped beyond C's share (b_v = 0.1 N·m·s/rad, as much again as C's): C alone reads
    about 0.1 + J_l b_v/(J_m+J_l) = 0.17 N·m·s/rad, its own interval far from the truth; the fit with b_v free reads C at
    the anti-resonance, and C's reported interval, widened to hold that fit's, holds the truth, as b_v's interval does.
    Measured (seed 3): C 0.171, alone [0.161, 0.183], widened [0.065, 0.45]; b_v 0.114 [0.033, 0.195]."""
    truth = replace(PAPER, bv_Nms_per_rad=0.1)
    frf, fit = identify(simulate(truth, 3))
    assert fit.values.C_Nms_per_rad == pytest.approx(0.171, rel=0.05)  # the values stay C alone's
    low, high = fit.ci95_c_alone["C_Nms_per_rad"]
    assert low > 1.4 * truth.C_Nms_per_rad, (low, high)
    assert fit.ci95["C_Nms_per_rad"][0] <= truth.C_Nms_per_rad <= fit.ci95["C_Nms_per_rad"][1], fit.ci95
    bv, bv_low, bv_high, c_with_bv = fit.vibration_damping
    assert bv_low <= truth.bv_Nms_per_rad <= bv_high and c_with_bv == pytest.approx(truth.C_Nms_per_rad, rel=0.2)
    assert fit.values.K_Nm_per_rad == pytest.approx(truth.K_Nm_per_rad, rel=0.01)
    alone = fit_two_mass(frf, FitOptions(vibration_damping=False))
    assert alone.vibration_damping is None and alone.ci95 == fit.ci95_c_alone


def test_a_second_fit_without_finite_intervals_keeps_c_alones_and_says_so():
    """When the fit with b_v free gives no finite reading (no result, or a b_v interval that is not finite) the intervals
    stay C alone's — and the result's note says they allow for no motor-side damping, where main kept them silently."""
    frf, fit = identify(simulate(PAPER, 3))
    assert fit.vibration_damping is not None and unbracketed_note(fit) is None  # the bracket made: nothing to say
    alone = fit_two_mass(frf, FitOptions(vibration_damping=False))
    assert unbracketed_note(alone) is None  # not asked for (the paper's chain)
    asked = replace(alone, options=FitOptions())  # C alone's result as fit_two_mass holds it before the bracket
    bv_low = fit.vibration_damping[1]
    unbounded = replace(fit, ci95={**fit.ci95, VIBRATION_DAMPING: (bv_low, np.inf)})
    for other in (None, unbounded):
        kept = _bracketed(asked, other)
        assert kept.ci95 == alone.ci95 and kept.vibration_damping is None
        low, high = alone.ci95["C_Nms_per_rad"]
        assert unbracketed_note(kept) == (
            "the intervals are the fit's with C alone: the second fit, with a motor-side damping of the vibration (b_v) "
            "free beside C, gave no finite interval, so they do not allow for one — friction on the motor side damps the "
            f"resonance and reads C high, beyond its interval [{low:.3g}, {high:.3g}] N·m·s/rad")


def test_params_K_keeps_the_nominal_inertias_and_fits_K_and_C():
    truth = scaled(1.6, 1.0)
    _, fit = identify(simulate(truth, 5), options=FitOptions(params="K"), nominal=PAPER)
    assert fit.fitted == ("K_Nm_per_rad", "C_Nms_per_rad")
    assert fit.values.Jm_kgm2 == PAPER.Jm_kgm2 and fit.ci95["Jl_kgm2"] == (PAPER.Jl_kgm2, PAPER.Jl_kgm2)
    assert fit.values.K_Nm_per_rad == pytest.approx(truth.K_Nm_per_rad, rel=0.01)
    assert fit.covariance.shape == (2, 2)


def test_params_K_without_nominal_inertias_is_refused():
    frf = estimate_frf(*vars(simulate(PAPER, 0, duration_s=2.0)).values(), PERIOD_S)
    with pytest.raises(FitInputError, match="nominal"):
        fit_two_mass(frf, FitOptions(params="K"))


def test_given_band_is_used_and_an_empty_band_is_refused():
    frf = estimate_frf(*vars(simulate(PAPER, 0, duration_s=3.0)).values(), PERIOD_S)
    fit = fit_two_mass(frf, FitOptions(band_hz=(20.0, 300.0)))
    assert fit.band == (20.0, 300.0) and fit.n_points == 141
    with pytest.raises(FitInputError, match="300…20 Hz is empty"):
        fit_two_mass(frf, FitOptions(band_hz=(300.0, 20.0)))


def test_good_excitation_gives_ok_and_the_slow_profile_does_not():
    """Same plant, same disturbance: 0.2 s ramps excite the joint, the paper's 0.5 s ramps do not."""
    fast_frf, fast_fit = identify(simulate(PAPER, 1, accel_time_s=0.2))
    fast = assess(fast_frf, fast_fit, clock_residual_s=2e-5)
    assert fast.verdict == "ok" and fast.reasons == ()
    assert fast.mean_coherence > 0.8 and fast.excitation_coherence > 0.9
    slow_frf, slow_fit = identify(simulate(PAPER, 1, accel_time_s=0.5))
    slow = assess(slow_frf, slow_fit, clock_residual_s=2e-5)
    assert slow.verdict in ("poor", "failed")
    assert slow.mean_coherence < 0.7
    assert slow.reasons[0] == ("mean coherence 0.59 in 10…400 Hz (in closed loop that biases |H|, not only scatters "
                               "it), below 0.72 in 192…400 Hz (the encoder's resolution and the torque estimate's "
                               "noise unknown: no cause judged)")  # neither noise known: no advice
    assert slow.excitation_torque_db < fast.excitation_torque_db - 6.0


def test_a_noisy_slow_profile_fails_on_the_excitation_between_fa_and_fr():
    frf, fit = identify(simulate(PAPER, 1, accel_time_s=0.5, disturbance_Nm=3.0))
    q = assess(frf, fit)
    assert q.verdict == "failed" and q.excitation_coherence < 0.4
    assert any(r.startswith(f"coherence {q.excitation_coherence:.2f} between f_a") for r in q.reasons)


def test_unmodelled_mode_and_clock_residual_are_reported():
    frf = estimate_frf(*vars(simulate(PAPER, 2)).values(), PERIOD_S)
    bump = signal.freqs([1.0, 2 * np.pi * 10.0, (2 * np.pi * 250.0) ** 2],
                        [1.0, 2 * np.pi * 60.0, (2 * np.pi * 250.0) ** 2], 2 * np.pi * frf.f_hz)[1]
    other = replace(frf, H=frf.H / bump, coherence=np.maximum(frf.coherence, 0.95))
    q = assess(other, fit_two_mass(other), clock_residual_s=3e-3)
    assert q.verdict in ("poor", "failed") and q.misfit_ratio > 3.0
    assert any("two-mass model misses |H|" in r for r in q.reasons)
    assert any("clock alignment residual 3000 µs" in r for r in q.reasons)


def test_a_start_that_reaches_a_zero_inertia_at_a_finite_cost_is_no_solution(monkeypatch: pytest.MonkeyPatch):
    """On a far-off FRF LM once walked a start to log J = −800 (J = 0.0) with a finite cost; that start must lose
    to the others, not end in a division by zero in f_r. The optimiser's outcome is staged (the first start
    returns such a point with the lowest cost); everything after it is the real fit."""
    import scipy.optimize

    from analysis import fit as fit_module

    real = scipy.optimize.least_squares
    calls = []

    def first_start_underflows(fun, x0, **kw):
        res = real(fun, x0, **kw)
        calls.append(1)
        if len(calls) == 1:
            res.x = res.x.copy()
            res.x[1] = -800.0  # J_m = exp(−800) = 0.0
            res.cost = 0.0
        return res

    monkeypatch.setattr(fit_module.optimize, "least_squares", first_start_underflows)
    _, fit = identify(simulate(PAPER, 0))
    assert fit.values.Jm_kgm2 == pytest.approx(PAPER.Jm_kgm2, rel=0.02)
    assert np.isfinite(fit.f_r) and fit.f_r == pytest.approx(PAPER.resonance_hz, rel=0.01)


def test_an_inertia_underflowed_by_the_vibration_fit_is_a_non_finite_point_not_an_exception() -> None:
    """A Levenberg–Marquardt step of the fit with b_v free took ln J_l to where its exp is 0: b_v's share (J_m+J_l) C/J_l
    divided by zero in Python's floats and the window's analysis failed with "ZeroDivisionError: float division by
    zero" (a 1 s monitor window of slow moves, session 14). Now b_v is not finite and the fit rejects the point."""
    from analysis.fit_problem import PARAM_NAMES, VIBRATION_DAMPING, free_is_finite, with_free

    free = (*PARAM_NAMES, VIBRATION_DAMPING)
    x = np.array([np.log(890.0), np.log(3e-3), -800.0, np.log(0.1), 0.5])  # exp(−800) underflows to 0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        p = with_free(TwoMassParams(890.0, 3e-3, 7.5e-3, 0.1), free, x)
    assert (p.Jl_kgm2, np.isfinite(p.bv_Nms_per_rad), free_is_finite(free, x)) == (0.0, False, False)
