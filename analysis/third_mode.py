"""A third mode the two-mass model lacks, looked for by its own shape (issue #13).

The window test of :func:`analysis.adequacy.band_misfits` judges each stretch of 8 bins on its own: it sees any misfit,
but a third mass behind the load spreads its trace over many bins — a dipole above the resonance, a shift of the
anti-resonance, a slope the fit half absorbs into K and J — so on a short record, with a 500 Hz encoder or with an
undithered motion whose quantisation repeats, no one window stands out although together they do, and K reads 2.5–4 %
low with an `ok` (README "How well it works"). Here the misfit is projected onto the shape a third mass would leave:

* the model with a small third mass J_3 = a·J_l at f_3 behind the load (:func:`analysis.model.third_mass_load_factor`),
  through the fit's own model of the Welch estimate, gives the signature s(f_3) = ∂ ln H/∂a;
* the fit absorbs part of it into K, J, C: the parameters move by a·J⁺s (J the fit's weighted Jacobian) and the rest,
  e = s − J·J⁺s, stays in the residual, so the misfit ln|H_model| − ln|H_meas| ≈ −a·e;
* â is the weighted least-squares amplitude of −e in the misfit, each bin weighted by the inverse of what it may hold
  besides (the jackknife's scatter per bin, the quantisation that repeats with the motion, the chain's smooth error,
  the loop's feedback bound squared); its standard error from the delete-one-block replicates (everything that varies
  along the record) and the systematic terms carried as in the window test, the loop's bound taken off â as a bound;
* a mass is positive: one-sided Student t with B − 1 degrees of freedom at :data:`analysis.adequacy.MISFIT_LEVEL`,
  shared by the effectively independent candidates (Li & Ji's M_eff of the candidates' correlation).

A mode that is there but moves K less than K's own interval does no harm to the result: it is reported only when the
K it pulls, â·∂ln K/∂a, lies beyond K's 95 % interval half-width — the same linear propagation the fit's intervals
use. Nothing here is measured on a simulator; the two constants below say what they assume.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from analysis.adequacy import MISFIT_LEVEL, WINDOW_BINS
from analysis.model import third_mass_load_factor

#: Damping ratio of the candidate third modes. A bolted or bearing-supported structural mode of a robot arm or tool is
#: damped ζ ≈ 0.01–0.1; the signature is smoothed by the Welch window's kernel (a few bins, ≥ 2 Hz) and by the fit's
#: absorption, so within that range it changes shape little (the simulated third masses, ζ = 0.02, are found with it).
THIRD_MODE_DAMPING = 0.05
#: J_3/J_l at which the signature is taken by difference: small enough to be linear (the signature's second-order
#: term is ~a), large enough that the difference is far above rounding (ln H to ~1e-16, steps ~1e-4).
SIGNATURE_STEP = 1e-4


@dataclass(frozen=True)
class ThirdMode:
    """The most evident third mode of a fit's misfit.

    Attributes
    ----------
    f_hz : float
        The candidate's f_3 (the third mass's natural frequency with the load held), Hz.
    mass_ratio : float
        â = J_3/J_l the misfit holds of that shape.
    t, t_crit : float
        Its one-sided t (after the loop's bound) and the level it must pass.
    k_shift : float
        Relative shift of the fitted K that a third mass of â causes (−0.04: K reads 4 % low).
    k_halfwidth : float
        K's 95 % interval half-width (relative) it is compared with.
    """

    f_hz: float
    mass_ratio: float
    t: float
    t_crit: float
    k_shift: float
    k_halfwidth: float

    @property
    def found(self) -> bool:
        """Beyond noise and moving K beyond its interval."""
        return self.t > self.t_crit and abs(self.k_shift) > self.k_halfwidth


def candidate_frequencies(f_a_hz: float, band_hz: tuple[float, float]) -> np.ndarray:
    """The f_3 looked at, Hz: from the anti-resonance (a mass below it would make a different two-mass joint) to the
    band's top, each 1 + ζ above the last so that neighbouring signatures overlap at their half-power width."""
    low = max(f_a_hz, band_hz[0]) if np.isfinite(f_a_hz) else band_hz[0]
    high = band_hz[1]
    if not (0.0 < low < high):
        return np.empty(0)
    n = int(np.ceil(np.log(high / low) / np.log1p(THIRD_MODE_DAMPING))) + 1
    return np.geomspace(low, high, n)


def effective_tests(corr: np.ndarray) -> float:
    """Li & Ji's (2005) effective number of independent tests: Σ I(λ ≥ 1) + (λ − ⌊λ⌋) over the eigenvalues λ of
    the tests' correlation matrix (statsmodels' multipletests takes the number of tests, not correlated ones)."""
    lam = np.abs(np.linalg.eigvalsh(corr))
    whole = np.floor(lam + 1e-9)  # an eigenvalue of 4 computed as 3.999…: whole, not 3 and a fraction
    return float(max(np.sum((whole >= 1.0) + np.clip(lam - whole, 0.0, None)), 1.0))


def third_mode(f_hz: np.ndarray, misfit: np.ndarray, replicate_misfits: np.ndarray,
               log_ratios: Callable[[Callable[[np.ndarray], np.ndarray] | None], np.ndarray],
               jac: np.ndarray, sqrt_w: np.ndarray, k_column: int, k_halfwidth: float,
               candidates_hz: np.ndarray, *, systematic_cov: np.ndarray | None = None,
               blind: np.ndarray | None = None, chain_std: float = 0.0,
               bias_bound: np.ndarray | None = None) -> ThirdMode | None:
    """The candidate third mode with the largest t among those beyond noise (else the largest t of all).

    Parameters
    ----------
    f_hz, misfit, replicate_misfits, systematic_cov, blind, chain_std, bias_bound
        As :func:`analysis.adequacy.band_misfits` takes them (the fit band's bins, Hz; ln|H_model| − ln|H_meas| of the
        record, shape (n,), and of each delete-one-block replicate, (B, n); the quantisation's carried covariance;
        bins not to judge; the chain's window error; the loop's bias bound per bin).
    log_ratios : callable
        ln(H_model/H_meas) at the bins for a load inertia factor (:func:`analysis.fit.model_log_ratios`).
    jac, sqrt_w : ndarray
        The fit's weighted Jacobian (m = n or 2n rows: amplitude, then phase) and its bin weights' square roots
        (:func:`analysis.fit.residual_jacobian`).
    k_column : int
        Jacobian column of ln K.
    k_halfwidth : float
        K's 95 % interval half-width, relative.
    candidates_hz : ndarray
        f_3 to look at (:func:`candidate_frequencies`), Hz.

    Returns
    -------
    ThirdMode or None
        None with fewer than two replicates, no candidate or no bin to judge.
    """
    reps = np.asarray(replicate_misfits, dtype=float)
    b = reps.shape[0] if reps.ndim == 2 else 0
    n = f_hz.size
    judged = np.isfinite(misfit) & (sqrt_w > 0) & np.all(np.isfinite(reps), axis=0) if b else np.zeros(n, bool)
    if blind is not None:
        judged &= ~blind
    if b < 2 or candidates_hz.size == 0 or not np.any(judged):
        return None
    m = np.where(judged, misfit, 0.0)
    reps = np.where(judged[None, :], reps, 0.0)
    carried = np.zeros((n, n)) if systematic_cov is None else np.where(np.outer(judged, judged), systematic_cov, 0.0)
    bound = np.zeros(n) if bias_bound is None else np.where(judged & np.isfinite(bias_bound), bias_bound, 0.0)
    window = np.arange(n) // WINDOW_BINS
    chain_cov = (window[:, None] == window[None, :]) * chain_std**2
    variance = (b - 1) / b * np.sum((reps - reps.mean(axis=0)) ** 2, axis=0) + np.diag(carried) + chain_std**2 + bound**2
    variance = np.where(judged & (variance > 0), variance, np.inf)

    base = log_ratios(None)
    pinv = np.linalg.pinv(jac)
    parts = jac.shape[0] // n
    rows = []
    for f3 in candidates_hz:
        s = (log_ratios(lambda f, f3=f3: third_mass_load_factor(f, SIGNATURE_STEP, f3, THIRD_MODE_DAMPING))
             - base) / SIGNATURE_STEP
        sv = sqrt_w * s.real if parts == 1 else np.concatenate([sqrt_w * s.real, sqrt_w * s.imag])
        moved = pinv @ sv  # the log parameters' move per unit J_3/J_l
        left = (sv - jac @ moved)[:n] / np.where(sqrt_w > 0, sqrt_w, 1.0)  # what stays in ln|H|'s residual
        left = np.where(judged, left, 0.0)
        energy = float(np.sum(left**2 / variance))
        if not energy > 0:
            continue
        v = -left / variance / energy  # â = v·misfit: the misfit is −a·left
        a_hat = float(v @ m)
        a_reps = reps @ v
        noise2 = (b - 1) / b * float(np.sum((a_reps - a_reps.mean()) ** 2))
        systematic2 = float(v @ carried @ v + v @ chain_cov @ v)
        scale = float(np.sqrt(noise2 + systematic2))
        t = (a_hat - float(np.abs(v) @ bound)) / scale if scale > 0 else 0.0
        rows.append((float(f3), a_hat, t, float(a_hat * moved[k_column]), v * np.sqrt(np.where(judged, variance, 0.0))))
    if not rows:
        return None
    unit = np.array([r[4] / np.linalg.norm(r[4]) for r in rows])
    t_crit = float(stats.t.ppf(1.0 - MISFIT_LEVEL / effective_tests(unit @ unit.T), b - 1))
    beyond = [r for r in rows if r[2] > t_crit and abs(r[3]) > k_halfwidth]
    f3, a_hat, t, k_shift, _ = max(beyond or rows, key=lambda r: r[2])
    return ThirdMode(f3, a_hat, t, t_crit, k_shift, k_halfwidth)
