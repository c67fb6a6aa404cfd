"""The errors of a session's ln H that no scatter between its blocks shows, and how they carry through the fit.

The jackknife over blocks of Welch segments sees everything that varies along the record, but not an error that
repeats with every motion period or varies smoothly along frequency. This module sizes those errors from the
session's own spectra and the encoder's resolution, and carries them through the fit — to the fitted log parameters
(:func:`quantisation_pull`, :func:`chain_pull`: the intervals' floor in :mod:`analysis.fit`) and to the fit's
residual (:func:`quantisation_through_fit`, :func:`spread_beyond_fit`: the allowance of the misfit test of
:mod:`analysis.adequacy`):

* the encoder's quantisation that repeats with the motion: modelled as a fixed error of random phase at each line of
  the motion, of the size of the white-quantisation bound √(N_q/G_yy), and carried through the fit (the fit absorbs
  part of it into K, J, C and moves the rest to other bins). On 2^17 counts/rev simulated sessions, |H| against the
  same run at 2^20 counts/rev stays within that bound per bin (≤ 1×, RMS 0.4× at 200–400 Hz);
* the speed loop's feedback of the rest of the quantisation (:func:`loop_feedback_bound`) and the chain's own
  approximations (:data:`CHAIN_WINDOW_STD`);
* beyond the fitted band, the model's own spread from its parameters' covariance (:func:`spread_beyond_fit`).
"""

from __future__ import annotations

import numpy as np

from analysis.adequacy import WINDOW_BINS

# What the chain's own approximations may leave in a window's mean misfit of ln|H| (1σ). Measured stage by stage
# against the simulator's truth (bench/chain_bias.py, paper plant, seeds 0–2, 10 s and 60 s): the Welch estimator's
# model (window kernel over the fine torque spectrum; it is exact for a stationary spectrum, not for the few strong
# lines of a periodic motion whose cross terms and per-segment detrend leak into the lowest bins) 0.07–0.30 % RMS of
# the window means, largest at 10–100 Hz; the one-phase torque estimate ≤ 0.25 % per band; the viscous frictions the
# fit fixes at 0 −0.16 % at 100–160 Hz. It matters only where nothing else is allowed: on long records, and where the
# quantisation error does not repeat with the motion (a dithered profile, a real loop's disturbances), so that the
# jackknife's scatter is the only other allowance (60 s, 2^17 counts/rev, dithered: misfits of ±0.1…0.2 % at
# 10–40 Hz against a scatter of 0.02 %). It is 1/20 of the smallest misfit the test must see (a third mode's
# ±6 % dipole). A bench whose chain is less exact (another estimator, a coarser torque model) needs it re-measured.
CHAIN_WINDOW_STD = 0.003


def motion_lines(torque_psd_fine: np.ndarray, fine_step_hz: float, low_hz: float, high_hz: float) -> float:
    """How many lines of the motion's spectrum lie in low…high Hz: the participation ratio (Σp)²/Σp² of the finely
    resolved torque PSD there, halved (a line fills about two fine bins of the Hann kernel); at least 1.

    A periodic motion puts its torque on a few harmonics, a varied one spreads it over many fine bins.
    """
    f = np.arange(torque_psd_fine.size) * fine_step_hz
    p = torque_psd_fine[(f >= low_hz) & (f <= high_hz)]
    total = float(np.sum(p ** 2))
    if not (np.isfinite(total) and total > 0):
        return 1.0  # no torque there, or a non-finite PSD: one line (the most a quantisation error can be)
    return max(float(np.sum(p)) ** 2 / total / 2.0, 1.0)


def lines_per_bin(torque_psd_fine: np.ndarray, fine_step_hz: float, f_hz: np.ndarray, bin_hz: float) -> np.ndarray:
    """The motion's lines (:func:`motion_lines`) per bin of ``f_hz`` (a fit's bins, Hz, ``bin_hz`` apart), counted
    per window of :data:`analysis.adequacy.WINDOW_BINS` bins and shared among its bins."""
    lines = np.ones_like(f_hz)
    for i in range(0, f_hz.size, WINDOW_BINS):
        w = slice(i, i + WINDOW_BINS)
        n = motion_lines(torque_psd_fine, fine_step_hz, f_hz[w][0] - bin_hz / 2, f_hz[w][-1] + bin_hz / 2)
        lines[w] = n / f_hz[w].size
    return lines


