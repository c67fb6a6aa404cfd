"""The spread of a two-mass fit's parameters: the delete-one-block jackknife's covariance of given replicates (the
refits :mod:`analysis.fit` makes, ``_jackknife``) or, linearised, of one Gauss–Newton step per replicate, the inflation
of a residual variance by the correlation of neighbouring Welch bins, and the 95 % intervals a covariance gives. Used
by :mod:`analysis.fit`, which fits, refits and brackets."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import stats

from analysis.fit_problem import PARAM_NAMES, VIBRATION_DAMPING, FitOptions, _Problem
from analysis.model import TwoMassParams

#: The standard normal's 97.5 % quantile: a 95 % interval is ± Z95 σ.
Z95 = 1.959963984540054


def replicate_covariance(xs: Sequence[np.ndarray], n: int) -> tuple[np.ndarray, float]:
    """The delete-one-block jackknife covariance (B − 1)/B · Σ (x_b − x̄)(x_b − x̄)ᵀ of the ``n`` free parameters'
    replicate optima ``xs`` and its 95 % Student-t quantile (B − 1 degrees of freedom); infinite when fewer than two
    replicates or one that diverged (the fit is not stable under the data)."""
    b = len(xs)
    if b < 2 or not np.all(np.isfinite(xs)):
        return np.full((n, n), np.inf), Z95
    d = np.asarray(xs) - np.mean(xs, axis=0)
    return (b - 1) / b * (d.T @ d), float(stats.t.ppf(0.975, b - 1))


def intervals_from_covariance(values: TwoMassParams, free: tuple[str, ...], x: np.ndarray,
                              cov: np.ndarray) -> dict[str, tuple[float, float]]:
    """The 95 % interval exp(ln θ ± 1.96 σ) of each free parameter from the free vector's covariance ``cov`` (b_v's: its
    ratio r ± 1.96 σ times C's share (J_m+J_l) C/J_l, C's own uncertainty left to C's interval); a fixed parameter's is
    its value."""
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    ci = {n: (getattr(values, n), getattr(values, n)) for n in PARAM_NAMES}
    for name, xi, s in zip(free, x, sigma):  # b_v's only in the bracketing fit (analysis.fit)
        if name == VIBRATION_DAMPING:
            share = (values.Jm_kgm2 + values.Jl_kgm2) * values.C_Nms_per_rad / values.Jl_kgm2
            ci[name] = (float((xi - Z95 * s) * share), float((xi + Z95 * s) * share))
        else:
            ci[name] = (float(np.exp(xi - Z95 * s)), float(np.exp(xi + Z95 * s)))
    return ci


def linearised_jackknife(problem: _Problem, x_best: np.ndarray, jac: np.ndarray,
                         options: FitOptions) -> tuple[np.ndarray, float]:
    """:func:`analysis.fit._jackknife` with each replicate's optimum taken one Gauss–Newton step from the full fit's,
    x_b = x̂ − J⁺ r_b(x̂), J the full fit's Jacobian (the linearised jackknife: a replicate lacks one block of B, so its
    optimum lies within a step; the refits by Levenberg–Marquardt took 3–5 iterations of 6 residuals each). For the
    bracketing fit (:func:`analysis.fit._vibration_damping_fit`), whose replicates cost 0.02–0.03 s of a 60 s
    session's 0.4 s."""
    steps = [np.linalg.lstsq(jac, -rep.residuals(x_best), rcond=None)[0]
             for rep in problem.replicate_problems(options)]  # rows as the Jacobian's: the same bins only
    return replicate_covariance(steps, x_best.size)


def correlation_inflation(r: np.ndarray, max_lag: int = 3) -> float:
    """Variance inflation 1 + 2 Σ ρ_k for residuals correlated between neighbouring bins.

    Welch bins overlap (Hann: adjacent bins share much of their window), and a model misfit is
    smooth in frequency, so neighbouring residuals are not independent; the effective number of
    points is N / (1 + 2 Σ ρ_k) with ρ_k the lag-k autocorrelation (positive lags up to
    ``max_lag``, negative values ignored).
    """
    r = r - r.mean()
    denom = float(r @ r)
    if denom <= 0.0 or r.size <= max_lag + 1:
        return 1.0
    rho = [float(r[:-k] @ r[k:]) / denom for k in range(1, max_lag + 1)]
    return 1.0 + 2.0 * sum(max(v, 0.0) for v in rho)
