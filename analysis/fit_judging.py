"""What judges a finished fit against the FRF (:mod:`analysis.quality`, :mod:`analysis.estimator_check`,
:mod:`analysis.third_mode`): the band it is judged in, its model's log ratio to the measurement for the record, each
replicate and any load, the log ratio's Jacobian, and the quantisation terms at its bins."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from analysis.systematic_errors import lines_per_bin
from analysis.encoder import quantisation_bound
from analysis.fit_problem import (FitKind, FitResult, _central_differences, _Problem, default_band_hz, fitted_bins,
                                  wrapped)
from analysis.frf import KERNEL_PER_BIN, FrequencyResponse


def judged_fit(frf: FrequencyResponse, fit: FitResult) -> FitResult:
    """``fit`` with its band widened up to the default band's top (:func:`default_band_hz`) where it ends below:
    the fitted model is judged against all of the FRF the encoder resolves. A band chosen to end below a mode does
    not remove the mode's pull on K (a third mass at 160–190 Hz with the band ending at 150 Hz: K −3 % with an
    interval of ±0.5 %), so the misfit tests look there too."""
    top = default_band_hz(frf.period_s)[1]
    return fit if fit.band[1] >= top else replace(fit, band=(fit.band[0], top))


def quantisation_terms(frf: FrequencyResponse, band: tuple[float, float],
                       lsb_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """At a fit's bins in ``band`` (Hz): the white-quantisation bound of |H| for the encoder's resolution ``lsb_rad``
    (:func:`analysis.encoder.quantisation_bound`; inf where there is no signal) and the motion's lines per bin
    (:func:`analysis.systematic_errors.lines_per_bin`) — what the intervals' floor and the misfit test carry through the fit."""
    sel = fitted_bins(frf, band)
    f = frf.f_hz[sel]
    bound = quantisation_bound(f, frf.H[sel], frf.torque_psd[sel], frf.period_s, lsb_rad)
    return bound, lines_per_bin(frf.torque_psd_fine, frf.f_hz[1] / KERNEL_PER_BIN, f, frf.f_hz[1])


def log_ratio_jacobian(frf: FrequencyResponse, fit: FitResult) -> tuple[np.ndarray, np.ndarray]:
    """d ln(H_model/H_meas)/d x of a fit at its optimum, x its free log parameters (central differences, step 1e-6;
    the model as the fit sees the Welch estimate), and the square roots of its bin weights.

    Returns
    -------
    jac : ndarray of complex, shape (n, p)
        At the band's bins: the real part moves ln|H|, the imaginary part the phase.
    sqrt_w : ndarray, shape (n,)
    """
    problem = _Problem(frf, fit.band, fit.options, fit.values)
    return _central_differences(problem.log_ratio, problem.x0(fit.values)), problem.sqrt_w


def weighted_jacobian(jac: np.ndarray, sqrt_w: np.ndarray, kind: FitKind) -> np.ndarray:
    """The Jacobian of a fit's weighted residuals from :func:`log_ratio_jacobian`: amplitude rows, then (a complex
    fit) phase rows, each bin times its weight's square root; shape (n, p) or (2n, p)."""
    rows = [sqrt_w[:, None] * jac.real]
    if kind == "complex":
        rows.append(sqrt_w[:, None] * jac.imag)
    return np.concatenate(rows, axis=0)


def kernel_model_log_ratio(frf: FrequencyResponse, fit: FitResult) -> np.ndarray:
    """ln(H_model/H_meas) of a fit's values against ``frf`` (complex, at the fit band's bins of ``frf``), the model as
    the fit sees the Welch estimate (:meth:`_Problem.log_ratio`)."""
    return model_log_ratios(frf, fit)(None)


def model_log_ratios(frf: FrequencyResponse,
                     fit: FitResult) -> Callable[[Callable[[np.ndarray], np.ndarray] | None], np.ndarray]:
    """ln(H_model/H_meas) of a fit's values against ``frf`` as the fit sees the Welch estimate, for any load: a
    function of the load inertia's factor (a function of f_hz, :func:`analysis.model.frequency_response`; None: the
    fit's rigid load) returning the complex log ratio at the fit band's bins. The fit's kernel and fold-over model is
    built once for all the loads asked for."""
    problem = _Problem(frf, fit.band, fit.options, fit.values)
    x = problem.x0(fit.values)

    def at(load_factor: Callable[[np.ndarray], np.ndarray] | None) -> np.ndarray:
        problem.load_factor = load_factor
        return problem.log_ratio(x)

    return at


def model_misfits(frf: FrequencyResponse, fit: FitResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ln(H_model/H_measured) of a fit at its band's bins, for the full record and each replicate: the real part is
    ln|H_model| − ln|H_measured|, the imaginary part the phase difference (radians, wrapped to ±π).

    Parameters
    ----------
    frf : FrequencyResponse
        The measured response the fit was made to (its ``replicates`` give the second array).
    fit : FitResult
        A fit of ``frf`` that did not fail.

    Returns
    -------
    f_hz : ndarray, shape (n,)
        The band's bins, Hz.
    misfit : ndarray of complex, shape (n,)
        The full record's misfit (the model as the Welch estimator sees it, :class:`_Problem`).
    replicate_misfits : ndarray of complex, shape (B, n)
        The same model against each delete-one-block replicate (B = 0 without replicates).
    """
    problem = _Problem(frf, fit.band, fit.options, fit.values)
    x = problem.x0(fit.values)
    reps = [wrapped(p.log_ratio(x)) for p in problem.replicate_problems(fit.options)]
    return problem.f, wrapped(problem.log_ratio(x)), np.asarray(reps, dtype=complex).reshape(len(reps), problem.f.size)