def line_variance(quant_rel: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """Variance per bin of ln H (in amplitude and alike in phase) that a quantisation error repeating with the motion
    leaves: q²/(2n) for a bin holding a share n of the motion's lines (``lines``, :func:`lines_per_bin`) with the
    white-quantisation bound q (``quant_rel``) — a random-phase error of q per line, averaged over the bin's lines;
    0 where either is not finite or positive (such bins are not judged)."""
    judged = np.isfinite(quant_rel) & np.isfinite(lines) & (lines > 0)
    return np.where(judged, quant_rel, 0.0) ** 2 / (2.0 * np.where(judged, lines, 1.0))


def quantisation_pull(quant_rel: np.ndarray, lines: np.ndarray, jac: np.ndarray, sqrt_w: np.ndarray) -> np.ndarray:
    """Covariance of the fitted log parameters that the encoder's quantisation causes: the same random-phase error
    per line as :func:`quantisation_through_fit`, the part the fit absorbs, (JᵀJ)⁻¹Jᵀ·W·S·J(JᵀJ)⁻¹ (J the Jacobian of
    the weighted residuals, W the weights). The jackknife cannot see it (it repeats with every motion period) and the
    residual does not show it (the fit took it); bins without a finite bound add nothing.

    Returns
    -------
    ndarray, shape (p, p)
    """
    parts = jac.shape[0] // quant_rel.size
    weighted = np.tile(line_variance(quant_rel, lines) * sqrt_w**2, parts)
    a = np.linalg.pinv(jac.T @ jac) @ jac.T
    return (a * weighted[None, :]) @ a.T


def loop_feedback_bound(quant_rel: np.ndarray, repeating_share: float) -> np.ndarray:
    """The most the speed loop's feedback of the quantisation noise that does not repeat with the motion can bias
    ln|H| per bin: (1 − share)·q².

    The drive closes its speed loop on the quantised angle, so its torque carries −C·n/(1 + C·H) of the speed noise
    n it measures, and that torque is correlated with the n in the recorded speed: H1 = G_xy/G_xx is biased by
    −T·G_nn/(H·G_xx) relative to H, T = C·H/(1 + C·H) the loop's complementary sensitivity. |T| ≤ 1 outside the
    loop's resonance and G_nn/(|H|²G_xx) is the square of the white-quantisation bound q per bin, so the bias is at
    most q² — of either sign, depending on T's phase. It matters only where q is large, near the band's top: with a
    4 kHz encoder at 2^17 counts/rev the speed's q² reaches ~9 % at 410–480 Hz, where the recorded |H| reads 6–11 %
    high and J_m 0.4 % low; at 2^20 counts/rev neither. The share that repeats with the motion is carried separately
    (:func:`quantisation_through_fit`), so only the rest counts here. The misfit test takes it off a window's misfit
    as the bound it is (allowing it as a standard deviation would let a third mode's +7 % dipole through at a 500 Hz
    encoder, where q² is 1–3 % at 170–184 Hz); the intervals carry it as a standard deviation
    (:func:`systematic_std`), which is wider.

    Parameters
    ----------
    quant_rel : ndarray, shape (n,)
        White-quantisation bound of |H| per bin (relative); a non-finite bound counts as none (such bins are not
        judged).
    repeating_share : float
        Share of the quantisation error that repeats with the motion (0…1).
    """
    q = np.where(np.isfinite(quant_rel), quant_rel, 0.0)
    return (1.0 - repeating_share) * q**2


def systematic_std(quant_rel: np.ndarray, repeating_share: float) -> np.ndarray:
    """Standard deviation per bin of the errors of ln|H| that vary smoothly along frequency and that no scatter
    between blocks shows, as the intervals carry them (:func:`chain_pull`): the chain's own
    (:data:`CHAIN_WINDOW_STD`) and the loop's feedback of the quantisation noise that does not repeat
    (:func:`loop_feedback_bound`, its bound taken as a standard deviation).
    """
    return np.hypot(CHAIN_WINDOW_STD, loop_feedback_bound(quant_rel, repeating_share))


def chain_pull(jac: np.ndarray, sqrt_w: np.ndarray, std: np.ndarray) -> np.ndarray:
    """Covariance of the fitted log parameters that the smooth systematic errors of :func:`systematic_std` may
    cause: an error of ``std`` in ln H shared by the bins of each window of :data:`analysis.adequacy.WINDOW_BINS` (it
    varies smoothly along frequency) and independent between windows, in amplitude and (for a complex fit) in phase,
    carried to the parameters as :func:`quantisation_pull` carries the quantisation's.

    Returns
    -------
    ndarray, shape (p, p)
    """
    n = sqrt_w.size
    parts = jac.shape[0] // n
    window = np.arange(n) // WINDOW_BINS
    shared = (window[:, None] == window[None, :]) * np.outer(std, std)
    weighted = np.kron(np.eye(parts), sqrt_w[:, None] * shared * sqrt_w[None, :])
    a = np.linalg.pinv(jac.T @ jac) @ jac.T
    return a @ weighted @ a.T


def quantisation_through_fit(quant_rel: np.ndarray, lines: np.ndarray, jac: np.ndarray, sqrt_w: np.ndarray,
                             kind: str = "amplitude", fitted: np.ndarray | None = None,
                             phase: bool = False) -> np.ndarray:
    """Covariance of the fit's log-amplitude residual (and with ``phase`` of its phase residual) that the encoder's
    quantisation leaves, bins × bins.

    The quantisation error repeats with a periodic motion, so at each of its lines it adds a fixed error whose phase
    has nothing to do with the speed's: ln H moves by E_k/Y_k, of variance q² per line in amplitude and in phase,
    q the white-quantisation bound √(N_q/G_yy) of the bin (``quant_rel``). A bin holding a share of n lines
    (``lines``: the lines of its window over the window's bins) has the variance q²/(2n) of its own line mean
    spread over those bins. The fit then absorbs part of it into K, J, C — and moves the residual elsewhere: the
    log parameters move by G·e (G = (JᵀJ)⁻¹Jᵀ·D, J the weighted Jacobian of the rows the fit matches, D their
    weights' square roots, e their errors), so a residual row with the model's derivative j is e_row − j·G·e, and
    its covariance is A·S·Aᵀ with A = P − J_rows·G — also at bins the fit did not match (a band judged beyond the
    fitted one) and in the phase, which an amplitude fit leaves whole and moves by its pull on K, J, C (near the
    resonance, where |H| is steep in them, that pull is most of it). Nothing here is measured on a simulator: the
    encoder's resolution, the session's spectra and the fit's own Jacobian.

    Parameters
    ----------
    quant_rel : ndarray, shape (n,)
        White-quantisation bound of |H| per bin (relative, 0.05 = 5 %).
    lines : ndarray, shape (n,)
        Lines of the motion per bin (a window's lines over its bins), ≥ 1/bins.
    jac : ndarray of complex, shape (n, p)
        d ln(H_model/H_meas)/d(log parameters) at the bins (:func:`analysis.fit.log_ratio_jacobian`).
    sqrt_w : ndarray, shape (n,)
        The fit's bin weights' square roots.
    kind : {"amplitude", "complex"}
        What the fit matched: |H|, or |H| and the phase.
    fitted : ndarray of bool, shape (n,), optional
        The bins the fit matched (default all).
    phase : bool, optional
        Also the phase residual's rows.

    Returns
    -------
    ndarray, shape (n, n) or (2n, 2n)
        Covariance of the amplitude residual ln|H_model| − ln|H_measured| (then of the phase residual). A bin without
        weight or a finite bound adds no error and is given none: the caller must not judge it.
    """
    judged = np.isfinite(quant_rel) & np.isfinite(lines) & (lines > 0) & (sqrt_w > 0)
    rest = residual_of_errors(jac, sqrt_w, kind, fitted, phase, judged)
    s2 = np.tile(np.where(judged, line_variance(quant_rel, lines), 0.0), 2)  # amplitude, then phase errors
    return (rest * s2[None, :]) @ rest.T


def residual_of_errors(jac: np.ndarray, sqrt_w: np.ndarray, kind: str = "amplitude", fitted: np.ndarray | None = None,
                       phase: bool = False, judged: np.ndarray | None = None) -> np.ndarray:
    """How errors of the measured ln H show in a fit's residual ln(H_model/H_meas) once the fit has absorbed what it
    could of them into its parameters: the matrix A = P − J_rows·G of :func:`quantisation_through_fit` (G: the log
    parameters' move per error of each row the fit matched, J the fit's weighted Jacobian), columns the errors of
    ln|H| at the n bins then of the phase, rows the amplitude residual then (with ``phase``) the phase residual.

    Parameters
    ----------
    jac : ndarray of complex, shape (n, p)
        d ln(H_model/H_meas)/d(log parameters) at the bins (:func:`analysis.fit.log_ratio_jacobian`).
    sqrt_w : ndarray, shape (n,)
        The fit's bin weights' square roots.
    kind : {"amplitude", "complex"}
        What the fit matched.
    fitted : ndarray of bool, shape (n,), optional
        The bins the fit matched (default all).
    phase : bool, optional
        Also the phase residual's rows.
    judged : ndarray of bool, shape (n,), optional
        The bins whose residual rows carry the parameters' move (default all): elsewhere the row is the error alone.

    Returns
    -------
    ndarray, shape (n, 2n) or (2n, 2n)
    """
    n = sqrt_w.size
    fit = np.flatnonzero(np.ones(n, bool) if fitted is None else fitted)
    matched = [fit, n + fit] if kind == "complex" else [fit]
    fit_jac = np.concatenate([sqrt_w[fit, None] * part for part in (jac[fit].real, jac[fit].imag)[:len(matched)]])
    moves = np.zeros((jac.shape[1], 2 * n))  # G: the log parameters' move per error of each row (amplitude, phase)
    moves[:, np.concatenate(matched)] = (np.linalg.pinv(fit_jac.T @ fit_jac) @ fit_jac.T
                                         * np.tile(sqrt_w[fit], len(matched))[None, :])
    observed = [jac.real, jac.imag] if phase else [jac.real]
    rows = np.ones(n, bool) if judged is None else judged
    derivative = np.concatenate([np.where(rows[:, None], part, 0.0) for part in observed])
    return np.eye(derivative.shape[0], 2 * n) - derivative @ moves


def spread_beyond_fit(jac: np.ndarray, covariance: np.ndarray, fitted: np.ndarray, phase: bool = False) -> np.ndarray:
    """Covariance of the model's ln H at bins the fit did not match (a band judged beyond the fitted one), from the
    fitted parameters' own uncertainty: J·Σ·Jᵀ on those rows, 0 elsewhere.

    The replicates' misfits hold the model at the full record's fit, so their scatter shows the measurement's noise
    but not the model's: inside the fitted band the residual is smaller than that noise, beyond it the model is
    extrapolated and carries its parameters' error whole (a healthy joint fitted to 100 Hz, f_r = 102 Hz: the model
    misses by 4–10 % at 102–120 Hz where the replicates scatter by 0.4–3.5 % and J·Σ·Jᵀ allows 2–5 %).

    Parameters
    ----------
    jac : ndarray of complex, shape (n, p)
        d ln(H_model/H_meas)/d(log parameters) (:func:`analysis.fit.log_ratio_jacobian`).
    covariance : ndarray, shape (p, p)
        The log parameters' covariance (:attr:`analysis.fit.FitResult.covariance`).
    fitted : ndarray of bool, shape (n,)
        The bins the fit matched.
    phase : bool, optional
        Also the phase rows (amplitude rows first).

    Returns
    -------
    ndarray, shape (n, n) or (2n, 2n)
        NaN between the bins beyond the fit when the covariance is not finite (a refit diverged, the intervals are
        undetermined: those bins cannot be judged), 0 in every row and column of a fitted bin.
    """
    beyond = np.tile(~np.asarray(fitted, dtype=bool), 2 if phase else 1)
    rows = np.concatenate([jac.real, jac.imag] if phase else [jac.real])[beyond]
    spread = np.zeros((beyond.size, beyond.size))
    # not rows·Σ·rowsᵀ with an infinite Σ: its 0·∞ would spread NaN over the fitted bins too, and warn
    spread[np.ix_(beyond, beyond)] = rows @ covariance @ rows.T if np.all(np.isfinite(covariance)) else np.nan
    return spread
