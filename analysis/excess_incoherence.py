"""The coherence a session loses beyond what its known noises explain, and the bias of H1 that loss stands for.

H1 of a system that is not linear estimates its best linear approximation (BLA: Pintelon & Schoukens, "System
Identification: A Frequency Domain Approach", 2nd ed. 2012, ch. 3), not the linear system underneath. What the
nonlinearity (friction on the load side, backlash) adds to the speed splits in two: a part correlated with the torque,
which moves the BLA away from the underlying system (the *bias*), and a part that is not, which lowers the coherence
like noise (the *stochastic nonlinear distortion*). Both come from the same nonlinear terms and are of the same order;
neither averages away with more segments (the bias is in every segment alike). So the coherence a record loses beyond
what its measured noises explain is the session's own measure of how far H1 may lie from the linear system.

Per bin of the fit band, the coherence that the known causes leave is
γ²_known = γ²_window / ((1 + q²)(1 + r)): the Welch window's own loss on the fitted model (noise-free, through the same
segments, :func:`analysis.estimator_check.model_estimate`), the encoder's quantisation (q² = N_q/G_yy,
:func:`analysis.encoder.quantisation_bound`) and the torque estimate's noise (r = G_nn/G_xx,
:attr:`analysis.frf.FrequencyResponse.noise_ratio`). The excess is e = 1/γ̂² − 1/γ²_known, the unexplained
noise-to-signal ratio: for a distortion of power σ² on the speed, e = σ²/|H|²G_xx, so √e is the relative size of the
distortion, and of the bias, in |H|.

Whether a window of :data:`analysis.adequacy.WINDOW_BINS` bins loses more than its known causes is judged by the
session's own scatter, not a formula: e is formed again on each delete-one-block replicate (the measured FRF's and the
model estimate's, the same segments left out of both, so the window's own loss varies alike in the pair), and the
window's mean excess must stand out of its jackknife standard error by Student's t for B − 1 degrees of freedom,
one-sided at the intervals' 95 % shared (Bonferroni) by the band's windows. (Carter, Knapp & Nuttall's scatter of γ̂²
assumes independent segments; Welch's overlap and a robot's program that does not repeat make the real scatter larger,
and healthy 4 s robot windows stood out of it — session 14.) A window that stands out adds a systematic error of
standard deviation √e to ln H in each of its bins, shared by the window and independent between windows, carried to
the fitted parameters as :func:`analysis.systematic_errors.chain_pull` carries the chain's own. Unlike the jackknife's
scatter it does not shrink with the number of averages; it tops an interval up to its own size, not added to the
interval's other allowances for a model error (:func:`with_excess_floor`). Without replicates (a record too short for
:data:`analysis.frf.MIN_JACKKNIFE_BLOCKS` blocks) nothing calibrates the test and no floor is added.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import stats

from analysis.adequacy import MISFIT_LEVEL, WINDOW_BINS
from analysis.encoder import quantisation_bound
from analysis.fit import Z95
from analysis.fit_problem import FitResult, _jacobian, _Problem, fitted_bins
from analysis.frf import FrequencyResponse
from analysis.systematic_errors import chain_pull


def excess(frf: FrequencyResponse, model_frf: FrequencyResponse, sel: np.ndarray, lsb_rad: float) -> np.ndarray:
    """The excess incoherence e = 1/γ̂² − 1/γ²_known (the unexplained noise-to-signal ratio, see the module's text) at
    the bins ``sel`` (boolean mask of ``frf``'s bins).

    Parameters
    ----------
    frf : FrequencyResponse
        The measured response (or one of its replicates).
    model_frf : FrequencyResponse
        What the Welch estimator makes of the fitted model for the recorded torque over the same segments
        (:func:`analysis.estimator_check.model_estimate`, or its replicate): its coherence is the window's own loss.
    sel : ndarray of bool
        The bins, :func:`analysis.fit_problem.fitted_bins` of the full record.
    lsb_rad : float
        The encoder's resolution, rad.
    """
    g2 = np.clip(frf.coherence[sel], 1e-6, 1.0)
    window = np.clip(model_frf.coherence[sel], 1e-6, 1.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        q = quantisation_bound(frf.f_hz[sel], frf.H[sel], frf.torque_psd[sel], frf.period_s, lsb_rad)
        ratio = np.zeros(g2.size) if frf.noise_ratio is None else frf.noise_ratio[sel]
        known = window / ((1.0 + q**2) * (1.0 + ratio))
        return 1.0 / g2 - 1.0 / known


def replicate_excess(frf: FrequencyResponse, model_frf: FrequencyResponse, band: tuple[float, float],
                     lsb_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`excess` at the fit band's bins (``band``, Hz) of the full record, and of each delete-one-block replicate
    pair (``frf.replicates`` with ``model_frf.replicates``, shape (B, n); B = 0 when either has none or their counts
    differ)."""
    sel = fitted_bins(frf, band)
    full = excess(frf, model_frf, sel, lsb_rad)
    reps, model_reps = frf.replicates or (), model_frf.replicates or ()
    if len(reps) != len(model_reps):
        return full, np.empty((0, full.size))
    return full, np.array([excess(r, m, sel, lsb_rad) for r, m in zip(reps, model_reps)]).reshape(-1, full.size)


def excess_std(e: np.ndarray, replicate_e: np.ndarray) -> np.ndarray:
    """Standard deviation per bin of the systematic error of ln H the excess stands for: √(mean e) in each window of
    :data:`analysis.adequacy.WINDOW_BINS` bins whose mean e (of ``e``, the full record's) stands out of its jackknife
    standard error (from ``replicate_e``, shape (B, n)) by Student's t, one-sided 95 % shared by the windows; 0
    elsewhere, where the mean is not finite (no signal: such bins carry no weight) and without two replicates."""
    std = np.zeros(e.size)
    windows = np.arange(e.size) // WINDOW_BINS
    n_windows = int(windows.max()) + 1 if e.size else 0
    for k in range(n_windows):
        w = windows == k
        m = float(np.mean(e[w]))
        reps = np.mean(replicate_e[:, w], axis=1) if replicate_e.size else np.empty(0)
        reps = reps[np.isfinite(reps)]
        b = reps.size
        if b < 2 or not np.isfinite(m) or m <= 0.0:
            continue
        se = np.sqrt((b - 1) / b * np.sum((reps - reps.mean()) ** 2))
        if m > stats.t.ppf(1.0 - MISFIT_LEVEL / n_windows, b - 1) * se:
            std[w] = np.sqrt(m)
    return std


def excess_pull(frf: FrequencyResponse, fit: FitResult, std: np.ndarray) -> np.ndarray:
    """Covariance of ``fit``'s free log parameters that a systematic error of ``std`` in ln H per bin of its band
    (:func:`excess_std`) may cause, carried through the fit by :func:`analysis.systematic_errors.chain_pull` with K,
    J_m, J_l and C free as the intervals' other floors are."""
    p = len(fit.fitted)
    if not np.any(std > 0):
        return np.zeros((p, p))
    full = _Problem(frf, fit.band, replace(fit.options, params="K,Jm,Jl"), fit.values)
    pull = chain_pull(_jacobian(full, full.x0(fit.values)), full.sqrt_w, std)
    at = [full.free.index(name) for name in fit.fitted]
    return pull[np.ix_(at, at)]


def excess_words(f_hz: np.ndarray, std: np.ndarray) -> str | None:
    """The sentence that names where the excess incoherence stood out (``std`` per bin at ``f_hz``, Hz, from
    :func:`excess_std`) and what it stands for; None where it stood out nowhere."""
    if not np.any(std > 0):
        return None
    on = np.flatnonzero(std > 0)
    worst = int(np.argmax(std))
    return (f"the speed follows the torque less closely at {f_hz[on[0]]:.0f}…{f_hz[on[-1]]:.0f} Hz than the encoder's "
            "resolution and the torque estimate's noise explain (by up to "
            f"{100.0 * std[worst]:.0f} % of |H| near {f_hz[worst]:.0f} Hz): friction in the joint (load or motor "
            "side), backlash, a torque the drive does not measure, or an error on the torque estimate beyond its modelled "
            "noise (hum, interference) — H1 is then the joint's best linear approximation, not its two-mass "
            "response, and the intervals of K, J_m, J_l, C carry the difference: check the joint for friction and the "
            "gear and the coupling for play")


def with_excess_floor(fit: FitResult, frf: FrequencyResponse,
                      model_frf: FrequencyResponse) -> tuple[FitResult, str | None]:
    """``fit`` with each interval widened, symmetrically on the log scale, to at least ±1.96 σ of :func:`excess_pull`,
    the covariance scaled alike (its correlations kept), and :func:`excess_words` (None, and ``fit`` itself, where no
    excess stood out or the encoder's resolution is not known). ``model_frf`` is
    :func:`analysis.estimator_check.model_estimate` with the replicates of ``frf``'s blocks.

    The excess stands for the whole systematic error the nonlinearity may cause, which the interval's own allowances for
    a model error (the misfit's share, the b_v fit's bracket, the H2 reading) may already hold: it tops the interval up
    to its own size, as the quantisation's floor tops up the misfit's share (:func:`analysis.fit._result`), rather than
    adding to it (added, it turned a friction-free robot monitor window poor: K ±4.9 → ±7.0 %, tests/test_monitor.py's
    restart case)."""
    if not fit.options.speed_lsb_rad:
        return fit, None
    std = excess_std(*replicate_excess(frf, model_frf, fit.band, fit.options.speed_lsb_rad))
    pull = excess_pull(frf, fit, std)
    if not np.any(pull):
        return fit, None
    x = np.log([getattr(fit.values, name) for name in fit.fitted])
    floor = Z95 * np.sqrt(np.clip(np.diag(pull), 0.0, None))

    def widened(ci: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        if not ci:
            return ci
        out = dict(ci)
        for name, xi, f in zip(fit.fitted, x, floor):
            with np.errstate(divide="ignore", invalid="ignore"):  # an undetermined 0 … ∞ interval stays so
                half = max(xi - np.log(ci[name][0]), np.log(ci[name][1]) - xi, f)
            out[name] = (float(np.exp(xi - half)), float(np.exp(xi + half)))
        return out

    sigma = np.sqrt(np.clip(np.diag(fit.covariance), 0.0, None))
    scale = np.where(sigma > 0.0, np.maximum(sigma, floor / Z95) / np.where(sigma > 0.0, sigma, 1.0), 1.0)
    cov = np.array(fit.covariance) * np.outer(scale, scale)
    cov.setflags(write=False)
    return (replace(fit, covariance=cov, ci95=widened(fit.ci95),
                    ci95_without_input_noise=widened(fit.ci95_without_input_noise)),
            excess_words(frf.f_hz[fitted_bins(frf, fit.band)], std))


def with_excess_reason(reasons: tuple[str, ...], words: str) -> tuple[str, ...]:
    """``reasons`` (a verdict's, worst first) with ``words`` (:func:`excess_words`) after the last that says an interval
    is wide ("… is known only to …"), or after the last that is no note when none does."""
    at = [i for i, r in enumerate(reasons) if " is known only to " in r]
    if not at:
        at = [i for i, r in enumerate(reasons) if not r.startswith("note:")] or [-1]
    return (*reasons[:at[-1] + 1], words, *reasons[at[-1] + 1:])
