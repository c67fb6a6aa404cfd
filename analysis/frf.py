"""Frequency response torque → motor speed by Welch's method (design §5 step 4).

H1 = G_xy / G_xx with Hann windows, 0.5 s segments, 50 % overlap and a linear detrend per
segment, and the coherence γ² = |G_xy|² / (G_xx G_yy). The speed is a backward difference of the
encoder angle, whose response relative to the true speed is D(f) = (1 − e^{−j2πfT})/(j2πfT); it is
divided out of H so that H is the plant's own response.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from analysis.encoder import difference_response


KERNEL_PER_BIN = 8
KERNEL_HALF_WIDTH_BINS = 4


class RecordTooShortError(ValueError):
    """The signals are too short for two Welch segments; the message names the duration needed."""


@dataclass(frozen=True)
class FrequencyResponse:
    """An estimated frequency response torque → motor speed.

    Attributes
    ----------
    f_hz : ndarray
        Frequencies, Hz, from 0 to the Nyquist frequency of the encoder grid.
    H : ndarray of complex
        H1 estimate, (rad/s)/(N·m), with the difference operator divided out.
    coherence : ndarray
        Magnitude-squared coherence γ² between torque and speed, 0…1.
    torque_psd : ndarray
        One-sided power spectral density of the torque, (N·m)²/Hz, at ``f_hz``.
    torque_psd_fine : ndarray
        The same at ``KERNEL_PER_BIN`` times finer spacing (segments that much longer, or the
        whole record zero-padded), for the spectral window of :func:`window_kernel`.
    segment_s : float
        Welch segment length, s.
    n_segments : int
        Number of (overlapping) segments averaged.
    period_s : float
        Sample period of the signals, s (the encoder period).
    """

    f_hz: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    torque_psd: np.ndarray
    torque_psd_fine: np.ndarray
    segment_s: float
    n_segments: int
    period_s: float


def min_duration_s(segment_s: float, overlap: float = 0.5) -> float:
    """Shortest record, s, that holds two Welch segments of ``segment_s`` with ``overlap``."""
    return segment_s * (2.0 - overlap)


def require_two_segments(n_samples: int, period_s: float, segment_s: float, overlap: float = 0.5) -> None:
    """Raise :class:`RecordTooShortError` unless ``n_samples`` at ``period_s`` hold two Welch segments."""
    nperseg = int(round(segment_s / period_s))
    step = nperseg - int(round(overlap * nperseg))
    if n_samples < nperseg + step:
        raise RecordTooShortError(
            f"signals last {n_samples * period_s:.3f} s; the FRF needs at least "
            f"{min_duration_s(segment_s, overlap):.3f} s (two {segment_s:g} s Welch segments)"
        )


def window_kernel(frf: FrequencyResponse) -> tuple[np.ndarray, np.ndarray]:
    """The Welch estimate's spectral window: what each FRF bin averages over.

    The expected H1 at bin f is Σ_ν H(f+ν)·S(f+ν)·|W(ν)|² / Σ_ν S(f+ν)·|W(ν)|², with |W|² the
    squared magnitude of the Hann window's transform and S the torque spectrum at a resolution
    finer than the bins (:attr:`FrequencyResponse.torque_psd_fine`; it resolves the harmonics of
    the rectangular torque). Sharp features — the resonance peak and the anti-resonance notch,
    a few hertz wide — are flattened by it at 0.5 s segments; the fit applies the same kernel to
    the model.

    Parameters
    ----------
    frf : FrequencyResponse
        The estimate (segment length, period and fine torque spectrum define the kernel).

    Returns
    -------
    offsets_hz : ndarray, shape (m,)
        Frequency offsets ν, Hz, ± ``KERNEL_HALF_WIDTH_BINS`` bins around each bin.
    weights : ndarray, shape (n_bins, m)
        Kernel of each bin of ``frf.f_hz``, rows summing to 1.
    """
    nperseg = int(round(frf.segment_s / frf.period_s))
    spectrum = np.abs(np.fft.fft(signal.get_window("hann", nperseg), nperseg * KERNEL_PER_BIN)) ** 2
    k = np.arange(-KERNEL_HALF_WIDTH_BINS * KERNEL_PER_BIN, KERNEL_HALF_WIDTH_BINS * KERNEL_PER_BIN + 1)
    fine = np.abs(np.arange(frf.f_hz.size)[:, None] * KERNEL_PER_BIN + k[None, :])
    fine = np.minimum(fine, 2 * (frf.torque_psd_fine.size - 1) - fine)  # mirror at Nyquist
    weights = frf.torque_psd_fine[fine] * spectrum[k % spectrum.size][None, :]
    weights /= np.maximum(weights.sum(axis=1, keepdims=True), np.finfo(float).tiny)
    return k / (KERNEL_PER_BIN * frf.segment_s), weights


def estimate_frf(
    torque_Nm: np.ndarray,
    speed_rad_s: np.ndarray,
    period_s: float,
    *,
    segment_s: float = 0.5,
    overlap: float = 0.5,
) -> FrequencyResponse:
    """Estimate H1 = G_xy/G_xx and the coherence from torque and backward-difference speed.

    Parameters
    ----------
    torque_Nm : ndarray
        Electromagnetic torque, N·m, on the encoder's regular grid.
    speed_rad_s : ndarray
        Motor speed, rad/s, the backward difference of the encoder angle on the same grid.
    period_s : float
        Grid period T, s.
    segment_s : float, optional
        Welch segment length, s (0.5 s by default: 2 Hz resolution).
    overlap : float, optional
        Fraction of a segment shared with the next one, 0 ≤ overlap < 1.

    Returns
    -------
    FrequencyResponse

    Raises
    ------
    RecordTooShortError
        If the signals do not hold two segments.
    ValueError
        If the two signals differ in length.
    """
    x = np.asarray(torque_Nm, dtype=float)
    y = np.asarray(speed_rad_s, dtype=float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"torque and speed must be 1-D arrays of one length, got {x.shape} and {y.shape}")
    require_two_segments(x.size, period_s, segment_s, overlap)
    fs = 1.0 / period_s
    nperseg = int(round(segment_s * fs))
    step = nperseg - int(round(overlap * nperseg))
    n_segments = 1 + (x.size - nperseg) // step
    kw = dict(fs=fs, window="hann", nperseg=nperseg, noverlap=nperseg - step, detrend="linear")
    f, gxx = signal.welch(x, **kw)
    _, gyy = signal.welch(y, **kw)
    _, gxy = signal.csd(x, y, **kw)
    n_fine = KERNEL_PER_BIN * nperseg
    _, gxx_fine = signal.welch(x, fs=fs, window="hann", nperseg=min(n_fine, x.size), nfft=n_fine,
                               detrend="linear")
    with np.errstate(divide="ignore", invalid="ignore"):
        h = gxy / gxx / difference_response(f, period_s)
        coh = np.abs(gxy) ** 2 / (gxx * gyy)
    coh = np.clip(np.nan_to_num(coh, nan=0.0), 0.0, 1.0)
    return FrequencyResponse(
        f_hz=f,
        H=h,
        coherence=coh,
        torque_psd=gxx,
        torque_psd_fine=gxx_fine,
        segment_s=nperseg * period_s,
        n_segments=n_segments,
        period_s=period_s,
    )
