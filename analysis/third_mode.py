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
  besides (the jackknife's scatter averaged over a window of bins, the quantisation that repeats with the motion, the
  chain's smooth error, the loop's feedback bound squared); its standard error from the delete-one-block replicates (everything that varies
  along the record) and the systematic terms carried as in the window test, the loop's bound taken off â as a bound;
* with the clocks aligned the phase is judged too — the trace of a lightly damped mode is as plain in it as in
  |H| (an amplitude fit leaves it all in the residual) — with a delay common to all bins (what is left of the clock
  offset) estimated beside the mode and taken out; |H| alone must confirm the mode at the one-sided 95 % level (the
  phase's own systematic errors near the band's top are not all known: alone it read four healthy runs of the
  scenario family as a mode near 360–480 Hz that |H| put below zero);
* a mass is positive: one-sided Student t with B − 1 degrees of freedom at :data:`analysis.adequacy.MISFIT_LEVEL`,
  shared by the effectively independent candidates (Li & Ji's M_eff of the candidates' correlation).

A mode that is there but moves K less than K's own interval does no harm to the result: it is reported only when the
K it pulls, â·∂ln K/∂a — the same linear propagation the fit's intervals use — lies beyond K's 95 % interval
half-width by more than its own noise: the pull of â's one-sided 95 % lower bound (â less Student's t at B − 1 degrees
of freedom times its jackknife standard error, after the loop's bound), the level |H| confirms at. The pull of â
itself is no test: where a third mass leaves little trace (f_3 above the resonance, near the coupled mode at
~180–190 Hz of a 55/95 Hz joint) â is large and uncertain, and its pull lies beyond K's interval by noise alone — on
healthy simulated robot windows â 0.10–0.13 at 176–193 Hz pulled K −1.3…−1.4 % against K's ±0.8–0.9 % at t 1.1–1.5,
so there the K test added nothing to the t test. Nothing here is measured on a simulator; the two constants below say
what they assume.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from analysis.adequacy import MISFIT_LEVEL, WINDOW_BINS
from analysis.fit import FitKind, weighted_jacobian
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
    t_amplitude, t_confirm : float
        The t of |H| alone (the same as ``t`` when the phase is not judged) and the one-sided level it must pass: a
        mode leaves its trace in |H| and in the phase alike, so the phase alone — whose systematic errors near the
        band's top are not all known (an anti-alias filter's phase curvature, the difference operator's) — does not
        make a mode.
    t_pull : float
        The t of its pull on K beyond K's interval, (|k_shift| − k_halfwidth)/(the pull's standard error), after the
        loop's bound (−inf when the mode does not move K): it must pass ``t_confirm`` too — the pull's one-sided 95 %
        lower bound beyond K's interval.
    """

    f_hz: float
    mass_ratio: float
    t: float
    t_crit: float
    k_shift: float
    k_halfwidth: float
    t_amplitude: float
    t_confirm: float
    t_pull: float

    @property
    def found(self) -> bool:
        """Beyond noise (|H| confirming it) and moving K beyond its interval by more than the pull's own noise."""
        return self.t > self.t_crit and self.t_amplitude > self.t_confirm and self.t_pull > self.t_confirm


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
               jac: np.ndarray, sqrt_w: np.ndarray, kind: FitKind, k_column: int, k_halfwidth: float,
               candidates_hz: np.ndarray, *, fitted: np.ndarray | None = None, use_phase: bool = False,
               systematic_cov: np.ndarray | None = None,
               blind: np.ndarray | None = None, chain_std: float = 0.0,
               bias_bound: np.ndarray | None = None,
               random_variance: np.ndarray | None = None) -> ThirdMode | None:
    """The candidate third mode with the largest t among those beyond noise that pull K beyond its interval (else the
    largest t of all).

    Parameters
    ----------
    f_hz : ndarray, shape (n,)
        The judged band's bins (the fit's band, or wider: :func:`analysis.fit.judged_fit`), Hz.
    misfit, replicate_misfits : ndarray of complex, shapes (n,) and (B, n)
        ln(H_model/H_meas) of the record and of each delete-one-block replicate (:func:`analysis.fit.model_misfits`,
        corrected by the estimator check): real part ln|H|, imaginary part the phase.
    log_ratios : callable
        ln(H_model/H_meas) at the bins for a load inertia factor (:func:`analysis.fit.model_log_ratios`).
    jac, sqrt_w : ndarray
        d ln(H_model/H_meas)/d(log parameters), complex (n, p), and the fit's bin weights' square roots
        (:func:`analysis.fit.log_ratio_jacobian`).
    kind : {"amplitude", "complex"}
        What the fit matched: the part of a third mass's trace it absorbs into K, J, C follows from it.
    k_column : int
        Jacobian column of ln K.
    k_halfwidth : float
        K's 95 % interval half-width, relative.
    candidates_hz : ndarray
        f_3 to look at (:func:`candidate_frequencies`), Hz.
    fitted : ndarray of bool, shape (n,), optional
        The bins the fit matched (default all): the fit absorbs a mode's trace there; beyond them (a band judged
        wider than the one fitted) the trace stays whole.
    use_phase : bool, optional
        Judge the phase too (only when the clocks were aligned, :func:`analysis.verdict_limits.phase_is_meaningful`): a
        delay common to all bins (what is left of the clock offset) is estimated beside each mode and taken out, and
        |H| alone must confirm the mode (:attr:`ThirdMode.t_confirm`).
    systematic_cov, blind, chain_std, bias_bound
        As :func:`analysis.adequacy.band_misfits` takes them (the quantisation's carried covariance of the residual,
        amplitude rows then, with ``use_phase``, phase rows: :func:`analysis.systematic_errors.quantisation_through_fit`;
        bins not to judge; the chain's window error; the loop's bias bound per bin). The phase is given the same
        chain error and bound as |H| (both bound ln H, a complex number).
    random_variance : ndarray, shape (n,), optional
        Variance per bin of ln|H| that the torque estimate's modelled noise gives (as
        :func:`analysis.adequacy.band_misfits` takes it; the phase's is the same, both being (1 − γ²)/(2γ²n_d) for
        H1): an estimate's noise is never taken below Σ v_i²·σ_i² of its weights v, the bins taken as independent (the
        smaller reading, as the window test takes it); a bin where it is infinite is not judged. None: the replicates'
        scatter alone.

    Returns
    -------
    ThirdMode or None
        None with fewer than two replicates, no candidate or no bin to judge.
    """
    reps = np.asarray(replicate_misfits, dtype=complex)
    b = reps.shape[0] if reps.ndim == 2 else 0
    n = f_hz.size
    judged = (np.isfinite(misfit) & (sqrt_w > 0) & np.all(np.isfinite(reps), axis=0)) if b else np.zeros(n, bool)
    if blind is not None:
        judged &= ~blind
    if random_variance is not None:
        judged &= np.isfinite(random_variance)  # no coherence the modelled noise would leave: nothing to judge there
    if b < 2 or candidates_hz.size == 0 or not np.any(judged):
        return None
    parts = 2 if use_phase else 1
    rows_judged = np.tile(judged, parts)

    def stacked(z: np.ndarray) -> np.ndarray:  # amplitude rows, then phase rows (last axis)
        return np.concatenate([z.real, z.imag], axis=-1) if use_phase else z.real

    m = np.where(rows_judged, stacked(np.where(judged, misfit, 0.0)), 0.0)
    r = np.where(rows_judged[None, :], stacked(np.where(judged[None, :], reps, 0.0)), 0.0)
    carried = (np.zeros((parts * n, parts * n)) if systematic_cov is None
               else np.where(np.outer(rows_judged, rows_judged), systematic_cov[:parts * n, :parts * n], 0.0))
    bound = np.zeros(n) if bias_bound is None else np.where(judged & np.isfinite(bias_bound), bias_bound, 0.0)
    bound = np.tile(bound, parts)
    random = np.zeros(parts * n) if random_variance is None else np.tile(np.where(judged, random_variance, 0.0), parts)
    window = np.tile(np.arange(n) // WINDOW_BINS, parts) + np.repeat(np.arange(parts), n) * n
    chain_cov = (window[:, None] == window[None, :]) * chain_std**2
    scatter = _along_frequency((b - 1) / b * np.sum((r - r.mean(axis=0)) ** 2, axis=0), rows_judged, n)
    variance = scatter + np.diag(carried) + chain_std**2 + bound**2
    variance = np.where(rows_judged & (variance > 0), variance, np.inf)
    delay = np.concatenate([np.zeros(n), np.where(judged, 2.0 * np.pi * f_hz, 0.0)]) if use_phase else None

    base = log_ratios(None)
    fit = np.ones(n, bool) if fitted is None else fitted
    pinv = np.linalg.pinv(weighted_jacobian(jac[fit], sqrt_w[fit], kind))
    amplitude_rows = np.arange(parts * n) < n

    def estimate(regressors: np.ndarray) -> tuple[float, float, float] | None:
        """â of the first regressor (weighted least squares with the others beside it), its t after the bound and its
        standard error."""
        normal = regressors.T @ (regressors / variance[:, None])
        if not (np.all(np.isfinite(normal)) and normal[0, 0] > 0 and abs(np.linalg.det(normal)) > 0):
            return None
        v = np.linalg.solve(normal, (regressors / variance[:, None]).T)[0]  # â = v·misfit
        a_reps = r @ v
        noise2 = max((b - 1) / b * float(np.sum((a_reps - a_reps.mean()) ** 2)), float(v**2 @ random))
        scale = float(np.sqrt(noise2 + v @ carried @ v + v @ chain_cov @ v))
        a = float(v @ m)
        return a, ((a - float(np.abs(v) @ bound)) / scale if scale > 0 else 0.0), scale

    rows = []
    for f3 in candidates_hz:
        s = (log_ratios(lambda f, f3=f3: third_mass_load_factor(f, SIGNATURE_STEP, f3, THIRD_MODE_DAMPING))
             - base) / SIGNATURE_STEP
        moved = pinv @ weighted_jacobian(s[fit, None], sqrt_w[fit], kind)[:, 0]  # log parameters' move per unit a
        left = np.where(rows_judged, stacked(s - jac @ moved), 0.0)  # what stays in the residual; misfit ≈ −a·left
        both = estimate(np.stack([-left] if delay is None else [-left, delay], axis=1))
        alone = both if delay is None else estimate(np.where(amplitude_rows, -left, 0.0)[:, None])
        if both is None or alone is None:
            continue
        weights = np.where(rows_judged, left / np.where(np.isfinite(variance), np.sqrt(variance), 1.0), 0.0)
        pull_se = both[2] * abs(float(moved[k_column]))  # the pull's standard error, relative
        t_pull = both[1] - k_halfwidth / pull_se if pull_se > 0 else -np.inf
        rows.append((float(f3), both[0], both[1], float(both[0] * moved[k_column]), alone[1], weights, float(t_pull)))
    if not rows:
        return None
    unit = np.array([row[5] / np.linalg.norm(row[5]) for row in rows])
    t_crit = float(stats.t.ppf(1.0 - MISFIT_LEVEL / effective_tests(unit @ unit.T), b - 1))
    t_confirm = float(stats.t.ppf(1.0 - MISFIT_LEVEL, b - 1))
    candidates = [ThirdMode(f3, a, t, t_crit, k_shift, k_halfwidth, t_amp, t_confirm, t_pull)
                  for f3, a, t, k_shift, t_amp, _, t_pull in rows]
    return max([c for c in candidates if c.found] or candidates, key=lambda c: c.t)


def _along_frequency(scatter: np.ndarray, judged: np.ndarray, n: int) -> np.ndarray:
    """The replicates' scatter per row averaged over :data:`WINDOW_BINS` neighbouring judged bins of its run (amplitude,
    phase), for the weights.

    One row's scatter has only B − 1 degrees of freedom: weighted by it alone, the estimate favours the rows whose
    scatter happens to be low, and the jackknife of the same rows then understates its spread (a misfit of pure noise,
    B = 10: 22 % of runs beyond the 5 % level, 7 % with the window's mean, 6 % with the true variances;
    tests/test_third_mode.py). The scatter varies slowly along frequency, so the window's mean is a fair weight.
    """
    def window_sum(x: np.ndarray) -> np.ndarray:  # centred as mode="same", also for runs shorter than a window
        return np.convolve(x, np.ones(WINDOW_BINS))[(WINDOW_BINS - 1) // 2:][:x.size]

    out = np.zeros_like(scatter)
    for start in range(0, scatter.size, n):
        run, ok = scatter[start:start + n], judged[start:start + n].astype(float)
        total, count = window_sum(np.where(ok > 0, run, 0.0)), window_sum(ok)
        out[start:start + n] = np.where(count > 0, total / np.maximum(count, 1.0), 0.0)
    return out

