"""Welch's power spectral density with all segments transformed at once.

:func:`scipy.signal.welch` (scipy 1.17, through ``ShortTimeFFT.stft_detrend``) detrends and transforms the
segments one by one in a Python loop — a least-squares fit per segment for a linear detrend, and 250 FFT calls
for a 4096-sample PSD of a 20 s chunk of the 25.6 kS/s current. Here the segments are one strided view, the
trends are removed from all of them at once and one batched FFT transforms them: the same estimate (Hann
window, 50 % overlap, the trailing partial segment dropped, one-sided density scaling) to rounding.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy import signal

Detrend = Literal["constant", "linear"] | None


def psd(x: np.ndarray, fs_hz: float, nperseg: int, detrend: Detrend = "constant",
        nfft: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies, Hz, and the one-sided power spectral density of ``x``, unit²/Hz, as
    ``scipy.signal.welch(x, fs_hz, nperseg=nperseg, nfft=nfft, detrend=detrend or False)``.

    Parameters
    ----------
    x : ndarray
        Real signal, 1-D, at least ``nperseg`` samples.
    fs_hz : float
        Sampling rate, Hz.
    nperseg : int
        Samples per segment (Hann window, overlap ``nperseg // 2``).
    detrend : {"constant", "linear", None}
        Subtract each segment's mean, or its least-squares line, before windowing; None: neither.
    nfft : int or None
        FFT length (zero padding beyond ``nperseg``); None: ``nperseg``.
    """
    nfft = nperseg if nfft is None else nfft
    window = signal.get_window("hann", nperseg)
    segments = np.lib.stride_tricks.sliding_window_view(np.asarray(x, dtype=np.float64), nperseg)
    segments = segments[::nperseg - nperseg // 2]
    if detrend is not None:
        segments = segments - segments.mean(axis=1, keepdims=True)
    if detrend == "linear":  # the centred time is orthogonal to the constant: the slope alone is left to remove
        t = np.arange(nperseg) - 0.5 * (nperseg - 1)
        segments -= (segments @ t / float(t @ t))[:, None] * t
    if detrend is None:
        segments = segments * window
    else:  # already a copy of the strided view: windowed in place
        segments *= window
    spectra = np.fft.rfft(segments, n=nfft, axis=1)
    density = np.mean(spectra.real**2 + spectra.imag**2, axis=0) / (fs_hz * float(np.sum(window**2)))
    density[1:-1 if nfft % 2 == 0 else None] *= 2.0  # one-sided: all but DC (and Nyquist) twice
    return np.fft.rfftfreq(nfft, 1.0 / fs_hz), density
