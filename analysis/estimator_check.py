"""What the Welch estimator makes of the fitted model, from the session's own torque: the fit's model of the
estimator checked against the estimator itself.

The fit compares |H| with the model as Welch's estimator sees it, modelled as the plant's H averaged over the Hann
window's kernel with the finely resolved torque spectrum as weights (:class:`analysis.fit._Problem`). That is exact
for a stationary torque; a periodic motion puts its torque on a few strong lines whose cross terms within a segment
and leakage the average does not hold. Where |H| is small — at the anti-resonance — the rest of the band's leakage is
large beside it: on a plant with the anti-resonance at 30–40 Hz (J_m ×0.5, J_l ×2) the model of the estimator is
+4.5…+6 % off there (the misfit test read a healthy joint as a missing mode), at 10–40 Hz ±0.1…0.2 % (60 s records).

Here the estimator is run on the model itself: the model's speed for the recorded torque — the torque's spectrum
times H·D (D the backward difference the speed was taken with; the record taken as one period of a periodic signal,
whose wrap-around the segments' linear detrend removes from all but the segments at the ends) — through the same
segments, window, detrend and selection as the measurement, and compared with the fit's kernel model of that same
estimate. Their ratio is the kernel model's error at each bin, for this session's torque; the misfit test compares
the measurement with the model corrected by it (:func:`analysis.quality`). Nothing in it is tuned: the same FFTs as
the measured FRF, once.
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from analysis.encoder import difference_response
from analysis.fit import FitResult, fitted_bins, kernel_model_log_ratio, wrapped
from analysis.frf import FrequencyResponse, estimate_frf
from analysis.model import frequency_response


def model_estimate(frf: FrequencyResponse, fit: FitResult, torque_Nm: np.ndarray,
                   jackknife_blocks: int = 0) -> FrequencyResponse:
    """What the Welch estimator makes of the fitted model: H1 and coherence of the model's own speed for the recorded
    torque, through the same segments, window, detrend and selection as the measurement (noise-free: its coherence is
    what the window alone leaves, lowest at a sharp resonance peak).

    Parameters
    ----------
    frf : FrequencyResponse
        The measured response the fit was made to (its segment length, period and selection are reused).
    fit : FitResult
        A fit of ``frf`` that did not fail.
    torque_Nm : ndarray
        The torque the FRF was estimated from, N·m, on the encoder's grid (``frf.period_s``).
    jackknife_blocks : int, optional
        The delete-one-block replicates, as :func:`analysis.frf.estimate_frf` forms ``frf``'s (the same segments, so
        the same blocks when given the same count); 0: none.
    """
    x = np.asarray(torque_Nm, dtype=float)
    x = x - x.mean()
    f = np.fft.rfftfreq(x.size, frf.period_s)
    h = np.zeros(f.size, dtype=complex)
    h[1:] = frequency_response(fit.values, f[1:]) * difference_response(f[1:], frf.period_s)  # no mean speed
    # scipy.fft, not NumPy's: the same results to the bit, but the forward transform's plan kept for the inverse of the
    # same length, which NumPy plans again — the record's length is whatever it is (59 909 = 139·431 samples for a 60 s
    # session): 12–14 ms against NumPy's 18–33 ms, one BLAS thread, load ≈ 7
    speed = scipy.fft.irfft(scipy.fft.rfft(x) * h, x.size)
    return estimate_frf(x, speed, frf.period_s, segment_s=frf.segment_s, reuse_selection=frf.selection,
                        leave_out=frf.unknown_torque, jackknife_blocks=jackknife_blocks)


def kernel_model_error(frf: FrequencyResponse, fit: FitResult, model_frf: FrequencyResponse) -> np.ndarray:
    """ln(H1 of the model's own speed) − ln(the fit's kernel model of it) at the fit's bins (complex).

    Parameters
    ----------
    frf : FrequencyResponse
        The measured response the fit was made to.
    fit : FitResult
        A fit of ``frf`` that did not fail.
    model_frf : FrequencyResponse
        What the estimator makes of ``fit``'s model for the recorded torque (:func:`model_estimate`).

    Returns
    -------
    ndarray of complex, shape (n,)
        At ``frf.f_hz[fitted_bins(frf, fit.band)]``; add its real part to the kernel model's ln|H| and its imaginary
        part to its phase to get what the estimator makes of the model.
    """
    sel = fitted_bins(frf, fit.band)
    if not np.array_equal(fitted_bins(model_frf, fit.band), sel):
        return np.zeros(int(np.count_nonzero(sel)), dtype=complex)  # a bin empty in one estimate: no correction
    return wrapped(-kernel_model_log_ratio(model_frf, fit))  # the phase wrapped to ±π as the misfits are
