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
        One-sided power spectral density of the torque, (N·m)²/Hz.
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
    segment_s: float
    n_segments: int
    period_s: float


def min_duration_s(segment_s: float, overlap: float = 0.5) -> float:
    """Shortest record, s, that holds two Welch segments of ``segment_s`` with ``overlap``."""
    return segment_s * (2.0 - overlap)


def window_kernel(frf: FrequencyResponse, half_width_bins: int = 4, per_bin: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """The Welch estimate's spectral window: what one FRF bin averages over.

    The expected H1 at a bin is, for a torque spectrum smooth over a few bins, the true H
    convolved with |W(ν)|², the squared magnitude of the Hann window's transform, normalised to
    unit sum. Sharp features (the resonance peak, the anti-resonance notch, a few hertz wide) are
    flattened by it at 0.5 s segments; the fit applies the same kernel to the model.

    Parameters
    ----------
    frf : FrequencyResponse
        The estimate (its segment length and period define the window).
    half_width_bins : int, optional
        Kernel support ± this many bins.
    per_bin : int, optional
        Kernel samples per bin.

    Returns
    -------
    offsets_hz : ndarray
        Frequency offsets ν, Hz, symmetric about 0.
    weights : ndarray
        |W(ν)|² normalised to sum 1.
    """
    nperseg = int(round(frf.segment_s / frf.period_s))
    spectrum = np.abs(np.fft.fft(signal.get_window("hann", nperseg), nperseg * per_bin)) ** 2
    k = np.arange(-half_width_bins * per_bin, half_width_bins * per_bin + 1)
    weights = spectrum[k % spectrum.size]
    return k / (per_bin * frf.segment_s), weights / weights.sum()


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
    fs = 1.0 / period_s
    nperseg = int(round(segment_s * fs))
    step = nperseg - int(round(overlap * nperseg))
    n_segments = 0 if x.size < nperseg else 1 + (x.size - nperseg) // step
    if n_segments < 2:
        raise RecordTooShortError(
            f"signals last {x.size * period_s:.3f} s; the FRF needs at least "
            f"{min_duration_s(segment_s, overlap):.3f} s (two {segment_s:g} s Welch segments)"
        )
    kw = dict(fs=fs, window="hann", nperseg=nperseg, noverlap=nperseg - step, detrend="linear")
    f, gxx = signal.welch(x, **kw)
    _, gyy = signal.welch(y, **kw)
    _, gxy = signal.csd(x, y, **kw)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = gxy / gxx / difference_response(f, period_s)
        coh = np.abs(gxy) ** 2 / (gxx * gyy)
    coh = np.clip(np.nan_to_num(coh, nan=0.0), 0.0, 1.0)
    return FrequencyResponse(
        f_hz=f,
        H=h,
        coherence=coh,
        torque_psd=gxx,
        segment_s=nperseg * period_s,
        n_segments=n_segments,
        period_s=period_s,
    )
