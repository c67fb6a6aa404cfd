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

from dataclasses import replace

import numpy as np

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
