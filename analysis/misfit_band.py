"""Where the fitted two-mass model misses the session's |H| beyond what noise and the errors no scatter shows explain.

The window test of :mod:`analysis.adequacy` with the allowances of :mod:`analysis.systematic_errors`, the third
mode of :mod:`analysis.third_mode`, and — for a torque read from one phase through the angle — whether the
estimate's own error (:mod:`analysis.input_noise`) explains the whole misfit; :mod:`analysis.quality` words the
verdict from it.
"""

from __future__ import annotations

import numpy as np

from analysis.adequacy import BandMisfit, band_misfits, coherence_variance, critical_t, missed_spans
from analysis.fit import band_mask, judged_fit, log_ratio_jacobian, model_log_ratios, model_misfits, quantisation_terms
from analysis.fit_problem import FitResult, fitted_bins, rel_halfwidth
from analysis.frf import FrequencyResponse
from analysis.input_noise import EstimateError, estimate_error_misfit
from analysis.sample_instants import EncoderJitter
from analysis.systematic_errors import (CHAIN_WINDOW_STD, loop_feedback_bound, quantisation_through_fit,
                                        spread_beyond_fit)
from analysis.third_mode import ThirdMode, candidate_frequencies, third_mode


def missed_band(frf: FrequencyResponse, fit: FitResult, jitter: EncoderJitter, kernel_error: np.ndarray | None,
                 use_phase: bool, torque_from_angle: bool = False
                 ) -> tuple[tuple[float, float, BandMisfit] | None, ThirdMode | None,
                            tuple[tuple[float, float, float, float], ...], tuple[tuple[float, float], ...],
                            EstimateError | None]:
    """Where the model misses |H| beyond noise and the encoder's quantisation (:mod:`analysis.adequacy`): the worst
    stretch of the band (low Hz, high Hz, worst window) or None, the most evident third mode
    (:mod:`analysis.third_mode`, judging the phase too when ``use_phase``) or None, the windows judged
    (:attr:`analysis.quality.Quality.misfit_windows`), the bins judged (:attr:`analysis.quality.Quality.misfit_bins`)
    and — for a torque read from one phase through the angle (``torque_from_angle``) whose misfit is all the
    estimate's own error, as the session's coherence at the resonance sizes it
    (:func:`analysis.input_noise.estimate_error_misfit`: no window is missed once its pattern is taken off) — that
    error; else None.

    The fitted model is judged up to the default band's top even where the fit's band ends below it
    (:func:`analysis.fit.judged_fit`; ``kernel_error`` at those bins), against the measurement as the Welch estimator
    really sees it (the fit's kernel model corrected by ``kernel_error``, :mod:`analysis.estimator_check`). The
    allowance: the jackknife's scatter, never below the random error the torque estimate's modelled noise gives
    (``random_variance`` of :func:`analysis.adequacy.band_misfits`); the share of the encoder's quantisation error
    that repeats with every motion period (``jitter.repeating_share``; the scatter cannot show it) — a random-phase
    error of the white-quantisation bound √(N_q/|H·D|²G_xx) at each line of the motion, carried through the fit
    (:func:`analysis.systematic_errors.quantisation_through_fit`); beyond the fitted band the model's own spread from
    its parameters' covariance (:func:`analysis.systematic_errors.spread_beyond_fit`); the chain's smooth errors
    (:data:`analysis.systematic_errors.CHAIN_WINDOW_STD`); and, taken off the misfit as the bound it is, the speed
    loop's feedback of the rest of the quantisation (:func:`analysis.systematic_errors.loop_feedback_bound`).
    """
    seen = judged_fit(frf, fit)
    f, misfit, reps = model_misfits(frf, seen)
    if kernel_error is not None and kernel_error.shape == misfit.shape:
        misfit, reps = misfit + kernel_error, reps + kernel_error[None, :]
    quant, lines = quantisation_terms(frf, seen.band, jitter.lsb_rad)
    jac, sqrt_w = log_ratio_jacobian(frf, seen)
    fitted = band_mask(f, fit.band)
    with np.errstate(invalid="ignore", divide="ignore"):
        carried = jitter.repeating_share * quantisation_through_fit(quant, lines, jac, sqrt_w, fit.options.kind,
                                                                    fitted, phase=use_phase)
    beyond = spread_beyond_fit(jac, fit.covariance, fitted, phase=use_phase)
    unknown = ~np.all(np.isfinite(beyond)) & ~fitted  # the parameters' spread unknown: no judging beyond the fit
    carried = carried + np.where(np.isfinite(beyond), beyond, 0.0)
    blind = ~np.isfinite(quant) | ~np.isfinite(lines) | ~(sqrt_w > 0) | unknown
    bound = loop_feedback_bound(quant, jitter.repeating_share)
    random = (None if frf.noise_ratio is None
              else coherence_variance(1.0 - frf.noise_ratio[fitted_bins(frf, seen.band)], frf.n_segments))
    windows = band_misfits(f, misfit.real, reps.real, carried[:f.size, :f.size], blind, CHAIN_WINDOW_STD, bound,
                           random)
    t_crit = critical_t(len(windows), reps.shape[0])
    spans = missed_spans(windows, t_crit)
    judged = tuple((w.low_hz, w.high_hz, w.misfit, w.bound + t_crit * float(np.hypot(w.noise, w.systematic)))
                   for w in windows if np.isfinite(w.misfit))
    mode = None
    if "K_Nm_per_rad" in fit.fitted:
        mode = third_mode(f, misfit, reps, model_log_ratios(frf, seen), jac, sqrt_w, fit.options.kind,
                          fit.fitted.index("K_Nm_per_rad"), rel_halfwidth(fit, "K_Nm_per_rad"),
                          candidate_frequencies(fit.f_a, seen.band), fitted=fitted, use_phase=use_phase,
                          systematic_cov=carried, blind=blind, chain_std=CHAIN_WINDOW_STD, bias_bound=bound,
                          random_variance=random)
    bins = tuple((float(fb), float(m)) for fb, m in zip(f, misfit.real))
    estimate = None
    if spans and torque_from_angle:
        estimate = estimate_error_misfit(frf, fit.values, fit.band, fitted_bins(frf, seen.band), jac, sqrt_w,
                                         fit.options.kind, fitted)
        if estimate is not None and missed_spans(band_misfits(
                f, misfit.real - estimate.misfit, reps.real - estimate.misfit[None, :], carried[:f.size, :f.size],
                blind, CHAIN_WINDOW_STD, bound, random), t_crit):
            estimate = None  # the estimate's error does not explain all of the misfit: the joint's advice stands
    return (spans[0] if spans else None), mode, judged, bins, estimate
