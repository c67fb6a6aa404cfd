"""How well the two-mass model fits a session's own FRF: the misfit's share of the intervals, and where it fails.

Two questions, both answered from the session's own data (issue #13):

* **How much could the misfit move the parameters?** The fit's weighted residual is what the model leaves
  unexplained — noise, the chain's own small errors, and whatever the two-mass model lacks (a third mode,
  backlash). :func:`misfit_covariance` treats it as a correlated error with the residual's observed size
  and correlation along frequency and propagates it to the log parameters — the heteroskedasticity and
  autocorrelation consistent (HAC, Newey–West) sandwich (JᵀJ)⁻¹ Ŝ (JᵀJ)⁻¹ with a Bartlett kernel, its
  bandwidth by Andrews' (1991) AR(1) plug-in rule. statsmodels has the kernel but only for its own
  regression results, not for a residual vector and Jacobian from ``scipy.optimize.least_squares``, hence
  the dozen lines here. It replaces a constant systematic floor measured on the simulator: where the model
  fits to the noise it is small (±0.2 % on K with a 2^20 counts/rev encoder), where it does not it widens
  the interval by what the residual shows (backlash: ±4 %).
* **Where does the model miss more than noise explains?** :func:`band_misfits` averages the misfit of
  ln|H| over windows of bins and compares each mean with its own scatter between the delete-one-block
  replicates of the FRF (the jackknife of that mean: it sees everything that varies along the record and
  the correlation between neighbouring bins) and with what the errors no scatter shows can bias it there
  (the encoder's quantisation that repeats with the motion, the chain's own, the loop's feedback:
  :mod:`analysis.systematic_errors`). A window counts as missed when its Student t (B − 1 degrees of
  freedom) passes the 95 % level after Bonferroni's correction for the number of windows. The scatter is never taken
  below the random error that the torque estimate's own modelled noise gives (:func:`coherence_variance`): that noise
  is in the record whatever else is, so a scatter below it is a low draw of B − 1 degrees of freedom — or an error in
  every block, which no scatter shows (:func:`band_misfits`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

# Bins per window of :func:`band_misfits`: two main lobes of the Hann window (4 bins each), so that the
# windows, stepped by half their width, are nearly independent and a resonance (a few bins wide at 0.5 s
# segments) fills one.
WINDOW_BINS = 8
# Family-wise level of the misfit test: the same 95 % as the intervals.
MISFIT_LEVEL = 0.05


def misfit_covariance(residual: np.ndarray, jac: np.ndarray, n_bins: int) -> np.ndarray:
    """HAC covariance of the fitted log parameters from the weighted residual's own size and correlation.

    Parameters
    ----------
    residual : ndarray, shape (m,)
        Weighted residuals at the optimum: one run of ``n_bins`` along frequency per residual kind
        (amplitude; amplitude then phase for a complex fit).
    jac : ndarray, shape (m, p)
        Their Jacobian with respect to the log parameters.
    n_bins : int
        Length of one run (the band's bins); the autocovariance is taken within each run.

    Returns
    -------
    ndarray, shape (p, p)
        (JᵀJ)⁻¹ Ŝ (JᵀJ)⁻¹ with Ŝ = Σ_l k(l) Σ_i g_i g_{i+l}ᵀ, g_i = J_iᵀ r_i, Bartlett k(l) = 1 − l/(L+1).
    """
    r = np.asarray(residual, dtype=float)
    J = np.asarray(jac, dtype=float)
    bread = np.linalg.pinv(J.T @ J)
    meat = np.zeros((J.shape[1], J.shape[1]))
    for start in range(0, r.size, n_bins):
        rr, g = r[start:start + n_bins], J[start:start + n_bins] * r[start:start + n_bins, None]
        lag = bandwidth_bins(rr)
        meat += g.T @ g
        for k in range(1, lag + 1):
            gk = g[:-k].T @ g[k:]
            meat += (1.0 - k / (lag + 1.0)) * (gk + gk.T)
    return bread @ meat @ bread


def bandwidth_bins(r: np.ndarray) -> int:
    """Bartlett bandwidth (bins) by Andrews' AR(1) plug-in: 1.1447 (α n)^{1/3}, α = 4ρ²/((1−ρ)²(1+ρ)²).

    ρ is the residual's lag-1 autocorrelation, clipped to 0…0.97 (a residual that alternates in sign needs
    no bandwidth; one that never does would need the whole band).
    """
    d = r - r.mean()
    denom = float(d @ d)
    if r.size < 3 or denom <= 0.0:
        return 0
    rho = float(np.clip(d[:-1] @ d[1:] / denom, 0.0, 0.97))
    alpha = 4.0 * rho**2 / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    return int(min(np.floor(1.1447 * (alpha * r.size) ** (1.0 / 3.0)), r.size - 1))


def coherence_variance(coherence: np.ndarray, n_segments: int) -> np.ndarray:
    """Variance per bin of ln|H1| that random noise costing the coherence γ² gives: (1 − γ²)/(2γ²·n_d) over n_d
    averaged segments (Bendat & Piersol, *Random Data*, 4th ed., eq. 9.90: the normalised random error of |H1| is
    √(1 − γ²)/(|γ|·√(2n_d))); infinite where γ² is not positive. The segments' 50 % overlap is not counted against
    n_d (Welch's factor 1.06 for a Hann window): the variance is, if anything, low."""
    g2 = np.asarray(coherence, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(g2 > 0.0, (1.0 - np.clip(g2, 0.0, 1.0)) / (2.0 * g2 * max(n_segments, 1)), np.inf)


@dataclass(frozen=True)
class BandMisfit:
    """The two-mass model's misfit of ln|H| in one window of the fit band.

    Attributes
    ----------
    low_hz, high_hz : float
        The window's first and last bin, Hz.
    misfit : float
        Mean of ln|H_model| − ln|H_measured| over the window (≈ relative misfit of |H|, 0.05 = 5 %).
    noise : float
        Its standard error: the scatter between the delete-one-block replicates, or, where larger, the random error
        the torque estimate's modelled noise gives the window's mean (``random_variance`` of :func:`band_misfits`).
    systematic : float
        Standard deviation of the window mean's bias that the session cannot show by scatter but allows for (the
        share of the encoder's quantisation that repeats with the motion, carried through the fit, the chain's own
        approximations and the loop's feedback of the rest of the quantisation; 0 when none is given, infinite where
        it is unbounded).
    bound : float
        The most a bias of known sign-less size can move the window's mean (the speed loop's feedback of the
        quantisation noise, :func:`analysis.systematic_errors.loop_feedback_bound`): taken off |misfit| before it is
        compared.
    t : float
        max(|misfit| − bound, 0) / √(noise² + systematic²).
    """

    low_hz: float
    high_hz: float
    misfit: float
    noise: float
    systematic: float
    t: float
    bound: float = 0.0


def band_misfits(f_hz: np.ndarray, misfit: np.ndarray, replicate_misfits: np.ndarray,
                 systematic_cov: np.ndarray | None = None,
                 blind: np.ndarray | None = None,
                 chain_std: float = 0.0,
                 bias_bound: np.ndarray | None = None,
                 random_variance: np.ndarray | None = None) -> tuple[BandMisfit, ...]:
    """The misfit of ln|H| per window of :data:`WINDOW_BINS` bins, stepped by half a window.

    Parameters
    ----------
    f_hz : ndarray, shape (n,)
        The fit band's bins, Hz.
    misfit : ndarray, shape (n,)
        ln|H_model| − ln|H_measured| at those bins, the full record.
    replicate_misfits : ndarray, shape (B, n)
        The same for each delete-one-block replicate (the model held at the full record's fit).
    systematic_cov : ndarray, shape (n, n), optional
        Covariance of the misfit's bias that the replicates cannot show but the test allows for (the encoder's
        quantisation carried through the fit, :func:`analysis.systematic_errors.quantisation_through_fit`); a window
        allows the variance of its mean.
    blind : ndarray of bool, shape (n,), optional
        Bins whose bias is unbounded (no signal to compare the quantisation with): a window holding one is not
        judged.
    chain_std : float, optional
        Standard deviation of every window's mean that the chain's smooth errors allow
        (:data:`analysis.systematic_errors.CHAIN_WINDOW_STD`); 0: none.
    bias_bound : ndarray, shape (n,), optional
        The most a bias may move each bin (:func:`analysis.systematic_errors.loop_feedback_bound`): a window takes its
        mean off |misfit|; None: none.
    random_variance : ndarray, shape (n,), optional
        Variance per bin of ln|H| that a noise known to be in the record gives (:func:`coherence_variance` of the
        coherence 1 − ν the torque estimate's modelled noise share ν alone would leave,
        :attr:`analysis.frf.FrequencyResponse.noise_ratio`): a window's standard error is never taken below
        √(mean/WINDOW_BINS) of it (its bins' errors taken as independent, the smaller reading: neighbouring bins of
        overlapped segments are correlated, which would raise it — a floor, not an estimate); None: the replicates'
        scatter alone. Where the floor sets the error it is still judged at the t of B − 1 degrees of freedom, though
        the model's variance has those of every segment averaged: stricter than it need be, never laxer. The
        replicates see that noise with B − 1 degrees of freedom, the model with those of every segment averaged; on a healthy one-phase robot window (configs/benches/sim_robot.toml, seed 0 at 160 s) the
        scatter of 178–192 Hz read 0.49 % against the model's 0.71 % and a misfit of the one-phase estimate's error,
        +3.2 % (+0.5 % with two phases), passed as a third mode at t 4.5 (level 4.3). The coherence measured is no
        such floor: it also holds the Welch window's own loss at the motion's lines and at the resonance, which is no
        random error (on the paper plant it would have raised the scatter at 10–24 Hz by a third and hidden a 4 %
        backlash-like dip, tests/test_analysis_adequacy.py).

    Returns
    -------
    tuple of BandMisfit
        Empty when there are fewer than two replicates or fewer bins than a window.
    """
    reps = np.asarray(replicate_misfits, dtype=float)
    b = reps.shape[0] if reps.ndim == 2 else 0
    if b < 2 or f_hz.size < WINDOW_BINS:
        return ()
    out = []
    for i in range(0, f_hz.size - WINDOW_BINS + 1, WINDOW_BINS // 2):
        w = slice(i, i + WINDOW_BINS)
        mean_b = reps[:, w].mean(axis=1)
        noise = float(np.sqrt((b - 1) / b * np.sum((mean_b - mean_b.mean()) ** 2)))
        if random_variance is not None:
            noise = max(noise, float(np.sqrt(np.mean(random_variance[w]) / WINDOW_BINS)))
        quant = 0.0 if systematic_cov is None else float(np.sqrt(max(np.mean(systematic_cov[w, w]), 0.0)))
        quant = float(np.hypot(quant, chain_std))
        if (blind is not None and np.any(blind[w])) or not np.isfinite(quant):
            quant = np.inf  # unbounded (or not computable): the window is not judged
        m = float(np.mean(misfit[w]))
        bound = 0.0 if bias_bound is None else float(np.mean(bias_bound[w]))
        excess = max(abs(m) - bound, 0.0) if np.isfinite(bound) else 0.0
        scale = float(np.hypot(noise, quant))
        if not (np.isfinite(m) and np.isfinite(noise)):
            t = 0.0  # a window with a non-finite misfit or scatter is not judged, never "missed"
        else:
            t = excess / scale if scale > 0 else (np.inf if excess > 0 else 0.0)
        out.append(BandMisfit(float(f_hz[i]), float(f_hz[i + WINDOW_BINS - 1]), m, noise, quant, float(t), bound))
    return tuple(out)



def critical_t(n_windows: int, n_replicates: int) -> float:
    """Student t beyond which a window's misfit is more than noise: two-sided :data:`MISFIT_LEVEL` shared
    by the independent windows (every other one of the half-overlapping windows), B − 1 degrees of freedom."""
    independent = max((n_windows + 1) // 2, 1)
    return float(stats.t.ppf(1.0 - MISFIT_LEVEL / (2.0 * independent), max(n_replicates - 1, 1)))


def missed_spans(windows: tuple[BandMisfit, ...], t_crit: float) -> list[tuple[float, float, BandMisfit]]:
    """Runs of overlapping windows beyond ``t_crit`` as (low Hz, high Hz, worst window), worst first."""
    spans: list[tuple[float, float, BandMisfit]] = []
    for w in windows:
        if not w.t > t_crit:
            continue
        if spans and w.low_hz <= spans[-1][1]:
            lo, _, worst = spans[-1]
            spans[-1] = (lo, w.high_hz, worst if worst.t >= w.t else w)
        else:
            spans.append((w.low_hz, w.high_hz, w))
    return sorted(spans, key=lambda s: -s[2].t)
