"""What an error on the torque estimate may hide at the resonance: the H2 estimate where H1 is biased by it.

An error n on the torque x = u + n that the speed does not follow (the one-phase estimate's error where the angle
leaves the phase little of the torque, a current sensor's noise, hum) is noise on the FRF's INPUT: H1 = G_xy/G_xx
reads H·(1 − G_nn/G_xx), low where the torque is weak. At the resonance the speed loop notches the torque, so there
the error is its largest share and the peak is flattened: C reads high, and neither the scatter between blocks (the
error is in every block) nor the misfit (a flatter peak is a higher C) shows it. The fit divides out the G_nn/G_xx
of the estimator's response to white current noise (:attr:`analysis.frf.FrequencyResponse.noise_ratio`), but an
estimate's error is more than that: on a one-phase robot window (tests/test_one_phase_doubt.py) the true share at
90–115 Hz was 0.28 against 0.013 modelled, |H1| 29 % low, C 0.171 against 0.1 (the true torque: 0.108).

Which noise lowered the coherence, the torque's or the speed's, no single record can tell: H1 is unbiased by noise
on the speed, H2 = G_yy/G_yx = H1/γ² by noise on the torque, and for noise uncorrelated with the motion the truth lies
between them. Across the fit band H2 is no answer (the encoder's quantisation is noise on the speed: H2 over the
whole band read K −4 % on that window). At the resonance it is: there the speed's response to the torque is at its
largest, so a noise on the speed is its smallest share, while the torque is at its weakest — the coherence lost
there is lost on the input (on that window |H1/H_true| followed γ² to a few % at every bin from 90 to 116 Hz, and
H2 in those bins gave C 0.108 — what the true torque gives — with K, J_m, J_l moved by 0.3 % at most). So :func:`h2_at_resonance` replaces H1 by H2 in the bins that read the resonance
peak — the fitted model's half-power band, widened by the Welch kernel's reach (those bins average the peak,
:func:`analysis.frf.window_kernel`) — and the fit (:func:`analysis.fit.fit_two_mass`) refits it: the shift of the
parameters is a bound of the bias the input noise may leave, carried in the intervals.

What the bound also holds (the second read, measured): the Welch window spreads a sharp peak over its neighbours, and
the coherence of a noise-free record falls there too — the fit models that spreading for H1 (its kernel), not for
H1/γ². So at 0.5 s segments the shift includes the estimator's own loss: on an exact plant with no noise at all, C's
shift is −9 % (paper plant; −2 % at 1 s segments, −0.5 % at 2 s) and −45 % on a soft plant (K/2, J×2). The interval
is then wider than the input noise alone needs — conservative, never narrower. Dividing γ² by the coherence the
window alone leaves on the fitted model would remove that part (noise-free shift +0.1 %), but then the mains-hum
runs of bench/accuracy.py read C +10…+13 % outside its interval: the H1/H2 bracket alone does not hold hum's bias
there, and a confident wrong C is worse than a wide one. Not taken until that is understood.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from analysis.systematic_errors import residual_of_errors
from analysis.fit_problem import FitResult
from analysis.frf import KERNEL_HALF_WIDTH_BINS, FrequencyResponse
from analysis.model import TwoMassParams, frequency_response


def resonance_bins(f_hz: np.ndarray, params: TwoMassParams, band: tuple[float, float]) -> np.ndarray:
    """The bins of ``f_hz`` (Hz) that read the resonance peak of ``params``: the contiguous half-power band
    (|H|² ≥ ½ of its peak) around the largest |H| in ``band`` (Hz) above the anti-resonance, widened by
    :data:`analysis.frf.KERNEL_HALF_WIDTH_BINS` bins either side; all False when no peak lies in the band. The
    largest |H| on the band's last bin is the peak when the model's resonance lies in the band (a band ending just
    above f_r: its peak falls on the last bin); on the first bin above the anti-resonance it is the rising flank."""
    out = np.zeros(f_hz.size, dtype=bool)
    inside = np.flatnonzero((f_hz >= band[0]) & (f_hz <= band[1]) & (f_hz > params.antiresonance_hz))
    if inside.size < 3:
        return out
    power = np.abs(frequency_response(params, f_hz[inside])) ** 2
    peak = int(np.argmax(power))
    if peak == 0 or (peak == inside.size - 1 and not params.resonance_hz <= band[1]):  # the band's edge, not a peak
        return out
    half = power >= 0.5 * power[peak]
    first, last = peak, peak
    while first > 0 and half[first - 1]:
        first -= 1
    while last < inside.size - 1 and half[last + 1]:
        last += 1
    out[max(inside[first] - KERNEL_HALF_WIDTH_BINS, 0):inside[last] + KERNEL_HALF_WIDTH_BINS + 1] = True
    return out


def h2_at_resonance(frf: FrequencyResponse, params: TwoMassParams,
                    band: tuple[float, float]) -> FrequencyResponse | None:
    """``frf`` with H2 = H1/γ² in the bins that read the resonance of ``params`` (:func:`resonance_bins`) and no
    modelled torque noise there (H2 is not biased by any), without replicates; None when the band holds no peak.

    Parameters
    ----------
    frf : FrequencyResponse
        The H1 estimate.
    params : TwoMassParams
        The model fitted to it (its resonance says which bins).
    band : tuple of float
        The fit band, Hz.
    """
    peak = resonance_bins(frf.f_hz, params, band) & (frf.coherence > 0.0)
    if not peak.any():
        return None
    h = frf.H.copy()
    h[peak] = frf.H[peak] / frf.coherence[peak]
    noise = None if frf.noise_ratio is None else np.where(peak, 0.0, frf.noise_ratio)
    return replace(frf, H=h, noise_ratio=noise, replicates=None)


@dataclass(frozen=True)
class EstimateError:
    """What the torque estimate's own error, read from the session's coherence at the resonance, leaves in the misfit
    of |H| (:func:`estimate_error_misfit`).

    Attributes
    ----------
    scale : float
        How many times the share of the torque's power the white-current-noise model gives
        (:attr:`analysis.frf.FrequencyResponse.noise_ratio`) the coherence lost at the resonance is.
    resonance_share : float
        The share G_nn/G_xx of the torque's power that is the estimate's error at the resonance (the coherence lost
        there, averaged over :func:`resonance_bins`).
    misfit : ndarray, shape (n,)
        ln|H_model| − ln|H_measured| that error leaves at the judged bins once the fit has bent to it.
    """

    scale: float
    resonance_share: float
    misfit: np.ndarray


def estimate_error_misfit(frf: FrequencyResponse, params: TwoMassParams, band: tuple[float, float],
                          bins: np.ndarray, jac: np.ndarray, sqrt_w: np.ndarray, kind: str,
                          fitted: np.ndarray) -> EstimateError | None:
    """The misfit of |H| an error on the torque estimate larger than its white-noise model leaves, from the session.

    An error n on the torque that the speed does not follow lowers H1 by 1 − G_nn/G_xx; the fit divides out the share
    its white-current-noise model gives, ν (:attr:`analysis.frf.FrequencyResponse.noise_ratio`), but the one-phase
    estimate's error is more than that where the motor holds or steps torque at an angle at which the phase shows
    little of it (on the robot windows of tests/test_one_phase_doubt.py 10–20× ν at 20–130 Hz against the true
    torque). How much more the session says where the coherence lost is the input's (the module docstring): at the
    resonance, scale s = Σ(1 − γ²)/Σν over :func:`resonance_bins`. Elsewhere the error's share is taken as s·ν (the
    estimator's response has ν's shape: on the window of seed 2 at 420 s the true share over s·ν was 0.6–2.0 from 20 to 130 Hz, s = 12.9), never
    above 1 − γ², the most an input noise can take of a bin's coherence. Its bias ln(1 − s·ν) − ln(1 − ν) of ln|H| is
    carried through the fit (:func:`analysis.systematic_errors.residual_of_errors`): the fit bends to the flattened peak (C up)
    and misses by it elsewhere — at the anti-resonance, where friction's misfit has the other sign.

    Parameters
    ----------
    frf : FrequencyResponse
        The H1 estimate the fit was made to.
    params : TwoMassParams
        The fitted model (its resonance says which bins read the peak).
    band : tuple of float
        The fit band, Hz.
    bins : ndarray of bool, shape like ``frf.f_hz``
        The judged bins (:func:`analysis.fit_problem.fitted_bins` of the judged band), n of them.
    jac, sqrt_w, kind, fitted
        The fit's log-ratio Jacobian and weights' square roots at those bins, what it matched and which of them
        (:func:`analysis.systematic_errors.residual_of_errors`).

    Returns
    -------
    EstimateError or None
        None without a noise model or a resonance peak in the band, or when the model gives no noise there.
    """
    if frf.noise_ratio is None:
        return None
    f, g2, nu = frf.f_hz[bins], frf.coherence[bins], frf.noise_ratio[bins]
    peak = resonance_bins(f, params, band)
    modelled = float(np.sum(nu[peak]))
    if not peak.any() or not modelled > 0.0:
        return None
    lost = 1.0 - g2
    scale = max(float(np.sum(lost[peak])) / modelled, 1.0)
    share = np.clip(np.minimum(scale * nu, lost), nu, 1.0 - 1e-6)  # never below the model, never all of the torque
    deficit = np.log1p(-share) - np.log1p(-nu)  # ln|H1| lower than the fit's noise model makes it (≤ 0)
    rest = residual_of_errors(jac, sqrt_w, kind, fitted)
    return EstimateError(scale, float(np.mean(share[peak])), rest[:, :f.size] @ -deficit)


def widened_c_note(fit: FitResult, frf: FrequencyResponse, model_frf: FrequencyResponse | None) -> str | None:
    """Why C's interval is wide, when the allowance for an error on the torque estimate (the H1/H2 bracket at the
    resonance, :func:`h2_at_resonance`, carried in the fit's intervals) widens it materially and for that reason.

    Materially: the H2 reading of C lies outside the interval the other terms give (without the allowance the
    interval would not hold it). For that reason: of the coherence lost at the resonance (:func:`resonance_bins`),
    more is the input's, 1 − γ²/γ²_w, than the Welch window's own, 1 − γ²_w (γ²_w the coherence of the estimator run
    on the fitted model for the recorded torque, ``model_frf``, :func:`analysis.estimator_check.model_estimate`): the
    bracket also holds the window's spreading of a sharp peak (the module docstring), which on a healthy 10 s run of
    the paper's plant is most of it (lost 5.8 %, the window's own 3.8 %: H2 reads C −7.5 %) and is no error on the
    torque; with 20 mA of mains hum the input's share was larger (lost 9.2 %, the window's 3.4 %: H1 reads C +10 %,
    H2 −15 %). None when either does not hold, or without the estimator's run.
    """
    name = "C_Nms_per_rad"
    shift, without, now = (fit.input_noise_shift.get(name), fit.ci95_without_input_noise.get(name),
                           fit.ci95.get(name))
    if model_frf is None or shift is None or without is None or now is None or not np.isfinite(shift):
        return None
    c = fit.values.C_Nms_per_rad
    h2 = c * float(np.exp(shift))
    peak = resonance_bins(frf.f_hz, fit.values, fit.band) & (model_frf.coherence > 0.0)
    if without[0] <= h2 <= without[1] or not peak.any():
        return None
    lost = float(np.mean(1.0 - frf.coherence[peak]))
    own = float(np.mean(1.0 - model_frf.coherence[peak]))
    if not float(np.mean(1.0 - frf.coherence[peak] / model_frf.coherence[peak])) > own:
        return None
    return (f"C's interval [{now[0]:.3g}, {now[1]:.3g}] N·m·s/rad allows for an error on the torque estimate (noise, "
            f"hum, the one-phase estimate's own error): at the resonance ({fit.f_r:.0f} Hz) the coherence lost is "
            f"{100 * lost:.1f} %, of which the Welch window's own spreading of the peak takes {100 * own:.1f} %; the rest "
            f"is noise on the torque, which flattens H1's peak and reads C high — from H2 = H1/γ² there C is {h2:.3g} "
            f"({100 * (h2 / c - 1):+.0f} %), and the truth lies between the two readings; without that allowance the "
            f"interval would be [{without[0]:.3g}, {without[1]:.3g}], "
            f"{np.log(now[1] / now[0]) / np.log(without[1] / without[0]):.1f}× narrower on a log scale")
