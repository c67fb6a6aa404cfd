"""Fit the two-mass model to a measured frequency response (design §5 steps 5–6).

Residuals are log-amplitude differences ln|H_model| − ln|H_meas| (``kind="amplitude"``, the
paper's clock-immune criterion) or the complex log ratio ln(H_model/H_meas), split into amplitude
and phase (``kind="complex"``), at the FRF bins of the band 10 Hz … min(0.4·f_enc, 500 Hz). Each bin
is weighted by γ²/(1−γ²) — the inverse of the variance of ln|H1| up to a constant — with γ²
clipped to 0.99 so that no handful of bins rules the fit.

Parameters are fitted as logarithms (positive, well scaled) with Levenberg–Marquardt
(``scipy.optimize.least_squares(method="lm")``) from a few starts built from the FRF itself
(:func:`initial_guess`); the lowest cost wins. The joint damping C is always fitted: fixing C = 0
biases K by about 20 %. The viscous frictions b_m, b_l are fixed at 0: their rigid-body terms only shape |H| below
(b_m+b_l)/(2π(J_m+J_l)), a fraction of a hertz for any joint, far below the 10 Hz band edge, so they are not
identifiable from the band and fitting them would only make JᵀJ singular. But a motor-side damping also damps the
resonance, and not the anti-resonance, whose depth C alone sets: a motor-side friction (a robot resting between its
moves, where Coulomb and Stribeck friction act like a steep viscous one) was read as C, confidently wrong
(bench/effects_robot.py, Coulomb 0.3 + Stribeck 0.2 N·m: C 25–55 % high, outside its interval, in 17 of 19 ``ok``
windows). So acq's chain fits the model again with that share, b_v (:data:`analysis.fit_problem.VIBRATION_DAMPING`,
analysis.model), free beside C — C then read at the anti-resonance — and widens each interval until it holds that
fit's too (:func:`_bracketed`): the truth lies in C alone's interval when the resonance's damping is the shaft's, in
b_v's when something on the motor side adds to it, and the data cannot tell which (b_v's interval held 0 in 84 of 85
`ok` robot windows, with friction or without). Fitting b_v always instead moved the values: C read from the
anti-resonance's few low-weight bins is off on some plants of the accuracy family (J_m ×0.5, J_l ×2: C off by up to
95 %, its interval missing in 3 of 5 runs; C's coverage 98 → 94 %), and the resonance no longer told a backlash's misfit
(one confident wrong result). The values, the residuals and the verdict stay C alone's; b_v's reading is reported
beside them. The paper's chain makes no second fit (:attr:`analysis.fit_problem.FitOptions.vibration_damping`).

Confidence intervals come from the session's own scatter when the FRF carries delete-one-block
replicates (:attr:`analysis.frf.FrequencyResponse.replicates`): each replicate is refitted from the
optimum and the jackknife covariance (B−1)/B Σ (x_b − x̄)(x_b − x̄)ᵀ of the log parameters is the
statistical part, with Student's t for B − 1 degrees of freedom. It sees everything that varies
along the record — sensor noise, torque-estimate noise, the plant's response to what the motion
does not repeat, nonlinear distortion that changes from period to period — and on 10 s simulated
sessions matches the spread of the errors over seeds (0.04…0.2 %), where the Jacobian's
s²·(JᵀJ)⁻¹ with correlation inflation was 3…10× wider. Without replicates (records too short for
four blocks) that Jacobian covariance is used, with the normal 1.96. Then the misfit's share is added:
what the residual leaves unexplained, propagated to the parameters with its own size and correlation along
frequency (:func:`analysis.adequacy.misfit_covariance`, a HAC sandwich) — the part no scatter between
blocks shows because every period repeats it (the chain's small errors, a mode or a nonlinearity the
two-mass model lacks). Where that share is below the pull of the systematic errors no scatter shows, the latter is
taken instead: the share of the encoder's quantisation error that repeats with the motion
(:func:`analysis.systematic_errors.quantisation_pull` times :attr:`FitOptions.quantisation_repeating_share`: the part the fit
absorbed leaves no residual) and the smooth errors of the chain and of the speed loop's feedback of the rest of the
quantisation (:func:`analysis.systematic_errors.chain_pull`) — computed from the session's own spectra and the encoder's
resolution (:attr:`FitOptions.speed_lsb_rad`); without the resolution, the constant :data:`CHAIN_REL_STD`. Last, the
bias an error on the torque estimate may leave (noise on the FRF's input flattens the resonance peak of H1, and C
reads high): the shift of the parameters when the resonance is read from H2 instead (:mod:`analysis.input_noise`),
the truth lying between the two readings. The 95 % interval is exp(ln θ ± half-width) on each value, widened to hold the
b_v fit's (above).

The model is compared with the measurement as the Welch estimator sees it: H convolved with the
Hann window's spectral kernel |W(ν)|², weighted by the finely resolved torque spectrum
(:func:`analysis.frf.window_kernel`). At 0.5 s segments (2 Hz bins) the resonance peak is only a
few bins wide; fitting the raw H there biased J_l by −1 % and C by +3 %.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import optimize
from scipy.ndimage import median_filter

from analysis.adequacy import misfit_covariance
from analysis.systematic_errors import chain_pull, quantisation_pull, systematic_std
from analysis.fit_judging import (judged_fit, kernel_model_log_ratio, log_ratio_jacobian, model_log_ratios,
                                  model_misfits, quantisation_terms, weighted_jacobian)
from analysis.fit_problem import (BAND_HIGH_FRACTION_OF_FENC, BAND_HIGH_MAX_HZ, BAND_LOW_HZ, COHERENCE_CLIP, PARAM_NAMES,
                                  VIBRATION_DAMPING, FitKind, FitOptions, FitParams, FitResult, FitStatus, FitWeighting,
                                  _free_params, _jacobian, _Problem, band_mask, default_band_hz, fitted_bins,
                                  free_is_finite, wrapped)
from analysis.fit_spread import (Z95, correlation_inflation, intervals_from_covariance, linearised_jackknife,
                                 replicate_covariance)
from analysis.frf import FrequencyResponse
from analysis.input_noise import h2_at_resonance
from analysis.model import TwoMassParams, antiresonance_hz, resonance_hz

# the fit's terms (analysis.fit_problem) and what judges a finished fit (analysis.fit_judging) live in their own
# modules; their names stay importable from here, where the callers have always found them
__all__ = [
    "BAND_HIGH_FRACTION_OF_FENC", "BAND_HIGH_MAX_HZ", "BAND_LOW_HZ", "CHAIN_REL_STD", "COHERENCE_CLIP", "PARAM_NAMES",
    "Z95", "FitInputError", "FitKind", "FitOptions", "FitParams", "FitResult", "FitStatus", "FitWeighting",
    "band_mask", "default_band_hz", "fit_two_mass", "fitted_bins", "initial_guess", "judged_fit",
    "kernel_model_log_ratio", "log_ratio_jacobian", "model_log_ratios", "model_misfits", "quantisation_terms",
    "weighted_jacobian", "wrapped",
]

# 1σ relative floor of the systematic part of an interval, used only when the fit is not given the encoder's
# resolution (a direct call of fit_two_mass; the pipeline always gives it). Where it comes from: on the simulated
# bench (8 plants with K, J_m, J_l scaled 0.5…2, 10 seeds each, 10 s sessions) every seed of a plant shares an
# error, −0.6…+0.6 % — which session 5 traced to the 2^17 counts/rev encoder's quantisation pulling the fit
# (bench/chain_bias.py; with 2^20 counts the shared error is ≤ 0.1 %): what analysis.systematic_errors.quantisation_pull
# now computes from each session's own spectra (0.35…0.71 % on those plants, 0.17…0.20 % at 2^20 counts). A
# torque scale error (k_t, a sensor gain) multiplies K, J_m, J_l, C alike and no session can show it: it is a bench
# constant (acq selftest checks k_t against a known inertia), not part of these intervals.
CHAIN_REL_STD = 0.004
_START_DAMPING_RATIOS = (0.01, 0.05, 0.2)


class FitInputError(ValueError):
    """The fit cannot start: bad band, too few usable bins, or missing nominal inertias."""


def initial_guess(frf: FrequencyResponse, band: tuple[float, float]) -> TwoMassParams:
    """Estimate K, J_m, J_l from the FRF alone, without any nominal value.

    The compensated amplitude m(f) = |H|·2πf is 1/(J_m+J_l) well below the anti-resonance and
    1/J_m well above the resonance; its minimum marks f_a, its maximum above f_a marks f_r. The
    total inertia is the median over the band of shape(f)/m(f), with shape the undamped model's
    |1 − (f/f_a)²| / |1 − (f/f_r)²| and the bins within 15 % of f_a or f_r left out. Then
    J_m = J_tot (f_a/f_r)², J_l = J_tot − J_m, K = J_l (2π f_a)². C is set for a damping ratio of
    5 % at the resonance.

    Parameters
    ----------
    frf : FrequencyResponse
        Measured frequency response.
    band : tuple of float
        Band (low, high), Hz, to look in.

    Returns
    -------
    TwoMassParams
    """
    sel = band_mask(frf.f_hz, band) & np.isfinite(frf.H) & (frf.H != 0)
    f = frf.f_hz[sel]
    log_m = median_filter(np.log(np.abs(frf.H[sel]) * 2.0 * np.pi * f), size=3, mode="nearest")
    i_r = int(np.argmax(log_m[1:])) + 1
    i_a = int(np.argmin(log_m[:i_r]))
    fa, fr = f[i_a], f[i_r]
    keep = (np.abs(f / fa - 1.0) > 0.15) & (np.abs(f / fr - 1.0) > 0.15)
    if not np.any(keep):
        keep = np.ones_like(f, dtype=bool)
    shape = np.abs(1.0 - (f[keep] / fa) ** 2) / np.abs(1.0 - (f[keep] / fr) ** 2)
    j_tot = float(np.median(shape / np.exp(log_m[keep])))
    jm = j_tot * (fa / fr) ** 2
    jl = j_tot - jm
    k = jl * (2.0 * np.pi * fa) ** 2
    return TwoMassParams(k, jm, jl, _damping_for_ratio(k, jm, jl, 0.05))


def _damping_for_ratio(k: float, jm: float, jl: float, zeta: float) -> float:
    """Joint damping C, N·m·s/rad, giving damping ratio ``zeta`` at the resonance."""
    return 2.0 * zeta * k / (2.0 * np.pi * resonance_hz(k, jm, jl))


def fit_two_mass(
    frf: FrequencyResponse,
    options: FitOptions = FitOptions(),
    nominal: TwoMassParams | None = None,
) -> FitResult:
    """Fit the two-mass model to a measured FRF by Levenberg–Marquardt from a few starts.

    Parameters
    ----------
    frf : FrequencyResponse
        Measured frequency response torque → motor speed.
    options : FitOptions, optional
        Free parameters, residual kind and band.
    nominal : TwoMassParams or None, optional
        The bench's nominal values. Required for ``params="K"`` (J_m, J_l are fixed to them);
        otherwise only one extra start among those built from the FRF (the best cost wins, so
        wrong nominal values cannot pull the result).

    Returns
    -------
    FitResult
        A failed fit comes back with ``status="failed"`` and NaN intervals, not an exception.

    Raises
    ------
    FitInputError
        If the band is empty or holds fewer usable bins than three per free parameter, or
        ``params="K"`` is asked without nominal inertias.
    """
    band = options.band_hz or default_band_hz(frf.period_s)
    band = (float(band[0]), float(min(band[1], frf.f_hz[-1])))
    if not band[0] < band[1]:
        raise FitInputError(f"fit band {band[0]:g}…{band[1]:g} Hz is empty")
    if options.params == "K" and nominal is None:
        raise FitInputError("--params K needs the bench's nominal J_m and J_l")
    n_bins, n_free = int(np.count_nonzero(fitted_bins(frf, band))), len(_free_params(options))
    if n_bins < 3 * n_free:  # also before the initial guess, whose search needs bins
        raise FitInputError(
            f"fit band {band[0]:g}…{band[1]:g} Hz holds {n_bins} FRF bin{'' if n_bins == 1 else 's'} (the "
            f"{frf.segment_s:g} s segments give {1.0 / frf.segment_s:g} Hz bins); need at least {3 * n_free}"
        )
    guess = initial_guess(frf, band)
    if options.params == "K":
        starts = _starts_inertias_fixed(guess, nominal)
    else:
        starts = [replace(guess, C_Nms_per_rad=_damping_for_ratio(guess.K_Nm_per_rad, guess.Jm_kgm2,
                                                                    guess.Jl_kgm2, z))
                  for z in _START_DAMPING_RATIOS]
        if nominal is not None:
            starts.append(replace(nominal, C_Nms_per_rad=_damping_for_ratio(
                nominal.K_Nm_per_rad, nominal.Jm_kgm2, nominal.Jl_kgm2, 0.05), bm_Nms_per_rad=0.0,
                bl_Nms_per_rad=0.0))
    problem = _Problem(frf, band, options, starts[0])
    n_res = problem.f.size * (1 if options.kind == "amplitude" else 2)
    # a start or a jackknife replicate may wander to log-parameters whose exp overflows: such a solution has a
    # non-finite cost or spread and is judged by that, so numpy's warnings about it would only reach the user
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        best = None
        for start in starts:
            try:
                res = optimize.least_squares(problem.residuals, problem.x0(start), method="lm", x_scale=1.0)
            except (ValueError, FloatingPointError):
                continue
            # a finite cost at a parameter that under- or overflowed (an inertia of exactly 0 on a far-off FRF,
            # seen with an analytic Jacobian) is no solution: f_a, f_r and the intervals divide by it
            if np.isfinite(res.cost) and free_is_finite(problem.free, res.x) and (best is None or res.cost < best.cost):
                best = res
        if best is None:
            return _failed(problem, band, options, "no start gave a finite cost")
        fit = _result(problem, best, band, options, n_res, _quantisation_floor(frf, problem, best.x, options),
                      _input_noise_shift(frf, problem, best.x, options))
        if options.vibration_damping and fit.status != "failed":
            fit = _bracketed(fit, _vibration_damping_fit(frf, problem, best.x, options, n_res))
        return fit


def _vibration_damping_fit(frf: FrequencyResponse, problem: _Problem, x: np.ndarray, options: FitOptions,
                           n_res: int) -> FitResult | None:
    """The fit made again with b_v free beside C (:data:`analysis.fit_problem.VIBRATION_DAMPING`), from C alone's optimum
    ``x`` and b_v = 0, with its own intervals (jackknife, misfit, systematic floor, the H2 reading); None when its run
    raises or ends off the finite numbers."""
    vib = _Problem(frf, problem.band, options, problem.params(x), vibration=True)
    try:
        res = optimize.least_squares(vib.residuals, vib.x0(problem.params(x)), method="lm", x_scale=1.0)
    except (ValueError, FloatingPointError):
        return None
    if not (np.isfinite(res.cost) and free_is_finite(vib.free, res.x)):
        return None
    return _result(vib, res, problem.band, options, n_res, _quantisation_floor(frf, vib, res.x, options),
                   _input_noise_shift(frf, vib, res.x, options), linearised=True)


def _bracketed(fit: FitResult, other: FitResult | None) -> FitResult:
    """``fit`` (C alone) with each parameter's 95 % interval widened, symmetrically on the log scale around its value,
    until it holds ``other``'s (the fit with b_v free too) — the truth lies in one model's interval or the other's: C
    alone's when the resonance's damping is the shaft's, b_v's when a motor-side damping adds to it — and the covariance
    scaled alike (its correlations kept). Unchanged when ``other`` is None or its intervals are not all finite (no
    reading to add; :func:`analysis.fit_problem.unbracketed_note` then says so in the result's notes). Also where
    ``other`` reads b_v < 0 — a damping the model's physics rules out: the two structures' disagreement is then the
    measure of a model error no jackknife shows (without it, the robot's load-friction windows: 10 of 21 ``ok``
    confidently wrong against 4, motor friction ×0.5/×1 1/3 against 0/1; session 14). b_v's own reading is reported
    passive, its value and interval clipped at 0 (a healthy J_l ×2 plant read b_v −0.056 [−0.068, −0.044] and reports
    0 [0, 0])."""
    names = fit.fitted
    if other is None or not all(np.isfinite(other.ci95[n]).all() for n in (*names, VIBRATION_DAMPING)):
        return fit
    x = np.log([getattr(fit.values, n) for n in names])
    sigma = np.sqrt(np.clip(np.diag(fit.covariance), 0.0, None))
    reach = np.array([max(xi - np.log(min(fit.ci95[n][0], other.ci95[n][0])),
                          np.log(max(fit.ci95[n][1], other.ci95[n][1])) - xi) for n, xi in zip(names, x)])
    wider = np.maximum(sigma, reach / Z95)
    scale = np.where(sigma > 0.0, wider / np.where(sigma > 0.0, sigma, 1.0), 1.0)
    cov = np.array(fit.covariance) * np.outer(scale, scale)
    cov.setflags(write=False)
    return replace(fit, covariance=cov, ci95=intervals_from_covariance(fit.values, names, x, cov), ci95_c_alone=fit.ci95,
                   vibration_damping=(max(other.values.bv_Nms_per_rad, 0.0),
                                      *(max(end, 0.0) for end in other.ci95[VIBRATION_DAMPING]),
                                      other.values.C_Nms_per_rad))


def _input_noise_shift(frf: FrequencyResponse, problem: _Problem, x: np.ndarray, options: FitOptions) -> np.ndarray:
    """How far the free parameters (:func:`analysis.fit_problem.free_vector`) move when the resonance is read from H2 instead of H1
    (:func:`analysis.input_noise.h2_at_resonance`, one Levenberg–Marquardt run from the optimum ``x``): the bias an
    error on the torque estimate may leave (zero when the band holds no resonance peak; infinite when the refit
    fails, stops without converging or ends off the finite numbers: the fit is not stable under it)."""
    h2 = h2_at_resonance(frf, problem.params(x), problem.band)
    if h2 is None:
        return np.zeros_like(x)
    refit = _refit_from(h2, problem, x, options)
    if refit is None or refit.status <= 0 or not np.all(np.isfinite(refit.x)):  # 0: the evaluation budget ran out
        return np.full_like(x, np.inf)
    return refit.x - x


def _refit_from(frf: FrequencyResponse, problem: _Problem, x: np.ndarray,
                options: FitOptions) -> optimize.OptimizeResult | None:
    """The fit of ``problem`` made again on another estimate ``frf`` of the same band (a jackknife replicate, H2 at the
    resonance): one Levenberg–Marquardt run from the optimum ``x``, which lies close; None when the run raises."""
    try:
        return optimize.least_squares(_Problem(frf, problem.band, options, problem.fixed, problem.vibration).residuals,
                                      x, method="lm", x_scale=1.0)
    except (ValueError, FloatingPointError):
        return None


def _quantisation_floor(frf: FrequencyResponse, problem: _Problem, x: np.ndarray,
                        options: FitOptions) -> np.ndarray | None:
    """Variance of each free parameter (:func:`analysis.fit_problem.free_vector`) that the systematic errors no scatter shows may pull it by: the encoder's
    quantisation (:func:`analysis.systematic_errors.quantisation_pull`, times the share of the error that repeats with the
    motion) and the smooth systematic errors of the chain and of the loop's feedback of the rest of the quantisation
    (:func:`analysis.systematic_errors.chain_pull`); None without the encoder's resolution.

    Always with K, J_m, J_l and C free: with the inertias held at nominal values (``params="K"``) the pull on K alone
    would be a fraction of what the data can tell K to, and the interval would lean on inertias known exactly.
    """
    if not options.speed_lsb_rad:
        return None
    bound, lines = quantisation_terms(frf, problem.band, options.speed_lsb_rad)
    values = problem.params(x)
    full = _Problem(frf, problem.band, replace(options, params="K,Jm,Jl"), values, problem.vibration)
    jac = _jacobian(full, full.x0(values))
    share = options.quantisation_repeating_share
    pull = share * np.diag(quantisation_pull(bound, lines, jac, full.sqrt_w))
    pull = pull + np.diag(chain_pull(jac, full.sqrt_w, systematic_std(bound, share)))
    return pull[[full.free.index(name) for name in problem.free]]


def _starts_inertias_fixed(guess: TwoMassParams, nominal: TwoMassParams) -> list[TwoMassParams]:
    """Starts for ``params="K"``: K from the FRF's f_a and from its f_r, with the nominal inertias."""
    jm, jl = nominal.Jm_kgm2, nominal.Jl_kgm2
    k_from_fa = jl * (2.0 * np.pi * guess.antiresonance_hz) ** 2
    k_from_fr = (2.0 * np.pi * guess.resonance_hz) ** 2 * jm * jl / (jm + jl)
    return [TwoMassParams(k, jm, jl, _damping_for_ratio(k, jm, jl, z))
            for k in (k_from_fa, k_from_fr) for z in (0.02, 0.1)]


def _result(problem: _Problem, res: optimize.OptimizeResult, band: tuple[float, float],
            options: FitOptions, n_res: int, quantisation_floor: np.ndarray | None = None,
            input_noise_shift: np.ndarray | None = None, linearised: bool = False) -> FitResult:
    """Package the best least-squares solution with its covariance and intervals (``input_noise_shift``: the free
    parameters' shift from H1 to H2 at the resonance, :func:`_input_noise_shift`; None: none; ``linearised``: the
    jackknife's replicates by one Gauss–Newton step each, :func:`analysis.fit_spread.linearised_jackknife`)."""
    values = problem.params(res.x)
    n_free = res.x.size
    dof = max(n_res - n_free, 1)
    s2 = 2.0 * res.cost / dof * correlation_inflation(res.fun[: problem.f.size])
    jac = np.asarray(res.jac)
    cov = s2 * np.linalg.pinv(jac.T @ jac)
    quantile = Z95
    if problem.replicates:
        cov, quantile = (linearised_jackknife(problem, res.x, jac, options) if linearised
                         else _jackknife(problem, res.x, options))
    cov = cov * (quantile / Z95) ** 2  # the interval below is ±1.96 σ of this covariance
    misfit = misfit_covariance(res.fun, jac, problem.f.size)
    # at least the quantisation's pull on the parameters (what the fit absorbed of an error no scatter and no residual
    # shows), or without the encoder's resolution the chain's accuracy: each stands for the systematic error as a
    # whole, the part a residual shows included, so it only tops up what the misfit leaves below it
    floor = (quantisation_floor if quantisation_floor is not None
             else np.full(n_free, np.log1p(CHAIN_REL_STD) ** 2))
    cov += misfit + np.diag(np.clip(floor - np.diag(misfit), 0.0, None))
    without = intervals_from_covariance(values, problem.free, res.x, cov)
    if input_noise_shift is not None:
        # the truth lies between the H1 and the H2 reading of the resonance (analysis.input_noise): a bias bounded by
        # the shift d, of unknown size within it, carried as a rectangular distribution of half-width |d| (GUM:
        # variance d²/3, so the 95 % interval holds the whole bracket, 1.96/√3 = 1.13 |d|), along d (a joint shift)
        cov += np.outer(input_noise_shift, input_noise_shift) / 3.0
    ci = intervals_from_covariance(values, problem.free, res.x, cov)
    amp = problem.log_ratio(res.x).real
    rms = float(np.sqrt(np.sum(problem.w * amp**2) / np.sum(problem.w)))
    status: FitStatus = "converged" if res.status > 0 else ("max_evaluations" if res.status == 0 else "failed")
    cov.setflags(write=False)
    return FitResult(
        values=values, ci95=ci, fitted=problem.free, covariance=cov, cost=float(res.cost),
        residual_rms=rms, status=status, message=str(res.message), band=band, options=options,
        f_a=antiresonance_hz(values.K_Nm_per_rad, values.Jl_kgm2),
        f_r=resonance_hz(values.K_Nm_per_rad, values.Jm_kgm2, values.Jl_kgm2),
        n_points=int(problem.f.size),
        input_noise_shift={} if input_noise_shift is None else dict(zip(problem.free, map(float, input_noise_shift))),
        ci95_without_input_noise=without if input_noise_shift is not None else {},
    )


def _jackknife(problem: _Problem, x_best: np.ndarray, options: FitOptions) -> tuple[np.ndarray, float]:
    """Delete-one-block jackknife covariance of the free parameters (:func:`analysis.fit_problem.free_vector`) and its
    95 % t quantile.

    Each replicate FRF is refitted by one Levenberg–Marquardt run from the full fit's optimum
    (the replicates differ from the full record by one block, so the optimum is close).
    """
    xs = [refit.x for refit in (_refit_from(rep, problem, x_best, options) for rep in problem.replicates)
          if refit is not None]
    return replicate_covariance(xs, x_best.size)


def _failed(problem: _Problem, band: tuple[float, float], options: FitOptions, message: str) -> FitResult:
    """A FitResult saying that no start converged to a finite cost."""
    nan = float("nan")
    values = TwoMassParams(nan, nan, nan, nan)
    n = len(problem.free)
    cov = np.full((n, n), nan)
    cov.setflags(write=False)
    return FitResult(
        values=values, ci95={k: (nan, nan) for k in PARAM_NAMES}, fitted=problem.free, covariance=cov,
        cost=nan, residual_rms=nan, status="failed", message=message, band=band, options=options,
        f_a=nan, f_r=nan, n_points=int(problem.f.size),
    )
